"""Where numba keeps compiled kernels: one folder per version of the kernel sources.

numba invalidates a cached kernel only when the file that defines it changes, not when a
function it calls (in another file) changes. The fused step kernel calls rules from several
files, so a stale cache could run old rules. Keying the cache folder on a hash of every file
that holds kernels makes any edit start a fresh cache.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

from pirl._paths import cache_root

_KERNEL_PACKAGES = ("world", "env", "pare", "physics")
_KEEP = 3


def configure() -> Path | None:
    """Point numba's cache at ``<base>/<hash of kernel sources>``; returns the folder."""
    import numba

    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for package in _KERNEL_PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            digest.update(path.name.encode())
            digest.update(path.read_bytes())
    base = Path(os.environ.get("PIRL_NUMBA_CACHE") or cache_root() / "numba")
    folder = base / digest.hexdigest()[:16]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # read-only home: numba falls back to compiling in memory
    numba.config.CACHE_DIR = str(folder)
    _prune(base, folder)
    return folder


@contextlib.contextmanager
def compiling() -> Iterator[None]:
    """Hold the cache folder's file lock while compiling kernels.

    numba does not coordinate processes: two that start together on a fresh cache (training
    workers, test workers) each compile every kernel (about 25 CPU-s for the step kernels).
    Under this lock the first compiles and writes the cache; the others wait, then load it.
    """
    import numba
    from filelock import FileLock

    folder = numba.config.CACHE_DIR  # configure()'s folder; empty when it could not make one
    if not folder:
        yield
        return
    with FileLock(str(Path(folder) / ".compile.lock")):
        yield


def _prune(base: Path, current: Path) -> None:
    """Keep the few most recently used cache folders."""
    try:
        folders = sorted(
            (p for p in base.iterdir() if p.is_dir() and p != current),
            key=lambda p: p.stat().st_mtime,
            reverse=True,
        )
    except OSError:
        return
    for old in folders[_KEEP - 1 :]:
        shutil.rmtree(old, ignore_errors=True)
