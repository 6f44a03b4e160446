"""Candidate views as a Stable-Baselines3 VecEnv: the batch a chooser trains in."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from pirl.config.world import VCPPConfig
from pirl.env.sb3_vec import SharedVecEnvPlumbing
from pirl.env.views import OBS_SIZE, ViewsWorld, views_spaces


@dataclass
class ViewsStep:
    """The reward terms of the last choices, one row per world (summed over each flight),
    read by the trainer's logs as a batched env's step snapshot."""

    terms: np.ndarray


class ViewsVecEnv(SharedVecEnvPlumbing, VecEnv):
    """N worlds of :class:`ViewsEnv` as a Stable-Baselines3 VecEnv (auto-reset as SB3 does:
    ``terminal_observation`` and ``TimeLimit.truncated`` in the info of a world that ended).
    World ``i`` seeded with ``s`` plays as ``ViewsEnv.reset(seed=s)`` does."""

    def __init__(self, num_envs: int, cfg: VCPPConfig) -> None:
        self.cfg = cfg
        self.worlds = [ViewsWorld(cfg) for _ in range(num_envs)]
        self.render_mode = None
        super().__init__(num_envs, *views_spaces())
        self._rngs = [np.random.default_rng() for _ in range(num_envs)]
        self._actions: np.ndarray | None = None
        self.step_snapshot: ViewsStep | None = None

    def reset(self) -> np.ndarray:
        for e, views in enumerate(self.worlds):
            if self._seeds[e] is not None:
                self._rngs[e] = seeding.np_random(self._seeds[e])[0]
            views.reset(self._rngs[e])
        self._reset_seeds()
        self._reset_options()
        return np.stack([v.obs for v in self.worlds])

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        obs = np.zeros((self.num_envs, OBS_SIZE), dtype=np.float32)
        rewards = np.zeros(self.num_envs, dtype=np.float32)
        dones = np.zeros(self.num_envs, dtype=bool)
        terms, infos = [], []
        for e, (views, k) in enumerate(zip(self.worlds, self._actions, strict=True)):
            f = views.fly(int(k))
            info = {**f.info, "primitive_steps": f.steps}
            obs[e], rewards[e], dones[e] = views.obs, f.reward, f.terminated or f.truncated
            if dones[e]:
                info["terminal_observation"] = obs[e].copy()
                info["TimeLimit.truncated"] = f.truncated and not f.terminated
                views.reset(self._rngs[e])
                obs[e] = views.obs
            terms.append(f.terms)
            infos.append(info)
        self._actions = None
        self.step_snapshot = ViewsStep(np.array(terms))
        return obs, rewards, dones, infos

    def action_masks(self) -> np.ndarray:
        return np.stack([v.mask for v in self.worlds])

    def state_dict(self) -> dict[str, Any]:
        """Copies of every world and its generator (see :meth:`ViewsWorld.state_dict`)."""
        return {
            "worlds": [v.state_dict() for v in self.worlds],
            "rngs": copy.deepcopy(self._rngs),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for views, saved in zip(self.worlds, state["worlds"], strict=True):
            views.load_state_dict(saved)
        self._rngs = copy.deepcopy(state["rngs"])

    def get_images(self) -> list[None]:
        return [None] * self.num_envs
