"""Teacher answers with the state they were asked about: the student's dataset.

SQLite in WAL mode beside the answer cache, so several processes append and read at once;
row ids only grow, so a reader that remembers the last id it has seen loads exactly the rows
added since. Rows carry the run that stored them (``source``) and its step (``t``).
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
from pathlib import Path
from typing import Any

import numpy as np

from pirl._paths import cache_root
from pirl.advice.cache import open_store


def default_dataset_path() -> Path:
    """``student.sqlite`` in the PIRL cache folder (:func:`pirl._paths.cache_root`)."""
    return cache_root() / "student.sqlite"


_SCHEMA = [
    """CREATE TABLE IF NOT EXISTS samples (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        teacher TEXT NOT NULL,
        features BLOB NOT NULL,
        labels TEXT NOT NULL,
        source TEXT NOT NULL,
        t INTEGER NOT NULL,
        created REAL NOT NULL
    )""",
    "CREATE INDEX IF NOT EXISTS samples_teacher ON samples (teacher, id)",
]


class TeacherDataset:
    """Teacher answers with the features of the state they were asked about (SQLite, WAL).

    Several processes may append and read at once. Row ids only grow, so a reader that
    remembers the last id it has seen loads exactly the rows added since.
    """

    def __init__(self, path: str | os.PathLike[str], timeout_s: float = 60.0) -> None:
        self.path = Path(path).expanduser()
        self.timeout_s = timeout_s
        self._conn: sqlite3.Connection | None = None
        self._pid = -1
        self.in_memory = False
        """True when the file could not be used and answers live in this process only."""
        self._connection()

    def _connection(self) -> sqlite3.Connection:
        if self._conn is None or self._pid != os.getpid():
            conn = None
            if not self.in_memory:
                conn = open_store(self.path, self.timeout_s, _SCHEMA, "teacher dataset")
            if conn is None:
                # Unusable file (said in one line): this process keeps its answers in memory,
                # so the run goes on; they are not shared and not kept.
                self.in_memory = True
                conn = sqlite3.connect(":memory:", isolation_level=None, check_same_thread=False)
                for statement in _SCHEMA:
                    conn.execute(statement)
            self._conn = conn
            self._pid = os.getpid()
        return self._conn

    def add(
        self, teacher: str, features: np.ndarray, labels: np.ndarray, source: str = "", t: int = 0
    ) -> int:
        """Append rows; returns how many. ``source`` and ``t`` name the run and its step, so a
        resumed run can :meth:`forget` what it stored after its checkpoint."""
        now = time.time()
        rows = [
            (
                teacher, np.asarray(f, dtype=np.float32).tobytes(), json.dumps(lab.tolist()),
                source, int(t), now,
            )
            for f, lab in zip(features, labels, strict=True)
        ]  # fmt: skip
        if rows:
            conn = self._connection()
            conn.execute("BEGIN IMMEDIATE")
            try:
                conn.executemany(
                    "INSERT INTO samples (teacher, features, labels, source, t, created) "
                    "VALUES (?,?,?,?,?,?)",
                    rows,
                )
                conn.execute("COMMIT")
            except BaseException:
                conn.execute("ROLLBACK")
                raise
        return len(rows)

    def load(
        self, teacher: str, after: int = 0, upto: int | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows of ``teacher`` with ``after < id <= upto``: (ids, features, labels)."""
        query = "SELECT id, features, labels FROM samples WHERE teacher = ? AND id > ?"
        args: list[Any] = [teacher, int(after)]
        if upto is not None:
            query += " AND id <= ?"
            args.append(int(upto))
        rows = self._connection().execute(query + " ORDER BY id", args).fetchall()
        if not rows:
            return (np.zeros(0, np.int64), np.zeros((0, 0), np.float32), np.zeros((0, 6), np.int64))
        ids = np.array([r[0] for r in rows], dtype=np.int64)
        feats = np.stack([np.frombuffer(r[1], dtype=np.float32) for r in rows])
        labels = np.array([json.loads(r[2]) for r in rows], dtype=np.int64)
        return ids, feats, labels

    def forget(self, source: str, after: int) -> int:
        """Delete the rows ``source`` stored after its step ``after``; returns how many."""
        if not source:
            return 0
        cur = self._connection().execute(
            "DELETE FROM samples WHERE source = ? AND t > ?", (source, int(after))
        )
        return int(cur.rowcount)

    def drop(self, teacher: str) -> int:
        """Delete every row of ``teacher``; returns how many."""
        cur = self._connection().execute("DELETE FROM samples WHERE teacher = ?", (teacher,))
        return int(cur.rowcount)

    def count(self, teacher: str, source_prefix: str = "") -> int:
        """Rows stored for ``teacher`` (only those whose source starts with
        ``source_prefix``, when given)."""
        query, args = "SELECT COUNT(*) FROM samples WHERE teacher = ?", [teacher]
        if source_prefix:
            query += " AND substr(source, 1, ?) = ?"
            args += [len(source_prefix), source_prefix]
        row = self._connection().execute(query, args).fetchone()
        return int(row[0])

    def copy_first(self, teacher: str, source_prefix: str, limit: int, to: str, source: str) -> int:
        """Copy the first ``limit`` rows of ``teacher`` whose source starts with
        ``source_prefix`` (in the order they were stored) under the key ``to``, as rows of
        ``source`` at step 0; returns how many. A run's head start: fixed answers taken once,
        before the run trains, so nothing another process stores later reaches it."""
        conn = self._connection()
        conn.execute("BEGIN IMMEDIATE")
        try:
            cur = conn.execute(
                "INSERT INTO samples (teacher, features, labels, source, t, created) "
                "SELECT ?, features, labels, ?, 0, created FROM samples "
                "WHERE teacher = ? AND substr(source, 1, ?) = ? ORDER BY id LIMIT ?",
                (to, source, teacher, len(source_prefix), source_prefix, int(limit)),
            )
            conn.execute("COMMIT")
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        return int(cur.rowcount)

    def close(self) -> None:
        if self._conn is not None and self._pid == os.getpid():
            self._conn.close()
        self._conn = None

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "timeout_s": self.timeout_s}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["path"], state["timeout_s"])


__all__ = ["TeacherDataset", "default_dataset_path"]
