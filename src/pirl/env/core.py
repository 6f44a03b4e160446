"""The environment logic shared by the single and the batched environment.

:class:`EnvCore` couples a :class:`~pirl.world.state.WorldBatch` with reward weights and the
observation builder. ``VCPPEnv`` is an ``EnvCore`` of one world, ``VCPPVecEnv`` one of N, so
both follow the same rules by construction.
"""

from __future__ import annotations

from itertools import repeat
from typing import Any

import numba
import numpy as np

from pirl.config.world import REWARD_TERMS, VCPPConfig
from pirl.env.info import InfoSnapshot, LazyInfo
from pirl.env.observation import _observation, build_observations, obs_extras, obs_size_for
from pirl.env.rewards import draw_weights
from pirl.world import dynamics as D
from pirl.world.dynamics import F_TERMINATED, F_TRUNCATED, N_ACTIONS, PI_STEP_LIMIT, step_one
from pirl.world.metrics import episode_metrics
from pirl.world.state import Scenario, WorldBatch


def _make_step_kernel(parallel: bool):
    """A kernel that steps every world, weighs its reward terms and builds its observation.

    One fused loop (one thread launch, data still in cache) over the rules defined once in
    :func:`pirl.world.dynamics.step_one` and :func:`pirl.env.observation._observation`, which
    numba inlines into it. Returns how many worlds ended, or -1 (nothing stepped) when an
    action lies outside [0, N_ACTIONS).
    """
    loop = numba.prange if parallel else range

    @numba.njit(cache=True, parallel=parallel)
    def kernel(
        actions, ints, energy, rng, blocked, coverable, views, redmask, visits, blk_todo,
        blk_total, bx, by, obstacles, pf, pi, buf, terms, flags, weights, rewards, capacity,
        window, obs, masks, extras,
    ):  # fmt: skip
        for e in range(actions.shape[0]):
            if actions[e] < 0 or actions[e] >= N_ACTIONS:
                return -1
        ended = 0
        for e in loop(actions.shape[0]):
            step_one(
                e, actions, ints, energy, rng, blocked, coverable, views, redmask, visits,
                blk_todo, bx, by, obstacles, pf, pi, buf, terms, flags,
            )  # fmt: skip
            r = 0.0
            for k in range(terms.shape[1]):
                r += terms[e, k] * weights[e, k]
            rewards[e] = r
            _observation(
                e, ints, energy, capacity, pi[PI_STEP_LIMIT], blocked, coverable, views,
                blk_todo, blk_total, window, obs, visits, extras,
            )  # fmt: skip
            D.action_mask(e, ints, blocked, pi, masks)
            ended += flags[e, F_TERMINATED] | flags[e, F_TRUNCATED]
        return ended

    return kernel


_step_serial = _make_step_kernel(False)
_step_parallel = _make_step_kernel(True)


class EnvCore:
    """N worlds plus their reward weights, observations and per-step info."""

    def __init__(self, cfg: VCPPConfig, num: int, parallel: bool | None = None) -> None:
        self.cfg = cfg
        self.num = num
        self.world = WorldBatch(cfg, num, parallel)
        self.weights = np.zeros((num, len(REWARD_TERMS)), dtype=np.float64)
        self.rewards = np.zeros(num, dtype=np.float64)
        self.obs = np.zeros((num, obs_size_for(cfg)), dtype=np.float32)
        self.extras = obs_extras(cfg)
        # Which actions can change something in each world's current state (written with the
        # observation after every reset and step; see dynamics.action_mask).
        self.masks = np.ones((num, N_ACTIONS), dtype=np.bool_)
        self._all = np.arange(num, dtype=np.int64)
        self.ended = -1  # worlds ended on the last step; -1 = unknown (read the flags)

    def reset_world(
        self, e: int, rng: np.random.Generator, scenario: Scenario | None = None
    ) -> None:
        """New episode in world ``e``: scenario (drawn from ``rng`` unless given), weights."""
        if scenario is None:
            self.world.reset_world(e, rng)
        else:
            self.world.load_scenario(e, scenario)
        self.weights[e] = draw_weights(self.cfg, rng)
        self.rewards[e] = 0.0
        self.ended = -1  # other worlds may still hold an ended step: look at the flags
        self._observe(np.array([e], dtype=np.int64))

    def step(self, actions: np.ndarray) -> int:
        """One action per world; afterwards read ``obs``, ``rewards`` and ``world.flags``.

        Returns how many worlds' episodes ended on this step.
        """
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num)
        w = self.world
        kernel = _step_parallel if w.parallel else _step_serial
        ended = kernel(
            actions, w.ints, w.energy, w.rng, w.blocked, w.coverable, w.views, w.redmask,
            w.visits, w.blk_todo, w.blk_total, w.bx, w.by, w.obstacles, w.pf, w.pi, w.buf,
            w.terms, w.flags, self.weights, self.rewards, w.capacity, self.cfg.obs_window,
            self.obs, self.masks, self.extras,
        )  # fmt: skip
        if ended < 0:
            raise ValueError(f"actions must be integers in [0, {D.N_ACTIONS}); got {actions}")
        self.ended = ended
        return ended

    def refresh_masks(self) -> None:
        """Recompute every world's valid actions (after its state was loaded from elsewhere,
        e.g. a checkpoint)."""
        w = self.world
        D.action_masks(self._all, w.ints, w.blocked, w.pi, self.masks)

    def _observe(self, worlds: np.ndarray) -> None:
        w = self.world
        build_observations(
            worlds, w.ints, w.energy, w.capacity, w.step_limit, w.blocked, w.coverable,
            w.views, w.blk_todo, w.blk_total, self.cfg.obs_window, self.obs, w.visits, self.extras,
        )  # fmt: skip
        D.action_masks(worlds, w.ints, w.blocked, w.pi, self.masks)

    @property
    def terminated(self) -> np.ndarray:
        return self.world.flags[:, D.F_TERMINATED].astype(bool)

    @property
    def truncated(self) -> np.ndarray:
        return self.world.flags[:, D.F_TRUNCATED].astype(bool)

    def infos_snapshot(self) -> InfoSnapshot:
        """Copies of what every world's info is made of, as of the last step or reset (with
        the episode metrics of the worlds whose episode just ended)."""
        w = self.world
        metrics = {}
        if self.ended:  # most steps end no episode: skip the search
            done = np.flatnonzero(w.flags[:, D.F_TERMINATED] | w.flags[:, D.F_TRUNCATED])
            metrics = {int(e): episode_metrics(w, int(e)) for e in done}
        return InfoSnapshot(
            w.ints, w.terms, self.weights, w.flags, w.energy, w.capacity, metrics, self.masks
        )

    def infos(self, worlds: list[int] | None = None, lazy: bool = False) -> list[dict[str, Any]]:
        """The ``info`` dict of each world (all by default), as of the last step or reset.

        With ``lazy`` the dicts are :class:`~pirl.env.info.LazyInfo` (filled on first read).
        """
        idx = range(self.num) if worlds is None else worlds
        snap = self.snapshot = self.infos_snapshot()
        if lazy:
            return list(map(LazyInfo, repeat(snap), idx))
        return [snap.info(e) for e in idx]
