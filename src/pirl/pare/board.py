"""What PARE knows about every world between steps: the advice it holds, which episode it is
in and how far, and the step clock. Advice sources write advice here; the core reads it."""

from __future__ import annotations

from typing import Any

import numpy as np

from pirl.pare.core import HAS

_ARRAYS = ("rec", "meta", "episode", "episode_step")


class AdviceBoard:
    """Per-world advice and episode clocks of ``n`` worlds."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.rec = np.zeros((n, 6), dtype=np.float64)
        """Advice rows: pan, tilt, zoom, dx, dy, dz."""
        self.meta = np.zeros((n, 3), dtype=np.int64)
        """Has advice, step it was asked at, kind (see :mod:`pirl.pare.core`)."""
        self.episode = np.zeros(n, dtype=np.int64)
        """Episodes started per world: advice is about one episode only."""
        self.episode_step = np.zeros(n, dtype=np.int64)
        """Steps into the current episode."""
        self.t = 0
        """Vector steps taken."""

    def start_all(self) -> None:
        """Every world starts a new episode, without advice."""
        self.meta[:, HAS] = 0
        self.episode += 1
        self.episode_step[:] = 0

    def tick(self, ended: np.ndarray) -> None:
        """One step taken; the worlds ``ended`` start a new episode, without advice."""
        self.t += 1
        self.episode_step += 1
        if ended.size:
            self.episode[ended] += 1
            self.episode_step[ended] = 0
            self.meta[ended, HAS] = 0

    def state_dict(self) -> dict[str, Any]:
        return {"t": self.t, **{name: getattr(self, name).copy() for name in _ARRAYS}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.t = state["t"]
        for name in _ARRAYS:
            getattr(self, name)[...] = state[name]


__all__ = ["AdviceBoard"]
