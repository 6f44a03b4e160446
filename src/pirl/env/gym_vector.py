"""The batched VCPP environment as a Gymnasium vector env (``gym.make_vec("pirl/VCPP-v0")``).

The same :class:`~pirl.env.core.EnvCore` as the single env and the Stable-Baselines3 adapter
(:class:`pirl.env.sb3_vec.VCPPVecEnv`): one compiled kernel steps every world, weighs its
reward and writes its observation into a preallocated buffer.
"""

from __future__ import annotations

import copy as copy_
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore, require_one_uav
from pirl.env.info import InfoSnapshot, LazyVectorInfo
from pirl.env.observation import obs_size_for
from pirl.env.render import render_world
from pirl.env.shaping import ShapingHooks
from pirl.world import dynamics as D
from pirl.world.state import WorldBatch


class VCPPVectorEnv(ShapingHooks, VectorEnv):
    """N VCPP worlds stepped at once (see :class:`pirl.env.vcpp_env.VCPPEnv` for the task).

    ## Vectorization
    ``gymnasium.make_vec("pirl/VCPP-v0", num_envs=N, ...)`` builds it (it is the registered
    vector entry point, so ``vectorization_mode="vector_entry_point"`` or no mode at all);
    it takes the same keyword settings as the single env. World ``i`` reset with seed ``s``
    plays exactly what a single ``VCPPEnv`` reset with seed ``s`` plays; ``reset(seed=s)``
    seeds world ``i`` with ``s + i``, as ``SyncVectorEnv`` does.

    ## Autoreset
    Gymnasium's default, ``AutoresetMode.NEXT_STEP``: the step on which a world's episode ends
    returns its last observation with ``terminated`` or ``truncated``; the next ``step`` ignores
    that world's action, resets it and returns its first observation with reward 0 and both
    flags False. ``reset(options={"reset_mask": mask})`` resets only the masked worlds.

    ## Info
    A dict of arrays (first axis = world) with a boolean mask ``_key`` per key, as
    ``SyncVectorEnv`` would build from the single envs' infos; ``position`` and ``camera`` are
    (N, 3) arrays, and ``episode_metrics`` is present (masked) for the worlds whose episode just
    ended. It is built on first read, so a loop that ignores it pays nothing for it.

    ``copy=False`` returns the observation buffer itself, which the next step overwrites.

    Reward wrappers such as PARE use the public hooks of
    :class:`~pirl.env.shaping.ShapingHooks`.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        config: VCPPConfig | Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        parallel: bool | None = None,
        copy: bool = True,
        **settings: Any,
    ) -> None:
        settings.pop("max_episode_steps", None)  # the step limit is the config's max_steps
        self.cfg = VCPPConfig.resolve(config, settings)
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode={render_mode!r}: allowed values are None, 'rgb_array'")
        self.render_mode = render_mode
        self.num_envs = num_envs
        require_one_uav(self.cfg, "VCPPVectorEnv")
        self.core = EnvCore(self.cfg, num_envs, parallel)
        self.copy = copy
        n = obs_size_for(self.cfg)
        self.single_observation_space = spaces.Box(0.0, 1.0, (n,), dtype=np.float32)
        self.single_action_space = spaces.Discrete(D.N_ACTIONS)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._rngs = [seeding.np_random(None)[0] for _ in range(num_envs)]
        # Worlds whose episode ended on the last step: the next step resets them.
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._n_autoreset = 0
        self._paths: list[list[tuple[int, int, int]]] = [[] for _ in range(num_envs)]
        self.step_snapshot: InfoSnapshot | None = None

    @property
    def world(self) -> WorldBatch:
        """The underlying :class:`~pirl.world.state.WorldBatch`."""
        return self.core.world

    def state_dict(self) -> dict[str, Any]:
        """Copies of what this env owns (the core, each world's random generator, which worlds
        the next step resets), enough to continue exactly after :meth:`load_state_dict`."""
        return {
            "core": self.core.state_dict(),
            "rngs": copy_.deepcopy(self._rngs),
            "autoreset": self._autoreset.copy(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Put a :meth:`state_dict` back (render paths start afresh)."""
        self.core.load_state_dict(state["core"])
        self._rngs = copy_.deepcopy(state["rngs"])
        self._autoreset[...] = state["autoreset"]
        self._n_autoreset = int(self._autoreset.sum())
        self._paths = [[self.world.position(e)] for e in range(self.num_envs)]

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every world (or those in ``options["reset_mask"]``); first observations, info."""
        n = self.num_envs
        if seed is None:
            seeds: Sequence[int | None] = [None] * n
        elif isinstance(seed, int | np.integer):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"{len(seeds)} seeds for {n} worlds")
        mask = (options or {}).get("reset_mask")
        if mask is None:
            mask = np.ones(n, dtype=np.bool_)
        elif not (isinstance(mask, np.ndarray) and mask.shape == (n,) and mask.dtype == np.bool_):
            raise ValueError(f"options['reset_mask'] must be a bool array of shape ({n},)")
        for e in np.flatnonzero(mask):
            if seeds[e] is not None:
                self._rngs[e] = seeding.np_random(seeds[e])[0]
            self.core.reset_world(int(e), self._rngs[e])
            self._paths[e] = [self.world.position(int(e))]
        self._autoreset[mask] = False
        self._n_autoreset = int(self._autoreset.sum())
        # Like SyncVectorEnv: the info covers (masks in) the worlds that were reset.
        return self._obs(), LazyVectorInfo(self.core.infos_snapshot(), mask.copy())

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One action per world; (observations, rewards, terminated, truncated, info)."""
        core = self.core
        ended = core.step(actions)
        if self._n_autoreset:
            # These worlds ended last step and were just stepped past their end (cheaper than
            # a masked kernel; their state is replaced now): reset them, which also zeroes
            # their reward and flags, as NEXT_STEP wants.
            for e in np.flatnonzero(self._autoreset):
                core.reset_world(int(e), self._rngs[e])
                self._paths[e] = []
            ended = -1  # the count included them: read the flags
        flags = core.world.flags
        terminated = flags["terminated"] != 0
        truncated = flags["truncated"] != 0
        if ended:
            np.logical_or(terminated, truncated, out=self._autoreset)
            self._n_autoreset = int(self._autoreset.sum())
        if self.render_mode is not None:
            for e in range(self.num_envs):
                self._paths[e].append(self.world.position(e))
        # Kept for the shaping hooks: a wrapper may still add to this step's info.
        self.step_snapshot = core.infos_snapshot()
        info = LazyVectorInfo(self.step_snapshot)
        return self._obs(), core.rewards.copy(), terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """``(num_envs, 12)`` booleans: the actions that can change something in each world now
        (also ``info["action_mask"]``). See ``VCPPEnv.action_masks``."""
        return self.core.masks.copy()

    def _obs(self) -> np.ndarray:
        return self.core.obs.copy() if self.copy else self.core.obs

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Top-down pictures of every world (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        return tuple(
            render_world(self.world, e, self._paths[e], self.cfg.render_cell_px)
            for e in range(self.num_envs)
        )

    def close_extras(self, **kwargs: Any) -> None:
        return None


__all__ = ["VCPPVectorEnv"]
