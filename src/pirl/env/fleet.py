"""A fleet of UAVs covering one world together: a PettingZoo ``ParallelEnv`` and a
Stable-Baselines3 ``VecEnv`` whose slots are (world, UAV) pairs.

Both run the one :class:`~pirl.env.core.EnvCore` (the rules of
:func:`pirl.world.dynamics.step_fleet`), so a fleet follows exactly the rules of one UAV,
plus three of its own: UAVs move in turn (the order turns by one every step), a move into a
cell a teammate holds is masked and, if a teammate took it earlier in the same step, holds
(a yield); a ground cell seen by several UAVs in one step is credited to the first; a UAV
leaves when its battery is spent or the fleet's coverage is complete. With one UAV both are
the single env (``pirl/VCPP-v0``) bit for bit.
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore
from pirl.env.observation import obs_size_for
from pirl.env.render import render_world
from pirl.env.sb3_vec import SharedVecEnvPlumbing
from pirl.env.shaping import ShapingHooks
from pirl.world import dynamics as D
from pirl.world.planning import WorldView
from pirl.world.scenario import Scenario
from pirl.world.state import WorldBatch


def agent_name(uav: int) -> str:
    """The PettingZoo name of UAV ``uav`` (0-based): ``uav_0``, ``uav_1``, ..."""
    return f"uav_{uav}"


class FleetParallelEnv(ParallelEnv):
    """K UAVs covering one VCPP world together, as a PettingZoo ``ParallelEnv``.

    ## Agents
    ``uav_0`` ... ``uav_{K-1}`` (``uavs=K``). An agent leaves ``agents`` after the step on
    which it is terminated (its battery spent, or the fleet's coverage complete) or truncated
    (the step limit, for every UAV still flying).

    ## Action Space
    ``Discrete(12)`` per agent, as the single env. ``infos[agent]["action_mask"]`` (int8, 12)
    gives the actions that can change something: moves into a teammate's cell are masked.

    ## Observation Space
    The single env's ``Box(0, 1, (n,), float32)`` per agent, with ``obs_teammates=M`` adding
    the nearest M teammates (6 values each; :mod:`pirl.env.observation`).

    ## Rewards
    Each agent's own reward terms weighed as in the single env (a world's UAVs share one draw
    of the EWRI weights); a cell is credited to the first UAV that saw it.

    ## Arguments
    ``FleetParallelEnv(uavs=K, size=..., ...)``: any field of
    :class:`pirl.config.world.VCPPConfig` as a keyword, or ``config=``; ``render_mode=
    "rgb_array"``. :func:`parallel_env` builds one, as PettingZoo's own modules do.
    """

    metadata = {"name": "pirl_fleet_v0", "render_modes": ["rgb_array"], "render_fps": 8}

    def __init__(
        self,
        config: VCPPConfig | Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        **settings: Any,
    ) -> None:
        self.cfg = VCPPConfig.resolve(config, settings)
        self.render_mode = render_mode
        self.core = EnvCore(self.cfg, 1)
        self.possible_agents = [agent_name(u) for u in range(self.cfg.uavs)]
        self.agents: list[str] = []
        n = obs_size_for(self.cfg)
        self._obs_space = spaces.Box(0.0, 1.0, (n,), dtype=np.float32)
        self._act_space = spaces.Discrete(D.N_ACTIONS)
        self._rng = seeding.np_random(None)[0]
        self.paths: list[list[tuple[int, int, int]]] = []

    @property
    def world(self) -> WorldBatch:
        """The underlying one-world :class:`~pirl.world.state.WorldBatch` (K slots)."""
        return self.core.world

    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Discrete:
        return self._act_space

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        if seed is not None:
            self._rng = seeding.np_random(seed)[0]
        scenario: Scenario | None = (options or {}).get("scenario")
        self.core.reset_world(0, self._rng, scenario)
        self.agents = list(self.possible_agents)
        self.paths = [[self.world.position(u)] for u in range(self.cfg.uavs)]
        infos = self.core.infos()
        return (
            {a: self.core.obs[u].copy() for u, a in enumerate(self.agents)},
            {a: _with_mask(infos[u]) for u, a in enumerate(self.agents)},
        )

    def step(self, actions: Mapping[str, int]) -> tuple[dict, dict, dict, dict, dict]:
        # A UAV that has left (or an agent left out of ``actions``) takes the parked action,
        # which the rules never carry out.
        row = np.full(self.cfg.uavs, D.PARKED, dtype=np.int64)
        for a in self.agents:
            if a in actions:
                row[self.possible_agents.index(a)] = int(actions[a])
        self.core.step(row)
        core = self.core
        infos_all = core.infos()
        obs, rewards, terms, truncs, infos = {}, {}, {}, {}, {}
        for a in self.agents:
            u = self.possible_agents.index(a)
            self.paths[u].append(self.world.position(u))
            obs[a] = core.obs[u].copy()
            rewards[a] = float(core.rewards[u])
            terms[a] = bool(core.terminated[u])
            truncs[a] = bool(core.truncated[u])
            infos[a] = _with_mask(infos_all[u])
        self.agents = [a for a in self.agents if not (terms[a] or truncs[a])]
        return obs, rewards, terms, truncs, infos

    def action_masks(self) -> dict[str, np.ndarray]:
        """Each agent still flying: its 12 actions that can change something now."""
        return {a: self.core.masks[self.possible_agents.index(a)].copy() for a in self.agents}

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return render_world(self.world, 0, self.paths, self.cfg.render_cell_px)

    def close(self) -> None:
        return None

    def state(self) -> np.ndarray:
        """Every agent's observation, stacked (a global state for centralised critics)."""
        return self.core.obs.copy()


