"""How a training run stops before its end: exceptions the command line turns into one line
and an exit code. They live apart from the trainer so that catching them costs no torch import."""

from __future__ import annotations

from pathlib import Path


class TrainingStopped(Exception):
    """Training stopped for a reason the user must fix (an advisor that keeps failing);
    ``checkpoint`` is the resumable state saved (or None)."""

    def __init__(self, reason: str, saved: Path | None) -> None:
        super().__init__(reason)
        self.reason, self.checkpoint = reason, saved


class TrainingInterrupted(Exception):
    """Ctrl-C during training; ``checkpoint`` is where the state was saved (or None)."""

    def __init__(self, saved: Path | None) -> None:
        super().__init__(f"interrupted; checkpoint: {saved}")
        self.checkpoint = saved


__all__ = ["TrainingInterrupted", "TrainingStopped"]
