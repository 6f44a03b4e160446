"""The public hooks a reward-shaping wrapper (PARE) uses on a batched VCPP environment.

Both batched environments (the Stable-Baselines3 :class:`~pirl.env.sb3_vec.VCPPVecEnv` and the
Gymnasium :class:`~pirl.env.gym_vector.VCPPVectorEnv`) offer them, so a wrapper reads poses and
world views and adds its reward term through these methods only, never through the world
arrays, and works over either.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from pirl.config.world import REWARD_TERMS, VCPPConfig
from pirl.env.core import EnvCore
from pirl.env.info import InfoSnapshot
from pirl.world.planning import WorldView


class ShapingHooks:
    """Mixed into the batched environments; needs ``core`` and ``step_snapshot`` (the info
    snapshot of the last step, taken before any auto-reset)."""

    core: EnvCore
    step_snapshot: InfoSnapshot | None
    num_envs: int
    cfg: VCPPConfig

    def poses(self) -> np.ndarray:
        """(num_envs, 6) int64: each world's position (x, y, z) and camera (tilt, pan, zoom
        tenths) now; after an auto-reset, the new episode's first."""
        return _poses(self.core.world.status)

    def step_poses(self) -> np.ndarray:
        """As :meth:`poses`, at the end of the last step (before any auto-reset)."""
        return _poses(self._last_step().status)

    def parked(self) -> np.ndarray:
        """(num_envs,) bool: the slots whose UAV has left its fleet's episode and waits, parked,
        for its world to start again (:mod:`pirl.env.fleet`); never one for a single UAV."""
        return self.core.world.left.copy()

    def step_weights(self, term: str) -> np.ndarray:
        """(num_envs,) float64: the weight of reward term ``term`` in each world's last step
        (an episode that ended on it keeps its own weight)."""
        return self._last_step().weights[:, REWARD_TERMS.index(term)].copy()

    def set_step_term(self, term: str, values: np.ndarray) -> None:
        """Report ``values`` as reward term ``term`` of the last step (``info["reward_terms"]``);
        the reward itself is the caller's to change."""
        self._last_step().terms[:, REWARD_TERMS.index(term)] = values

    def add_step_info(self, key: str, build: Callable[[int], Any]) -> None:
        """Add ``info[key] = build(world)`` to the last step's infos (built on first read)."""
        self._last_step().extras[key] = build

    def world_views(self, worlds: Sequence[int], copy: bool = False) -> list[WorldView]:
        """The map and pose of each of ``worlds`` now: frozen copies with ``copy`` (for a
        reader in another thread), else live arrays the next step changes."""
        world = self.core.world
        return [WorldView.of(world, int(e), copy=copy) for e in worlds]

    def _last_step(self) -> InfoSnapshot:
        if self.step_snapshot is None:
            raise RuntimeError("no step yet: the shaping hooks describe the last step")
        return self.step_snapshot


_POSE_FIELDS = ("x", "y", "z", "tilt", "pan", "zoom10")


def _poses(status: np.ndarray) -> np.ndarray:
    """(n, 6) int64 pose columns of the worlds' status records."""
    return np.stack([status[name] for name in _POSE_FIELDS], axis=-1).astype(np.int64)


__all__ = ["ShapingHooks"]
