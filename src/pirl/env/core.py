"""The environment logic shared by the single, the batched and the fleet environments.

:class:`EnvCore` couples a :class:`~pirl.world.state.WorldBatch` with reward weights and the
observation builder. ``VCPPEnv`` is an ``EnvCore`` of one world, ``VCPPVecEnv`` one of N, and
the fleet envs (:mod:`pirl.env.fleet`) one of N worlds of K UAVs, whose rows (rewards,
observations, masks) are slots, one per (world, UAV); all follow the same rules by
construction.
"""

from __future__ import annotations

from itertools import repeat
from typing import Any, NamedTuple

import numba
import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.world import REWARD_TERMS, VCPPConfig
from pirl.env.info import InfoSnapshot, LazyInfo
from pirl.env.observation import build_observations, obs_layout, obs_size_for, observation
from pirl.env.rewards import draw_weights
from pirl.world import dynamics as D
from pirl.world.dynamics import N_ACTIONS, step_one
from pirl.world.metrics import episode_metrics
from pirl.world.scenario import Scenario
from pirl.world.state import WorldBatch


class EnvArrays(NamedTuple):
    """What the environment adds to each world (first axis = world), as the kernel takes it."""

    weights: np.ndarray
    """(N*K, 8) reward weights, in the order of ``REWARD_TERMS`` (a world's UAVs share one
    draw)."""
    rewards: np.ndarray
    """(N*K,) reward of the last step."""
    obs: np.ndarray
    """(N*K, obs_size) float32 observations."""
    masks: np.ndarray
    """(N*K, 12) actions that can change something now (see ``dynamics.action_mask``)."""


@numba.njit(**D.BATCH_KERNEL)
def step_world(w, p, layout, env, e, a):
    """Step world e with action ``a``, weigh its reward, write its observation and mask;
    return 1 when its episode ended.

    Its own function, not inlined into the loop below: numba's parallel loop loses writes
    made through a tuple's fields in its body, but not those made in a function it calls.
    """
    step_one(w, p, e, a)
    _close_slot(w, p, layout, env, e)
    return w.flags[e]["terminated"] | w.flags[e]["truncated"]


@numba.njit(cache=True)
def _close_slot(w, p, layout, env, e):
    """Slot e's reward (its terms weighed), observation and mask after a step."""
    terms, weights = w.terms, env.weights
    r = 0.0
    for k in range(terms.shape[1]):
        r += terms[e, k] * weights[e, k]
    env.rewards[e] = r
    observation(w, p, layout, e, env.obs)
    D.action_mask(w, p, e, env.masks)


@numba.njit(**D.BATCH_KERNEL)
def step_fleet_world(w, p, layout, env, g, actions):
    """Step every UAV of world g (:func:`pirl.world.dynamics.step_fleet`), then weigh each
    UAV's reward and write its observation and mask, each seeing where every teammate ended
    up; return 1 when the world's episode ended."""
    over = D.step_fleet(w, p, g, actions)
    k = D.fleet_size(w)
    for e in range(g * k, g * k + k):
        _close_slot(w, p, layout, env, e)
    return over


def _make_step_kernel(parallel: bool):
    """A kernel that steps every world, weighs its reward terms and builds its observation.

    One fused loop (one thread launch, data still in cache) over :func:`step_world`, the rules
    defined once in :func:`pirl.world.dynamics.step_one` and
    :func:`pirl.env.observation.observation`. Returns how many worlds ended, or -1 (nothing
    stepped) when an action lies outside [0, N_ACTIONS).
    """
    loop = numba.prange if parallel else range

    # numba's parallel loop needs its reference counting; step_world still goes without.
    options = {"cache": True, "parallel": True} if parallel else D.BATCH_KERNEL

    @numba.njit(**options)
    def kernel(w, p, layout, env, actions):
        for e in range(actions.shape[0]):
            if actions[e] < 0 or actions[e] >= N_ACTIONS:
                return -1
        ended = 0
        for e in loop(actions.shape[0]):
            ended += step_world(w, p, layout, env, e, actions[e])
        return ended

    return kernel


_step_serial = _make_step_kernel(False)
_step_parallel = _make_step_kernel(True)


def _make_fleet_kernel(parallel: bool):
    """The step kernel of worlds of K UAVs: one loop over worlds, each world's UAVs in turn
    (:func:`step_fleet_world`). Returns how many worlds ended, or -1 (nothing stepped) when an
    action lies outside [0, N_ACTIONS)."""
    loop = numba.prange if parallel else range
    options = {"cache": True, "parallel": True} if parallel else D.BATCH_KERNEL

    @numba.njit(**options)
    def kernel(w, p, layout, env, actions):
        for e in range(actions.shape[0]):
            if actions[e] < 0 or actions[e] >= N_ACTIONS:
                return -1
        ended = 0
        for g in loop(w.coverable.shape[0]):
            ended += step_fleet_world(w, p, layout, env, g, actions)
        return ended

    return kernel


_fleet_serial = _make_fleet_kernel(False)
_fleet_parallel = _make_fleet_kernel(True)


def require_one_uav(cfg: VCPPConfig, api: str) -> None:
    """Refuse a fleet (``env.uavs`` > 1) in an environment API that flies one UAV."""
    if cfg.uavs != 1:
        raise ConfigError(
            f"env.uavs={cfg.uavs}: {api} flies one UAV; a fleet flies in "
            "pirl.env.fleet (FleetParallelEnv for PettingZoo, FleetVecEnv for Stable-Baselines3)"
        )


