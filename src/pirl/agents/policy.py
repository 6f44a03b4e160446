"""One interface for every method, so evaluation treats them alike."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from pirl.world.state import WorldBatch


class Policy(ABC):
    """Chooses one action per step for one world.

    ``reset`` is called at the start of every episode with the world (and its index in the
    batch): learned policies ignore it, planners and LLM controllers read the map from it.
    """

    name: str = "policy"
    label: str = "policy"

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        """Start a new episode."""
        return None

    @abstractmethod
    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        """The action (0-11) for this step."""


class RandomPolicy(Policy):
    """Uniformly random actions (a floor for every comparison)."""

    name = "random"
    label = "random"

    def __init__(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(seed)

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        return int(self._rng.integers(12))
