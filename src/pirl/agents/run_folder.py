"""Run folders: creating one without overwriting, resuming, and the small files they hold.

Shared by every trained method (PPO in :mod:`pirl.agents.train`, TabNet in
:mod:`pirl.agents.imitation`) and by ``pirl reproduce``.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from pirl.agents import checkpoint
from pirl.config.errors import ConfigError


def train_seed_base(seed: int) -> int:
    """World i of a run with ``seed`` starts from scenario seed ``base + i``.

    Evaluation scenario seeds start at 10**9, so training never sees them.
    """
    return 1_000 * seed


LOCK_NAME = ".pirl.lock"
"""The lock file in a run or output folder; it holds the writing process's PID."""
_HELD: dict[tuple[int, str], int] = {}  # (pid, folder) -> descriptor holding the lock


class FolderBusy(ConfigError):
    """Another live process writes to the folder (exit code 2, like every user mistake)."""


def lock_folder(folder: Path, what: str = "run folder") -> None:
    """Become the one writer of ``folder`` (which must exist) until this process ends or
    :func:`release_folder`; raise :class:`FolderBusy` naming the holder's PID otherwise.

    ``fcntl.flock`` on ``folder/.pirl.lock``: the kernel drops the lock when its holder dies,
    so a run killed with ``kill -9`` never leaves a stale lock. Taking it again in the same
    process is a no-op.
    """
    key = (os.getpid(), str(Path(folder).resolve()))
    if key in _HELD:
        return
    path = Path(folder) / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 64).decode(errors="replace").strip() or "unknown"
        os.close(fd)
        raise FolderBusy(
            f"{what} {folder} is in use by another pirl process (PID {holder}); wait for it "
            "to end (or stop it), or choose another --out"
        ) from None
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    _HELD[key] = fd


def release_folder(folder: Path) -> None:
    """Give up the lock this process holds on ``folder`` (if any)."""
    fd = _HELD.pop((os.getpid(), str(Path(folder).resolve())), None)
    if fd is not None:
        os.close(fd)  # closing the descriptor releases the flock


@contextlib.contextmanager
def folder_lock(folder: Path, what: str = "output folder") -> Iterator[None]:
    """Hold ``folder``'s lock for a block, creating the folder if needed; a folder made here
    that holds nothing but the lock at the end is removed (a refused command leaves nothing)."""
    folder = Path(folder)
    made = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    lock_folder(folder, what)
    try:
        yield
    finally:
        release_folder(folder)
        if made and [p.name for p in folder.iterdir()] == [LOCK_NAME]:
            with contextlib.suppress(OSError):
                (folder / LOCK_NAME).unlink()
                folder.rmdir()


def folder_contents(folder: Path) -> list[Path]:
    """What a folder holds besides its lock file (empty when it does not exist)."""
    if not Path(folder).is_dir():
        return []
    return sorted(p for p in Path(folder).iterdir() if p.name != LOCK_NAME)


def prepare_run_folder(out: Path, resume: bool, log: Any = None) -> tuple[Path, dict] | None:
    """Create ``out`` for a new run, or return the checkpoint to resume from and its state.

    A folder that exists without ``resume`` is an error: runs are never overwritten. A run
    stopped before its first checkpoint resumes from step 0 (None); a damaged latest
    checkpoint falls back to the previous complete one. Either way this process becomes the
    folder's one writer (:func:`lock_folder`).
    """
    if resume:
        if not out.is_dir():
            raise ConfigError(f"--resume: run folder {out} does not exist")
        lock_folder(out)  # before reading checkpoints: nobody else may be writing them
        found = checkpoint.load_latest(out / "checkpoints", log)
        if found is None and log is not None:
            log(f"resume: no complete checkpoint in {out / 'checkpoints'}; starting from step 0")
        return found
    if out.exists() and never_saved(out):
        # A run that failed before its first checkpoint saved nothing: start it again here.
        lock_folder(out)
        for path in folder_contents(out):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
        if log is not None:
            log(f"{out} holds a run that stopped before its first checkpoint; starting it again")
        return None
    if out.exists():
        raise ConfigError(
            f"run folder {out} already exists; pass --resume to continue it or choose --out"
        )
    try:
        out.mkdir(parents=True)
    except FileExistsError:  # another process made it since the check above
        raise ConfigError(
            f"run folder {out} already exists; pass --resume to continue it or choose --out"
        ) from None
    lock_folder(out)
    return None


_RUN_FILES = {"config.yaml", "meta.json", "episodes.csv", "tb", "checkpoints", LOCK_NAME}


def never_saved(out: Path) -> bool:
    """Whether ``out`` is a folder that holds nothing a run saved: empty, or the first files
    of a run that stopped before its first checkpoint (no checkpoint, no model, not complete)."""
    out = Path(out)
    if not out.is_dir():
        return False
    names = {p.name for p in out.iterdir()}
    if not names <= _RUN_FILES:
        return False
    if checkpoint.latest(out / "checkpoints") is not None or any(
        (out / "checkpoints").glob("step_*")
    ):
        return False
    try:
        meta = json.loads((out / "meta.json").read_text()) if "meta.json" in names else {}
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and not meta.get("complete")


def git_commit() -> str:
    """The code's git commit (with '-dirty' when modified), or 'unknown'."""
    root = Path(__file__).resolve().parents[3]
    try:
        sha = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=10,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (sha + ("-dirty" if dirty else "")) if sha else "unknown"


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write JSON atomically (temporary file, then rename)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True, default=str))
    os.replace(tmp, path)
