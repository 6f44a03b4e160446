"""Files written whole or not at all: each is written to a temporary name beside it and then
renamed over it (``os.replace``, atomic on one filesystem), so a reader, a crash or a full disk
never meets half a file."""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any


@contextlib.contextmanager
def replacing(
    path: str | os.PathLike[str], tmp: str | os.PathLike[str] | None = None
) -> Iterator[Path]:
    """Yield a temporary path to write ``path``'s new content to; when the block ends, rename it
    over ``path``, and when the block raises, remove it and leave ``path`` as it was.

    ``tmp`` defaults to ``path`` with ``.tmp`` appended; a writer that adds its own suffix (SB3
    adds ``.zip`` to a name without it) passes one it keeps. One writer per file at a time: two
    writers of the same ``path`` would share the temporary name.
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp") if tmp is None else Path(tmp)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)  # only still there when the block or the rename failed


def write_atomic(
    path: str | os.PathLike[str], data: str | bytes, tmp: str | os.PathLike[str] | None = None
) -> Path:
    """Write ``data`` (text in the locale's encoding, as ``Path.write_text``, or bytes) to
    ``path`` atomically; returns the path."""
    path = Path(path)
    with replacing(path, tmp) as out:
        if isinstance(data, bytes):
            out.write_bytes(data)
        else:
            out.write_text(data)
    return path


def write_json(
    path: str | os.PathLike[str],
    data: Any,
    *,
    sort_keys: bool = False,
    default: Callable[[Any], Any] | None = None,
) -> Path:
    """Write ``data`` as indented JSON (2 spaces) to ``path`` atomically; returns the path."""
    return write_atomic(path, json.dumps(data, indent=2, sort_keys=sort_keys, default=default))


__all__ = ["replacing", "write_atomic", "write_json"]
