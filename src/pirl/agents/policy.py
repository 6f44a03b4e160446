"""One interface for every method, so evaluation treats them alike."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from pirl.config import grid as g
from pirl.world import dynamics as D
from pirl.world.state import WorldBatch


class Policy(ABC):
    """Chooses one action per step for one world.

    ``reset`` is called at the start of every episode with the world (and its index in the
    batch): learned policies ignore it, planners and LLM controllers read the map from it.
    """

    name: str = "policy"
    label: str = "policy"

    @classmethod
    def build(
        cls,
        seed: int | None = None,
        advisor: Any | None = None,
        prompt_variant: str = "paper",
        max_calls: int = 0,
    ) -> Policy:
        """A played method's policy from the options any played method may take; each class
        uses those it needs (a planner none of them)."""
        return cls()

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        """Start a new episode."""
        return None

    @abstractmethod
    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        """The action (0 to N_ACTIONS - 1, see :mod:`pirl.world.dynamics`) for this step."""


class RandomPolicy(Policy):
    """Uniformly random actions (a floor for every comparison)."""

    name = "random"
    label = "random"

    def __init__(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(seed)

    @classmethod
    def build(cls, seed: int | None = None, **_options: Any) -> RandomPolicy:
        return cls(seed)

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        return int(self._rng.integers(D.N_ACTIONS))


def hold_action(camera: tuple[int, int, int]) -> int:
    """An action that changes nothing when one exists (a camera action at its limit).

    ``camera`` is (tilt, pan, zoom10). With no camera axis at a limit it tilts down by 5, the
    least disruptive change.
    """
    tilt, pan, zoom10 = camera
    for at_limit, action in (
        (tilt == g.TILT_MAX, D.TILT_PLUS), (tilt == g.TILT_MIN, D.TILT_MINUS),
        (pan == g.PAN_MAX, D.PAN_PLUS), (pan == g.PAN_MIN, D.PAN_MINUS),
        (zoom10 == g.ZOOM_MAX10, D.ZOOM_PLUS), (zoom10 == g.ZOOM_MIN10, D.ZOOM_MINUS),
    ):  # fmt: skip
        if at_limit:
            return action
    return D.TILT_PLUS
