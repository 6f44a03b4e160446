"""The batched VCPP environment: N worlds stepped at once, as a Stable-Baselines3 VecEnv."""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore, require_one_uav
from pirl.env.observation import obs_size_for
from pirl.env.render import render_world
from pirl.env.shaping import ShapingHooks
from pirl.world import dynamics as D
from pirl.world.state import WorldBatch


class SharedVecEnvPlumbing:
    """SB3's ``VecEnv`` plumbing for a batch whose slots share one Python object: attributes
    and methods are the vec env's own, nothing is wrapped, and ``action_masks`` (asked of
    every slot at every step by sb3-contrib) is one batched copy of :meth:`action_masks`."""

    def action_masks(self) -> np.ndarray:
        raise NotImplementedError

    def close(self) -> None:
        return None

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        slots = self._get_indices(indices)  # type: ignore[attr-defined]
        return [getattr(self, attr_name) for _ in slots]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        slots = list(self._get_indices(indices))  # type: ignore[attr-defined]
        if method_name == "action_masks":
            return list(self.action_masks()[slots])
        method = getattr(self, method_name)
        return [method(*method_args, **method_kwargs) for _ in slots]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]  # type: ignore[attr-defined]


class VCPPVecEnv(SharedVecEnvPlumbing, ShapingHooks, VecEnv):
    """N VCPP worlds on batched numpy arrays (see :class:`pirl.env.vcpp_env.VCPPEnv`).

    World ``i`` seeded with ``s`` behaves exactly like a single ``VCPPEnv`` reset with seed
    ``s``: same observations, rewards, dones and infos. Auto-reset follows Stable-Baselines3:
    when a world ends, ``infos[i]["terminal_observation"]`` holds its last observation,
    ``infos[i]["TimeLimit.truncated"]`` tells truncation, and the returned observation is the
    first one of the next episode.

    Reward wrappers such as PARE use the public hooks of
    :class:`~pirl.env.shaping.ShapingHooks`.
    """

    def __init__(
        self,
        num_envs: int,
        config: VCPPConfig | Mapping[str, Any] | None = None,
        parallel: bool | None = None,
        **settings: Any,
    ) -> None:
        self.cfg = VCPPConfig.resolve(config, settings)
        require_one_uav(self.cfg, "VCPPVecEnv")
        self.core = EnvCore(self.cfg, num_envs, parallel)
        n = obs_size_for(self.cfg)
        self.render_mode = "rgb_array"
        super().__init__(
            num_envs,
            spaces.Box(0.0, 1.0, (n,), dtype=np.float32),
            spaces.Discrete(D.N_ACTIONS),
        )
        self._rngs = [seeding.np_random(None)[0] for _ in range(num_envs)]
        self._actions: np.ndarray | None = None
        self.step_snapshot = None

    @property
    def world(self) -> WorldBatch:
        """The underlying :class:`~pirl.world.state.WorldBatch`."""
        return self.core.world

    def state_dict(self) -> dict[str, Any]:
        """Copies of what this env owns (the core's worlds, weights and observations, each
        world's random generator), enough to continue exactly after :meth:`load_state_dict`."""
        return {"core": self.core.state_dict(), "rngs": copy.deepcopy(self._rngs)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Put a :meth:`state_dict` back."""
        self.core.load_state_dict(state["core"])
        self._rngs = copy.deepcopy(state["rngs"])

    def reset(self) -> np.ndarray:
        for e in range(self.num_envs):
            if self._seeds[e] is not None:
                self._rngs[e] = seeding.np_random(self._seeds[e])[0]
            self.core.reset_world(e, self._rngs[e])
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = self.core.infos()
        return self.core.obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        core = self.core
        n_ended = core.step(self._actions)
        self._actions = None
        terminated, truncated = core.terminated, core.truncated
        dones = terminated | truncated
        rewards = core.rewards.astype(np.float32)
        infos = core.infos(lazy=True)
        # The step's info snapshot, for wrappers that add terms (PARE writes the LLM term).
        self.step_snapshot = core.snapshot
        obs = core.obs.copy()
        ended = np.flatnonzero(dones) if n_ended else ()
        if len(ended):
            for e in ended:
                infos[e]["terminal_observation"] = obs[e].copy()
                infos[e]["TimeLimit.truncated"] = bool(truncated[e] and not terminated[e])
                core.reset_world(int(e), self._rngs[e])
            obs[ended] = core.obs[ended]
            for e, info in zip(ended, core.infos(ended.tolist(), lazy=True), strict=True):
                self.reset_infos[e] = info
        return obs, rewards, dones, infos

    def action_masks(self) -> np.ndarray:
        """``(num_envs, 12)`` booleans: the actions that can change something in each world's
        current state (after auto-reset: the new episode's). See ``VCPPEnv.action_masks``."""
        return self.core.masks.copy()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [
            render_world(self.world, e, None, self.cfg.render_cell_px) for e in range(self.num_envs)
        ]


def make_vec_env(
    num_envs: int,
    seed: int | None = 0,
    config: VCPPConfig | Mapping[str, Any] | None = None,
    parallel: bool | None = None,
    **settings: Any,
) -> VCPPVecEnv:
    """A batched VCPP environment whose world ``i`` is seeded with ``seed + i`` at first reset.

    Takes the same keyword settings as ``gymnasium.make("pirl/VCPP-v0", ...)``; ``parallel``
    spreads worlds over numba threads (off by default; same results).
    """
    venv = VCPPVecEnv(num_envs, config, parallel, **settings)
    if seed is not None:
        venv.seed(seed)
    return venv


__all__ = ["SharedVecEnvPlumbing", "VCPPVecEnv", "make_vec_env"]
