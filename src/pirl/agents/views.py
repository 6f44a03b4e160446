"""Playing a chooser of candidate views (:mod:`pirl.env.views`) as a policy."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pirl.agents.policy import Policy, hold_action
from pirl.env.views import K_VIEWS, VIEW_FEATURES, Candidates, ViewPilot, candidates
from pirl.world.planning import WorldView
from pirl.world.state import WorldBatch

Chooser = Callable[[Candidates], int]
"""Picks a slot of a :class:`Candidates` whose place is present."""


def nearest_view(c: Candidates) -> int:
    """The rule a learned chooser is measured against: the nearest candidate (then the one
    whose view adds more cells)."""
    feats = c.obs[: K_VIEWS * VIEW_FEATURES].reshape(K_VIEWS, VIEW_FEATURES)
    keys = [(f[3], -f[4]) if f[0] else (np.inf, 0.0) for f in feats]
    return int(min(range(K_VIEWS), key=lambda k: keys[k]))


class ViewsPolicy(Policy):
    """A chooser of candidate views played step by step: it chooses a place whenever the
    last one is reached (or no longer useful), and the pilot's moves fill the steps between."""

    name = "views"
    label = "candidate views"

    def __init__(self, chooser: Chooser = nearest_view, label: str | None = None) -> None:
        self.chooser = chooser
        if label is not None:
            self.label = label

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        self.world, self.e = world, index
        self.pilot = ViewPilot(world, index)
        self.choices = 0

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        for _ in range(2):
            action = self.pilot.action()
            if action is not None:
                return action
            if not self._choose():
                break
        return hold_action(self.world.camera_setting(self.e))

    def _choose(self) -> bool:
        view = WorldView.of(self.world, self.e)
        c = candidates(view, self.pilot.camera, self.pilot.altitude)
        if not c.any:
            return False
        k = self.chooser(c)
        self.pilot.aim(c.cells[k])
        self.choices += 1
        return True
