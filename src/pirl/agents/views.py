"""Playing a chooser of candidate views (:mod:`pirl.env.views`) as a policy."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pirl.agents.policy import Policy, hold_action
from pirl.env.views import Candidates, ViewPilot, candidates, flight_limit, nearest_view
from pirl.world.planning import WorldView
from pirl.world.state import WorldBatch

Chooser = Callable[[Candidates], int]
"""Picks a slot of a :class:`Candidates` whose place is present."""


class ViewsPolicy(Policy):
    """A chooser of candidate views played step by step, as :class:`~pirl.env.views.ViewsEnv`
    plays it: a choice among the candidates of the moment, the pilot's steps to its place
    (at most :func:`~pirl.env.views.flight_limit`), then the next choice. Where no useful
    place is reachable it holds still (the env's stall guard, when on, leads it on)."""

    name = "views"
    label = "candidate views"

    def __init__(self, chooser: Chooser = nearest_view, label: str | None = None) -> None:
        self.chooser = chooser
        if label is not None:
            self.label = label

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        self.world, self.e = world, index
        self.pilot = ViewPilot(world, index)
        self.limit = flight_limit(world.cfg)
        self.flown, self.choosing = 0, True

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        for _ in range(2):
            if self.choosing:
                view = WorldView.of(self.world, self.e)
                c = candidates(view, self.pilot.camera, self.pilot.altitude)
                if not c.any:
                    break
                self.pilot.aim(c.place(self.chooser(c)))
                self.flown, self.choosing = 0, False
            action = self.pilot.action() if self.flown < self.limit else None
            if action is not None:
                self.flown += 1
                return action
            self.choosing = True
        return hold_action(self.world.camera_setting(self.e))
