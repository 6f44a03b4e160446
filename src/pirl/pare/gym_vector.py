"""PARE as a Gymnasium ``VectorWrapper`` around :class:`~pirl.env.gym_vector.VCPPVectorEnv`.

The vector env resets an ended world on the step after its end (``AutoresetMode.NEXT_STEP``):
that step is no transition, so PARE neither shapes nor counts it, and no advice is asked
about an ended episode's last state. ``info["pare"]`` holds arrays (first axis = world) of
``f_llm``, ``dir_align``, ``pos_align``, ``move``, ``cam``, ``status`` and ``staleness``; the
LLM term also appears in ``info["reward_terms"]["llm"]``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import VectorWrapper

from pirl.config.errors import ConfigError
from pirl.env.gym_vector import VCPPVectorEnv
from pirl.pare.core import STATUSES, Shaped
from pirl.pare.engine import PARE
from pirl.pare.stats import PareStats

_COLUMNS = ("f_llm", "dir_align", "pos_align", "move", "cam")


class PAREVectorWrapper(VectorWrapper):
    """Adds the PARE reward term to a VCPPVectorEnv."""

    def __init__(self, env: VCPPVectorEnv, pare: PARE) -> None:
        super().__init__(env)
        self.pare = pare
        self._ended = np.zeros(env.num_envs, dtype=bool)  # reset by the next step

    @classmethod
    def from_settings(
        cls,
        env: VCPPVectorEnv,
        settings: Any,
        advice: Any,
        refit_every: int = 256,
        seed: int = 0,
        source: str = "",
    ) -> PAREVectorWrapper:
        """The wrapper of :meth:`PARE.from_settings <pirl.pare.engine.PARE.from_settings>`."""
        return cls(env, PARE.from_settings(env, settings, advice, refit_every, seed, source))

    @property
    def stats(self) -> PareStats:
        return self.pare.stats

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every world (PARE follows whole-batch resets only)."""
        if (options or {}).get("reset_mask") is not None:
            raise ConfigError("PARE resets every world at once: no options['reset_mask']")
        obs, info = self.env.reset(seed=seed, options=options)
        self._ended[:] = False
        self.pare.start(obs)
        return obs, info

    def step(self, actions: np.ndarray):
        self.pare.before_step()
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        dones = terminated | truncated
        restarted = self._ended.copy()
        shaped = self.pare.after_step(obs, rewards, dones, ~dones, restarted)
        self._ended[:] = dones
        info["pare"] = _info_of(shaped, ~restarted)
        info["_pare"] = ~restarted
        return obs, rewards, terminated, truncated, info

    def state_dict(self) -> dict[str, Any]:
        return {"pare": self.pare.state_dict(), "ended": self._ended.copy()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.pare.load_state_dict(state["pare"])
        self._ended[:] = state["ended"]

    def settle(self) -> PareStats:
        return self.pare.settle()

    def close(self, **kwargs: Any) -> None:
        self.pare.close()
        super().close(**kwargs)


def _info_of(shaped: Shaped, shown: np.ndarray) -> dict[str, Any]:
    """``info["pare"]`` as Gymnasium's vector infos hold it: arrays with a mask per key."""
    out: dict[str, Any] = {}
    values = [shaped.table[:, k].copy() for k in range(len(_COLUMNS))]
    values += [np.array(STATUSES, dtype=object)[shaped.status], shaped.staleness.copy()]
    for name, value in zip((*_COLUMNS, "status", "staleness"), values, strict=True):
        out[name], out["_" + name] = value, shown.copy()
    return out


__all__ = ["PAREVectorWrapper"]
