"""A persistent SQLite cache in front of any advisor.

The key is the SHA-256 of (advisor name, model, settings key, prompt). The database runs in WAL
mode with a busy timeout, so several processes (vectorized environments, parallel evaluation
runs) can read and write it at once. Only successful calls are stored (an answer that does not
parse is stored: the model did answer); failed calls are asked again next time.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sqlite3
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.parser import parse_recommendation
from pirl.advice.recommendation import Recommendation

__all__ = ["CachedAdvisor", "cache_key"]

log = logging.getLogger(__name__)

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
        with self._lock:
            self._connection()  # fail early on a bad path

    def settings_key(self) -> str:
        """The inner advisor's settings key."""
        return self.inner.settings_key()

    def key(self, prompt: str) -> str:
        """The cache key of ``prompt`` for the inner advisor."""
        return cache_key(self.inner.name, self.inner.model, self.inner.settings_key(), prompt)

    def _connection(self) -> sqlite3.Connection:
        if self._conn is not None and self._pid == os.getpid():
            return self._conn
        self._conn, self._pid = connect_wal(self.path, self.timeout_s, [_SCHEMA]), os.getpid()
        return self._conn

    def _lookup(self, keys: list[str]) -> dict[str, Answer]:
        found: dict[str, Answer] = {}
        unique = list(dict.fromkeys(keys))
        with self._lock:
            conn = self._connection()
            for start in range(0, len(unique), _CHUNK):
                chunk = unique[start : start + _CHUNK]
                marks = ",".join("?" * len(chunk))
                rows = conn.execute(
                    f"SELECT key, text, recommendation FROM answers WHERE key IN ({marks})", chunk
                ).fetchall()
                for key, text, rec in rows:
                    found[key] = Answer(
                        text=text, recommendation=_load_rec(rec, text), from_cache=True
                    )
        return found

    def _store(self, rows: list[tuple[Any, ...]]) -> None:
        with self._lock:
            conn = self._connection()
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
            log.warning("advice cache %s unreadable (%s); asking the advisor", self.path, exc)
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
                if a.error is None
            ]
            if rows:
                try:
                    self._store(rows)
                except Exception as exc:  # noqa: BLE001
                    log.warning("advice cache %s not written (%s)", self.path, exc)
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
            return int(self._connection().execute("SELECT COUNT(*) FROM answers").fetchone()[0])

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