def _with_mask(info: dict[str, Any]) -> dict[str, Any]:
    """An agent's info with its mask as int8, as PettingZoo's masked envs give it."""
    info = dict(info)
    info["action_mask"] = np.asarray(info["action_mask"], dtype=np.int8)
    return info


def parallel_env(**kwargs: Any) -> FleetParallelEnv:
    """A :class:`FleetParallelEnv` (PettingZoo's convention: ``module.parallel_env()``)."""
    return FleetParallelEnv(**kwargs)


class FleetVecEnv(SharedVecEnvPlumbing, ShapingHooks, VecEnv):
    """N fleet worlds of K UAVs as one Stable-Baselines3 ``VecEnv`` of N*K slots.

    Slot ``world * K + uav`` is one UAV: one policy acts for every UAV (parameter sharing),
    with ``action_masks()`` for sb3-contrib's ``MaskablePPO``, and no SuperSuit wrapper (which
    loses the masks). World ``i`` seeded with ``s`` steps exactly like
    :class:`FleetParallelEnv` reset with seed ``s``.

    A UAV's slot reports ``done`` on the step it leaves. Until its world's episode ends, the
    slot is parked: its action is not carried out, its mask holds one action, its reward is 0
    and it reports ``done`` again at every step (episodes of one step), so a masked policy
    gets no gradient from it (the one allowed action has probability 1) and the critic learns
    only that a parked UAV is worth 0. When every UAV has left or the step limit is reached,
    the world resets (every slot's ``infos[i]["terminal_observation"]`` and
    ``"TimeLimit.truncated"`` as SB3 expects) and every slot starts its next episode.
    ``infos[i]["fleet_active"]`` tells whether the slot's UAV flew this step.
    """

    def __init__(
        self,
        num_worlds: int,
        config: VCPPConfig | Mapping[str, Any] | None = None,
        parallel: bool | None = None,
        **settings: Any,
    ) -> None:
        self.cfg = VCPPConfig.resolve(config, settings)
        self.core = EnvCore(self.cfg, num_worlds, parallel)
        self.num_worlds = num_worlds
        self.uavs = self.cfg.uavs
        n = obs_size_for(self.cfg)
        self.render_mode = "rgb_array"
        super().__init__(
            num_worlds * self.uavs,
            spaces.Box(0.0, 1.0, (n,), dtype=np.float32),
            spaces.Discrete(D.N_ACTIONS),
        )
        self._rngs = [seeding.np_random(None)[0] for _ in range(num_worlds)]
        self._world_seeds: list[int | None] = [None] * num_worlds
        self._actions: np.ndarray | None = None
        self.step_snapshot = None

    @property
    def world(self) -> WorldBatch:
        """The underlying :class:`~pirl.world.state.WorldBatch`."""
        return self.core.world

    def seed(self, seed: int | None = None) -> Sequence[None | int]:
        """World ``i`` is seeded with ``seed + i`` at the next reset."""
        if seed is None:
            seed = int(np.random.randint(0, 2**31 - 1))
        self._world_seeds = [seed + g for g in range(self.num_worlds)]
        return [seed + s // self.uavs for s in range(self.num_envs)]

    def state_dict(self) -> dict[str, Any]:
        """Copies of what this env owns, enough to continue exactly."""
        return {"core": self.core.state_dict(), "rngs": copy.deepcopy(self._rngs)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Put a :meth:`state_dict` back."""
        self.core.load_state_dict(state["core"])
        self._rngs = copy.deepcopy(state["rngs"])

    def reset(self) -> np.ndarray:
        for g in range(self.num_worlds):
            if self._world_seeds[g] is not None:
                self._rngs[g] = seeding.np_random(self._world_seeds[g])[0]
            self.core.reset_world(g, self._rngs[g])
        self._world_seeds = [None] * self.num_worlds
        self._reset_options()
        self.reset_infos = self.core.infos()
        return self.core.obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        core = self.core
        was_left = self.world.left.copy()
        n_ended = core.step(self._actions)
        self._actions = None
        terminated, truncated = core.terminated, core.truncated
        dones = terminated | truncated
        rewards = core.rewards.astype(np.float32)
        infos = core.infos(lazy=True)
        self.step_snapshot = core.snapshot
        obs = core.obs.copy()
        for s in np.flatnonzero(dones):
            infos[s]["terminal_observation"] = obs[s].copy()
            infos[s]["TimeLimit.truncated"] = bool(truncated[s] and not terminated[s])
        for s in np.flatnonzero(was_left):
            infos[s]["fleet_active"] = False
        if n_ended:
            k = self.uavs
            for g in core.worlds_over():
                core.reset_world(int(g), self._rngs[g])
                rows = list(range(g * k, g * k + k))
                obs[rows] = core.obs[rows]
                for s, info in zip(rows, core.infos(rows, lazy=True), strict=True):
                    self.reset_infos[s] = info
        return obs, rewards, dones, infos

    def action_masks(self) -> np.ndarray:
        """``(num_envs, 12)`` booleans: each slot's actions that can change something now (a
        parked slot: one)."""
        return self.core.masks.copy()

    def get_images(self) -> Sequence[np.ndarray | None]:
        k = self.uavs
        return [
            render_world(self.world, g * k, None, self.cfg.render_cell_px)
            for g in range(self.num_worlds)
        ]


def make_fleet_vec_env(
    num_worlds: int,
    seed: int | None = 0,
    config: VCPPConfig | Mapping[str, Any] | None = None,
    parallel: bool | None = None,
    **settings: Any,
) -> FleetVecEnv:
    """A :class:`FleetVecEnv` whose world ``i`` is seeded with ``seed + i`` at first reset."""
    venv = FleetVecEnv(num_worlds, config, parallel, **settings)
    if seed is not None:
        venv.seed(seed)
    return venv


class MixedFleetVecEnv(SharedVecEnvPlumbing, ShapingHooks, VecEnv):
    """Fleets of several sizes side by side as one ``VecEnv``: a :class:`FleetVecEnv` per
    fleet size K, their slots one after the other (``sizes[0]``'s first), so one masked
    policy learns from fleets of every size at once. Each K gets about the same number of
    UAV slots: ``max(1, round(worlds / (len(sizes) * K)))`` worlds of K UAVs.

    Its shaping hooks (:class:`~pirl.env.shaping.ShapingHooks`) are the parts' joined, so
    PARE shapes every UAV's reward with advice about that UAV."""

    def __init__(
        self, worlds: int, config: VCPPConfig, sizes: Sequence[int], seed: int | None = 0
    ) -> None:
        self.parts = [
            make_fleet_vec_env(
                max(1, round(worlds / (len(sizes) * k))),
                None if seed is None else seed + 1_000 * i,
                config.replace(uavs=k),
            )
            for i, k in enumerate(sizes)
        ]
        self.sizes = list(sizes)
        self.cfg = config
        self._edges = np.cumsum([0] + [p.num_envs for p in self.parts])
        first = self.parts[0]
        self.render_mode = "rgb_array"
        super().__init__(int(self._edges[-1]), first.observation_space, first.action_space)
        self.step_snapshot: Any = None

    def _split(self, values: np.ndarray) -> list[np.ndarray]:
        return [values[a:b] for a, b in zip(self._edges[:-1], self._edges[1:], strict=True)]

    def reset(self) -> np.ndarray:
        obs = np.concatenate([p.reset() for p in self.parts])
        self.reset_infos = [i for p in self.parts for i in p.reset_infos]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        for part, chunk in zip(self.parts, self._split(np.asarray(actions)), strict=True):
            part.step_async(chunk)

    def step_wait(self):
        results = [p.step_wait() for p in self.parts]
        self.step_snapshot = _Terms(np.concatenate([p.step_snapshot.terms for p in self.parts]))
        obs, rewards, dones = (np.concatenate([r[i] for r in results]) for i in range(3))
        return obs, rewards, dones, [i for r in results for i in r[3]]

    def action_masks(self) -> np.ndarray:
        return np.concatenate([p.action_masks() for p in self.parts])

    def seed(self, seed: int | None = None) -> Sequence[None | int]:
        return [
            s
            for i, p in enumerate(self.parts)
            for s in p.seed(None if seed is None else seed + 1_000 * i)
        ]

    def state_dict(self) -> dict[str, Any]:
        """Every part's :meth:`FleetVecEnv.state_dict`, enough to continue exactly."""
        return {"parts": [p.state_dict() for p in self.parts]}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for part, saved in zip(self.parts, state["parts"], strict=True):
            part.load_state_dict(saved)

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [image for p in self.parts for image in p.get_images()]

    # -- the shaping hooks, joined over the parts ---------------------------------------------
    def poses(self) -> np.ndarray:
        return np.concatenate([p.poses() for p in self.parts])

    def step_poses(self) -> np.ndarray:
        return np.concatenate([p.step_poses() for p in self.parts])

    def parked(self) -> np.ndarray:
        return np.concatenate([p.parked() for p in self.parts])

    def step_weights(self, term: str) -> np.ndarray:
        return np.concatenate([p.step_weights(term) for p in self.parts])

    def set_step_term(self, term: str, values: np.ndarray) -> None:
        for part, chunk in zip(self.parts, self._split(np.asarray(values)), strict=True):
            part.set_step_term(term, chunk)

    def add_step_info(self, key: str, build: Callable[[int], Any]) -> None:
        for part, start in zip(self.parts, self._edges[:-1], strict=True):
            part.add_step_info(key, functools.partial(_shifted, build, int(start)))

    def world_views(self, worlds: Sequence[int], copy: bool = False) -> list[WorldView]:
        views = []
        for e in worlds:
            i = int(np.searchsorted(self._edges, int(e), side="right")) - 1
            views += self.parts[i].world_views([int(e) - int(self._edges[i])], copy)
        return views


def _shifted(build: Callable[[int], Any], start: int, e: int) -> Any:
    """``build`` of the joined slot a part's slot ``e`` is."""
    return build(start + e)


class _Terms:
    """The reward terms of a step (what training logs), the parts' one after the other."""

    def __init__(self, terms: np.ndarray) -> None:
        self.terms = terms


__all__ = [
    "FleetParallelEnv",
    "FleetVecEnv",
    "MixedFleetVecEnv",
    "agent_name",
    "make_fleet_vec_env",
    "parallel_env",
]