class EnvCore:
    """N worlds of K UAVs (``cfg.uavs``) plus their reward weights, observations and per-step
    info; rows of the env arrays are slots (world * K + UAV), worlds when K = 1."""

    def __init__(self, cfg: VCPPConfig, num: int, parallel: bool | None = None) -> None:
        self.cfg = cfg
        self.num = num
        self.world = WorldBatch(cfg, num, parallel)
        self.uavs = k = self.world.uavs
        self.slots = slots = num * k
        self.arrays = EnvArrays(
            weights=np.zeros((slots, len(REWARD_TERMS)), dtype=np.float64),
            rewards=np.zeros(slots, dtype=np.float64),
            obs=np.zeros((slots, obs_size_for(cfg)), dtype=np.float32),
            # Written with the observation after every reset and step.
            masks=np.ones((slots, N_ACTIONS), dtype=np.bool_),
        )
        self.weights, self.rewards, self.obs, self.masks = self.arrays
        self.layout = obs_layout(cfg)
        self._all = np.arange(slots, dtype=np.int64)
        self.ended = -1  # worlds ended on the last step; -1 = unknown (read the flags)

    def reset_world(
        self, e: int, rng: np.random.Generator, scenario: Scenario | None = None
    ) -> None:
        """New episode in world ``e`` (all its UAVs): scenario (drawn from ``rng`` unless
        given), weights."""
        if scenario is None:
            self.world.reset_world(e, rng)
        else:
            self.world.load_scenario(e, scenario)
        rows = slice(e * self.uavs, (e + 1) * self.uavs)
        self.weights[rows] = draw_weights(self.cfg, rng)
        self.rewards[rows] = 0.0
        self.ended = -1  # other worlds may still hold an ended step: look at the flags
        self._observe(np.arange(rows.start, rows.stop, dtype=np.int64))

    def step(self, actions: np.ndarray) -> int:
        """One action per slot; afterwards read ``obs``, ``rewards`` and ``world.flags``.

        Returns how many worlds' episodes ended on this step.
        """
        actions = np.asarray(actions, dtype=np.int64).reshape(self.slots)
        w = self.world
        if self.uavs > 1:
            kernel = _fleet_parallel if w.parallel else _fleet_serial
        else:
            kernel = _step_parallel if w.parallel else _step_serial
        ended = kernel(w.arrays, w.params, self.layout, self.arrays, actions)
        if ended < 0:
            raise ValueError(f"actions must be integers in [0, {D.N_ACTIONS}); got {actions}")
        # A fleet's UAV may leave (its slot done) while its world goes on: read the flags.
        self.ended = ended if self.uavs == 1 else -1
        return ended

    def state_dict(self) -> dict[str, Any]:
        """Copies of what continues an episode exactly: the worlds, the weights, the
        observations (the masks are derived from the worlds)."""
        return {
            "world": self.world.state_dict(),
            "weights": self.weights.copy(),
            "obs": self.obs.copy(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Put a :meth:`state_dict` back into this core's own arrays."""
        self.world.load_state_dict(state["world"])
        self.weights[...] = state["weights"]
        self.obs[...] = state["obs"]
        self.ended = -1
        w = self.world
        D.action_masks(w.arrays, w.params, self._all, self.masks)

    def _observe(self, worlds: np.ndarray) -> None:
        w = self.world
        build_observations(w.arrays, w.params, self.layout, worlds, self.obs)
        D.action_masks(w.arrays, w.params, worlds, self.masks)

    def worlds_over(self) -> np.ndarray:
        """Indices of the worlds whose episode ended on the last step (every UAV left, or
        truncated)."""
        f = self.world.flags
        done = (f["terminated"] | f["truncated"]).astype(bool)
        return np.flatnonzero(done.reshape(self.num, self.uavs).all(axis=1))

    @property
    def terminated(self) -> np.ndarray:
        return self.world.flags["terminated"].astype(bool)

    @property
    def truncated(self) -> np.ndarray:
        return self.world.flags["truncated"].astype(bool)

    def infos_snapshot(self) -> InfoSnapshot:
        """Copies of what every world's info is made of, as of the last step or reset (with
        the episode metrics of the worlds whose episode just ended)."""
        w = self.world
        metrics = {}
        if self.ended:  # most steps end no episode: skip the search
            done = np.flatnonzero(w.flags["terminated"] | w.flags["truncated"])
            metrics = {int(e): episode_metrics(w, int(e)) for e in done}
        return InfoSnapshot(w, self.weights, metrics, self.masks)

    def infos(self, worlds: list[int] | None = None, lazy: bool = False) -> list[dict[str, Any]]:
        """The ``info`` dict of each slot (all by default), as of the last step or reset.

        With ``lazy`` the dicts are :class:`~pirl.env.info.LazyInfo` (filled on first read).
        """
        idx = range(self.slots) if worlds is None else worlds
        snap = self.snapshot = self.infos_snapshot()
        if lazy:
            return list(map(LazyInfo, repeat(snap), idx))
        return [snap.info(e) for e in idx]


def compile_kernels() -> None:
    """Compile, or load from numba's cache, the serial step kernels of one UAV and of a fleet,
    once per cache folder: processes that start together (training workers, test workers)
    wait for the first to write the cache instead of each compiling the same kernels."""
    from pirl import _numba_cache

    with _numba_cache.compiling():
        for uavs in (1, 2):
            core = EnvCore(VCPPConfig(size=(5, 5, 3), uavs=uavs), 1, parallel=False)
            core.reset_world(0, np.random.default_rng(0))
            core.step(np.zeros(core.slots, dtype=np.int64))
