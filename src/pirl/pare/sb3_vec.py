"""PARE as a Stable-Baselines3 ``VecEnvWrapper`` around :class:`~pirl.env.sb3_vec.VCPPVecEnv`
or a fleet's VecEnv (:mod:`pirl.env.fleet`).

Per step, ``info["pare"]`` holds ``f_llm``, ``dir_align``, ``pos_align``, ``move``, ``cam``,
``status`` (fresh, cached, stale, student or missing) and ``staleness`` (steps); the LLM term
also appears in ``info["reward_terms"]["llm"]``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnvWrapper

from pirl.env.shaping import ShapingHooks
from pirl.pare.core import STATUSES, Shaped
from pirl.pare.engine import PARE
from pirl.pare.stats import PareStats


class PAREVecEnv(VecEnvWrapper):
    """Adds the PARE reward term to a batched env with shaping hooks (which resets an ended
    world at once)."""

    def __init__(self, venv: ShapingHooks, pare: PARE) -> None:
        super().__init__(venv)
        self.pare = pare

    @classmethod
    def from_settings(
        cls,
        venv: ShapingHooks,
        settings: Any,
        advice: Any,
        refit_every: int = 256,
        seed: int = 0,
        source: str = "",
    ) -> PAREVecEnv:
        """The wrapper of :meth:`PARE.from_settings <pirl.pare.engine.PARE.from_settings>`."""
        return cls(venv, PARE.from_settings(venv, settings, advice, refit_every, seed, source))

    @property
    def mode(self) -> str:
        return self.pare.mode

    @property
    def stats(self) -> PareStats:
        return self.pare.stats

    def reset(self) -> np.ndarray:
        obs = self.venv.reset()
        self.pare.start(obs)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self.pare.before_step()
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        shaped = self.pare.after_step(obs, rewards, dones)
        self.venv.add_step_info("pare", _info_of(shaped))
        return obs, rewards, dones, infos

    def state_dict(self) -> dict[str, Any]:
        return self.pare.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.pare.load_state_dict(state)

    def settle(self) -> PareStats:
        return self.pare.settle()

    def close(self) -> None:
        self.pare.close()
        self.venv.close()


def _info_of(shaped: Shaped):
    """World ``e``'s ``info["pare"]``, built when first read."""
    table, status, staleness = shaped.table, shaped.status, shaped.staleness

    def build(e: int) -> dict[str, Any]:
        return {
            "f_llm": float(table[e, 0]),
            "dir_align": float(table[e, 1]),
            "pos_align": float(table[e, 2]),
            "move": float(table[e, 3]),
            "cam": float(table[e, 4]),
            "status": STATUSES[status[e]],
            "staleness": int(staleness[e]),
        }

    return build


__all__ = ["PAREVecEnv"]
