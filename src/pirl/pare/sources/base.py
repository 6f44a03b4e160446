"""The contract of an advice source: where the advice each world holds comes from.

PARE's engine calls, per step: :meth:`AdviceSource.collect` before it shapes the step,
:meth:`~AdviceSource.end` for the worlds whose episode ended, :meth:`~AdviceSource.tick` once
the step is counted, then :meth:`~AdviceSource.request` about the worlds' new states. Sources
write advice rows into the shared :class:`~pirl.pare.board.AdviceBoard` and count into
:class:`~pirl.pare.stats.PareStats`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from pirl.advice.base import Advisor
from pirl.env.shaping import ShapingHooks
from pirl.pare.board import AdviceBoard
from pirl.pare.bundle import AdviceBundle
from pirl.pare.stats import Health


@dataclass
class SourceSetup:
    """What a source is built from."""

    board: AdviceBoard
    """The advice every world holds, and the clocks."""
    health: Health
    """Counts the teacher's answers; stops a run whose teacher keeps failing."""
    advisor: Advisor
    """The teacher (cached and budgeted as configured)."""
    settings: Any
    """The ``pare`` settings section (:class:`PareSettings`)."""
    advice: AdviceBundle
    """The run's advice side: student, dataset,
    teacher rate and batch size."""
    refit_every: int
    """Vector steps per rollout (PPO's ``n_steps``): the student's rollout boundaries."""
    seed: int
    """The teacher's sampling stream."""
    source: str
    """The run's name in the teacher dataset."""


class AdviceSource(Protocol):
    """Where the advice of every world comes from (student, sync or async)."""

    mode: str

    def reset(self) -> None:
        """Every world starts a new episode: drop what was asked about the old ones."""

    def collect(self) -> None:
        """Before a step is shaped: take the answers that arrived into the board."""

    def end(self, worlds: np.ndarray) -> None:
        """The episodes of ``worlds`` ended (the board has dropped their advice)."""

    def tick(self) -> None:
        """A step was shaped and counted (the board's clock moved on)."""

    def request(self, env: ShapingHooks, obs: np.ndarray, live: np.ndarray | None) -> None:
        """Ask about the current states of the ``live`` worlds (None = all); ``obs`` holds
        every world's observation now."""

    def settle(self) -> None:
        """At the end of a run, without waiting: count what is still in flight or waiting."""

    def state_dict(self) -> dict[str, Any]:
        """What a resume needs (at a rollout boundary)."""
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`state_dict` (after the board)."""

    def close(self) -> None:
        """Stop background work (the advisor itself is closed by the engine)."""


__all__ = ["AdviceSource", "SourceSetup"]
