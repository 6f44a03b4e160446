"""Folders written whole: ``pirl plan`` stages a mission folder beside ``--out`` and renames
it into place; a staging folder left by a writer that was killed is removed by the next
``pirl plan`` into the same parent, on the machine that made it, once its process is gone."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path


def pid_alive(pid: int) -> bool:
    """Whether a process of this id runs on this machine (one of another user's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def host_name() -> str:
    """This machine's name as a staging folder carries it (letters and digits only)."""
    import socket

    return re.sub(r"[^A-Za-z0-9]", "", socket.gethostname())[:32] or "host"


STAGING = re.compile(r"^\..+\.staging-(?P<host>[A-Za-z0-9]*)-(?P<pid>[0-9]+)-[A-Za-z0-9_]+$")
"""A folder ``pirl plan`` writes into before renaming it to ``--out``: ``.NAME.staging-HOST-
PID-RANDOM``, beside ``--out`` (a rename within one file system is atomic)."""


def remove_stale_staging(parent: Path) -> list[Path]:
    """Remove the staging folders in ``parent`` whose writer, on this machine, is gone (a
    ``pirl plan`` killed mid-write); a running writer's, or another machine's, stay."""
    removed: list[Path] = []
    host = host_name()
    try:
        entries = list(parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        found = STAGING.match(entry.name)
        if not found or found["host"] != host or pid_alive(int(found["pid"])):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


__all__ = ["STAGING", "host_name", "pid_alive", "remove_stale_staging"]
