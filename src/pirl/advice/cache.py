"""A persistent SQLite cache in front of any advisor.

The key is the SHA-256 of (advisor name, model, settings key, prompt); an advisor's settings key
holds everything else that changes its answers (for an OpenAI-compatible server, the server's
URL). The database runs in WAL mode with a busy timeout, so several processes (vectorized
environments, parallel evaluation runs) can read and write it at once. Only answers that parse
are stored and served: a failed call or an unparseable answer is asked again next time, so a
server that answered badly and was then fixed is heard (and a run stopped by it resumes).

A cache file that is damaged is moved aside (``*.corrupt``) and started afresh; one that cannot
be opened (read-only folder, locked beyond the timeout) is left alone and the advisor runs
without a cache. Either way one warning line names the file and what was done.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.parser import parse_recommendation
from pirl.advice.recommendation import Recommendation

__all__ = ["CachedAdvisor", "cache_key", "connect_wal", "open_store"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS answers (
    key TEXT PRIMARY KEY,
    advisor TEXT NOT NULL,
    model TEXT NOT NULL,
    settings TEXT NOT NULL,
    prompt TEXT NOT NULL,
    text TEXT NOT NULL,
    recommendation TEXT,
    prompt_tokens INTEGER NOT NULL,
    completion_tokens INTEGER NOT NULL,
    latency_s REAL NOT NULL,
    created REAL NOT NULL
)
"""
_FIELDS = ("pan", "tilt", "zoom", "dx", "dy", "dz")
_CHUNK = 500  # SQLite host parameters per query, well under every build's limit


