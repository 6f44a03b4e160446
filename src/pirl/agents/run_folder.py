"""Run folders: creating one without overwriting, resuming, and the small files they hold.

Shared by every trained method (PPO in :mod:`pirl.agents.train`, TabNet in
:mod:`pirl.agents.imitation`) and by ``pirl reproduce``.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any

from pirl.agents import checkpoint
from pirl.world.config import ConfigError


def train_seed_base(seed: int) -> int:
    """World i of a run with ``seed`` starts from scenario seed ``base + i``.

    Evaluation scenario seeds start at 10**9, so training never sees them.
    """
    return 1_000 * seed


def prepare_run_folder(out: Path, resume: bool, log: Any = None) -> tuple[Path, dict] | None:
    """Create ``out`` for a new run, or return the checkpoint to resume from and its state.

    A folder that exists without ``resume`` is an error: runs are never overwritten. A run
    stopped before its first checkpoint resumes from step 0 (None); a damaged latest
    checkpoint falls back to the previous complete one.
    """
    if resume:
        if not out.is_dir():
            raise ConfigError(f"--resume: run folder {out} does not exist")
        found = checkpoint.load_latest(out / "checkpoints", log)
        if found is None and log is not None:
            log(f"resume: no complete checkpoint in {out / 'checkpoints'}; starting from step 0")
        return found
    if out.exists():
        raise ConfigError(
            f"run folder {out} already exists; pass --resume to continue it or choose --out"
        )
    out.mkdir(parents=True)
    return None


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