def connect_wal(path: Path, timeout_s: float, schema: list[str]) -> sqlite3.Connection:
    """An autocommit SQLite connection in WAL mode that several processes can share, with
    ``schema`` statements applied (folder created if missing)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    conn = sqlite3.connect(path, timeout=timeout_s, isolation_level=None, check_same_thread=False)
    conn.execute(f"PRAGMA busy_timeout = {int(timeout_s * 1000)}")
    deadline = time.monotonic() + timeout_s
    while True:  # switching to WAL needs a moment alone with the file
        try:
            conn.execute("PRAGMA journal_mode = WAL")
            conn.execute("PRAGMA synchronous = NORMAL")
            for statement in schema:
                conn.execute(statement)
            return conn
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                conn.close()
                raise
            time.sleep(0.05)


def warn(message: str) -> None:
    """One warning line on stderr (shown in every process, logging configured or not)."""
    print(f"warning: {message}", file=sys.stderr, flush=True)


def _damaged(exc: BaseException) -> bool:
    """Whether SQLite says the file itself is not a (sound) database."""
    text = str(exc).lower()
    return isinstance(exc, sqlite3.DatabaseError) and (
        "not a database" in text or "malformed" in text or "encrypted" in text
    )


def _move_aside(path: Path) -> Path:
    """Rename ``path`` (and its WAL companions) to ``*.corrupt``; returns the new name."""
    aside = path.with_name(path.name + ".corrupt")
    n = 1
    while aside.exists():  # keep every earlier damaged copy for a post-mortem
        aside = path.with_name(f"{path.name}.{n}.corrupt")
        n += 1
    os.replace(path, aside)
    for suffix in ("-wal", "-shm"):
        companion = path.with_name(path.name + suffix)
        if companion.exists():
            os.replace(companion, aside.with_name(aside.name + suffix))
    return aside


def open_store(
    path: Path, timeout_s: float, schema: list[str], what: str
) -> sqlite3.Connection | None:
    """:func:`connect_wal`, degrading instead of failing: a damaged file is moved aside and
    started afresh; a file that cannot be opened gives None (run without it). Each case says
    so in one warning line naming ``what`` and the file."""
    try:
        return connect_wal(path, timeout_s, schema)
    except (sqlite3.Error, OSError) as exc:
        reason: BaseException = exc
        if _damaged(exc):
            try:
                aside = _move_aside(path)
            except OSError as move_exc:
                reason = move_exc
            else:
                try:
                    conn = connect_wal(path, timeout_s, schema)
                except (sqlite3.Error, OSError) as again:
                    reason = again
                else:
                    warn(f"{what} {path} was damaged ({exc}); moved it to {aside}, started afresh")
                    return conn
    warn(f"{what} {path} cannot be used ({_first_line(reason)}); going on without it")
    return None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def cache_key(advisor: str, model: str, settings: str, prompt: str) -> str:
    """The cache key of one prompt: SHA-256 hex of the four parts."""
    payload = json.dumps([advisor, model, settings, prompt], ensure_ascii=False)
    return hashlib.sha256(payload.encode("utf-8")).hexdigest()


class CachedAdvisor(Advisor):
    """Answers from the cache when it has them; only misses go to ``advisor``, as one batch.

    Args:
        advisor: the advisor behind the cache.
        path: SQLite file (created with its folder if missing).
        timeout_s: how long to wait for a lock held by another process.

    Attributes:
        hits: prompts answered from the cache so far.
        misses: prompts that were not (duplicates within a batch are asked once).
    """

    def __init__(self, advisor: Advisor, path: str | os.PathLike[str], timeout_s: float = 60.0):
        self.inner = advisor
        self.path = Path(path).expanduser()
        self.timeout_s = float(timeout_s)
        self.name = advisor.name
        self.model = advisor.model
        self.label = advisor.label
        self.wants_view = advisor.wants_view
        self.hits = 0
        self.misses = 0
        self._lock = threading.Lock()
        self._conn: sqlite3.Connection | None = None
        self._pid = -1
        self.disabled = False
        """True once the file proved unusable: answers are then asked, never stored."""
        with self._lock:
            self._connection()  # damaged or unusable files are dealt with now, in one line

    def settings_key(self) -> str:
        """The inner advisor's settings key."""
        return self.inner.settings_key()

    def key(self, prompt: str) -> str:
        """The cache key of ``prompt`` for the inner advisor."""
        return cache_key(self.inner.name, self.inner.model, self.inner.settings_key(), prompt)

    def _connection(self) -> sqlite3.Connection | None:
        if self.disabled:
            return None
        if self._conn is not None and self._pid == os.getpid():
            return self._conn
        conn = open_store(self.path, self.timeout_s, [_SCHEMA], "advice cache")
        if conn is None:
            self.disabled = True  # said once; a copy in another process inherits the verdict
            return None
        self._conn, self._pid = conn, os.getpid()
        return self._conn

    def _lookup(self, keys: list[str]) -> dict[str, Answer]:
        found: dict[str, Answer] = {}
        unique = list(dict.fromkeys(keys))
        with self._lock:
            conn = self._connection()
            if conn is None:
                return found
            for start in range(0, len(unique), _CHUNK):
                chunk = unique[start : start + _CHUNK]
                marks = ",".join("?" * len(chunk))
                rows = conn.execute(
                    f"SELECT key, text, recommendation FROM answers WHERE key IN ({marks})", chunk
                ).fetchall()
                for key, text, rec in rows:
                    parsed = _load_rec(rec, text)
                    if parsed is None:  # stored by an older version: ask again, never replay
                        continue
                    found[key] = Answer(text=text, recommendation=parsed, from_cache=True)
        return found

    def _store(self, rows: list[tuple[Any, ...]]) -> None:
        with self._lock:
            conn = self._connection()
            if conn is None:
                return
            conn.execute("BEGIN IMMEDIATE")
            try:
                conn.executemany(
                    "INSERT OR REPLACE INTO answers VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", rows
                )
                conn.execute("COMMIT")
            except BaseException:
                conn.execute("ROLLBACK")
                raise

    def advise(self, prompts: list[str], views: Sequence[Any] | None = None) -> list[Answer]:
        """Cached answers where present; one inner batch for the rest; never raises.

        The key is the prompt alone, so an advisor that reads views is never cached here.
        """
        if self.inner.wants_view:
            return self.inner.advise(prompts, views)
        if not prompts:
            return []
        started = time.perf_counter()
        settings = self.inner.settings_key()
        keys = [cache_key(self.inner.name, self.inner.model, settings, p) for p in prompts]
        try:
            found = self._lookup(keys)
        except Exception as exc:  # noqa: BLE001 - a broken cache degrades to no cache
            self._give_up(exc)
            found = {}
        lookup_s = time.perf_counter() - started
        missing: dict[str, str] = {}
        for key, prompt in zip(keys, prompts, strict=True):
            if key not in found:
                missing.setdefault(key, prompt)
        fresh: dict[str, Answer] = {}
        if missing:
            try:
                answers = self.inner.advise(list(missing.values()))
                fresh = dict(zip(missing.keys(), answers, strict=True))
            except Exception as exc:  # noqa: BLE001 - an advisor that broke its contract
                fresh = {k: error_answer(f"{type(exc).__name__}: {exc}") for k in missing}
            now = time.time()
            rows = [
                (
                    key,
                    self.inner.name,
                    self.inner.model,
                    settings,
                    missing[key],
                    a.text,
                    _dump_rec(a.recommendation),
                    a.prompt_tokens,
                    a.completion_tokens,
                    a.latency_s,
                    now,
                )
                for key, a in fresh.items()
                if a.error is None and a.recommendation is not None
            ]
            if rows:
                try:
                    self._store(rows)
                except Exception as exc:  # noqa: BLE001 - a broken cache degrades to no cache
                    self._give_up(exc)
        result = []
        n_hits = 0
        for key in keys:
            if key in found:
                n_hits += 1
                cached = found[key]
                result.append(
                    Answer(
                        text=cached.text,
                        recommendation=cached.recommendation,
                        latency_s=lookup_s,
                        from_cache=True,
                    )
                )
            else:
                result.append(fresh[key])
        with self._lock:
            self.hits += n_hits
            self.misses += len(prompts) - n_hits
        return result

    def _give_up(self, exc: BaseException) -> None:
        """The file failed after it opened (damaged later, disk full): say it once, go on
        without the cache."""
        with self._lock:
            if self.disabled:
                return
            self.disabled = True
            if self._conn is not None and self._pid == os.getpid():
                self._conn.close()
            self._conn = None
        warn(f"advice cache {self.path} failed ({_first_line(exc)}); going on without it")

    @property
    def exhausted(self) -> bool:
        """Whether the advisor behind the cache has spent its budget (if it has one)."""
        return bool(getattr(self.inner, "exhausted", False))

    @property
    def calls(self) -> int | None:
        """Calls charged by a budget behind the cache, if any."""
        return getattr(self.inner, "calls", None)

    @property
    def tokens(self) -> int | None:
        """Tokens charged by a budget behind the cache, if any."""
        return getattr(self.inner, "tokens", None)

    def stats(self) -> dict[str, float]:
        """``hits``, ``misses`` and ``hit_rate`` of this advisor so far."""
        total = self.hits + self.misses
        return {
            "hits": self.hits,
            "misses": self.misses,
            "hit_rate": self.hits / total if total else 0.0,
        }

    def __len__(self) -> int:
        with self._lock:
            conn = self._connection()
            if conn is None:
                return 0
            return int(conn.execute("SELECT COUNT(*) FROM answers").fetchone()[0])

    def close(self) -> None:
        """Close the database and the inner advisor."""
        with self._lock:
            if self._conn is not None and self._pid == os.getpid():
                self._conn.close()
            self._conn = None
        self.inner.close()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_conn"], state["_pid"], state["_lock"] = None, -1, None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        return f"CachedAdvisor({self.inner!r}, path={str(self.path)!r})"


def _dump_rec(rec: Recommendation | None) -> str | None:
    if rec is None:
        return None
    return json.dumps([getattr(rec, f) for f in _FIELDS])


def _load_rec(stored: str | None, text: str) -> Recommendation | None:
    if stored is None:
        return None
    try:
        values = json.loads(stored)
        return Recommendation(**dict(zip(_FIELDS, values, strict=True)))
    except Exception:  # noqa: BLE001 - fall back to the text
        return parse_recommendation(text)
