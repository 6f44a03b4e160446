"""A fleet's episodes: K UAVs cover one world, each with its own policy (the planner's split,
one learned policy shared by every UAV, or one random policy per UAV), measured by the
fleet's coverage over time.

A fleet row holds the single-UAV row's headline metrics for the fleet (``vcr`` of the
fleet's coverage; ``steps`` the fleet's clock; ``battery_left`` the UAVs' mean; ``be`` and
``rvc`` from those and the summed redundant cells) and the fleet's own: ``uavs``,
``makespan_95`` and ``makespan_99`` (the fleet's steps until it had covered 0.95 and 0.99 of
the seeable cells; None when never), ``energy_used`` (full batteries), ``uav_overlap``
(ground cells seen by more than one UAV, over cells seen; ``overlap`` keeps the single-UAV
meaning, cells seen by several views of one step), ``near_misses`` (pairs of UAVs in
face-adjacent cells, summed over steps), yields, collisions, each UAV's credited cells and
``coverage_steps`` (the fleet's step at which it first covered 5%, 10%, ... 100% of the
seeable cells, None when never: the coverage-over-time curve). The speed-up of K UAVs is
``makespan(K) / makespan(1)`` from the same seed (UAV 1 starts where the single UAV starts).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from pirl.agents.boustrophedon import BoustrophedonPolicy, fleet_planners
from pirl.agents.llm_only import LLMOnlyPolicy
from pirl.agents.loading import LearnedPolicy, act_rng
from pirl.agents.methods import METHODS
from pirl.agents.policy import Policy, RandomPolicy
from pirl.config.choices import Sim
from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore
from pirl.env.render import render_world
from pirl.world import dynamics as D
from pirl.world.metrics import fleet_metrics
from pirl.world.state import WorldBatch

MILESTONES = (0.95, 0.99)
"""Shares of the seeable cells whose first step is a fleet's makespan."""
CURVE = tuple(round(0.05 * i, 2) for i in range(1, 21))
"""Shares of the seeable cells whose first step a fleet row records (``coverage_steps``)."""
_UAV_SALT = 0xF1EE7


class Team:
    """The K UAVs' choices in one world: ``reset`` at the start of an episode, then ``act``
    once per step with every UAV's observation and info and whether it is still in the
    episode (a UAV that has left must be given :data:`~pirl.world.dynamics.PARKED`)."""

    def reset(self, world: WorldBatch, g: int, seed: int) -> None:
        raise NotImplementedError

    def act(self, obs: np.ndarray, infos: list[dict[str, Any]], active: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class PolicyTeam(Team):
    """One policy object per UAV, built for each episode by ``build(world, g)``."""

    def __init__(self, build: Any) -> None:
        self._build = build
        self._team: list[Policy] = []

    def reset(self, world: WorldBatch, g: int, seed: int) -> None:
        self._team = list(self._build(world, g))
        k = world.uavs
        for u, policy in enumerate(self._team):
            policy.reset(world, g * k + u, seed=uav_seed(seed, u))

    def act(self, obs: np.ndarray, infos: list[dict[str, Any]], active: np.ndarray) -> np.ndarray:
        return np.array(
            [p.act(obs[u], infos[u]) if active[u] else D.PARKED for u, p in enumerate(self._team)],
            dtype=np.int64,
        )


class SharedTeam(Team):
    """One learned policy shared by every UAV (parameter sharing): one forward pass per step
    for the whole fleet, each UAV sampling with its own generator when acting stochastic
    (UAV 1's is the single UAV's, so K = 1 acts as ``pirl evaluate`` does)."""

    def __init__(self, policy: LearnedPolicy) -> None:
        self.policy = policy
        self._rngs: list[np.random.Generator] = []

    def reset(self, world: WorldBatch, g: int, seed: int) -> None:
        self._rngs = [act_rng(uav_seed(seed, u)) for u in range(world.uavs)]

    def act(self, obs: np.ndarray, infos: list[dict[str, Any]], active: np.ndarray) -> np.ndarray:
        masks = np.array([i["action_mask"] for i in infos], dtype=bool)
        actions = self.policy.act_batch(np.asarray(obs), self._rngs, masks).astype(np.int64)
        return np.where(active, actions, D.PARKED)


def check_fleets(env: VCPPConfig, uavs: list[int], sims: list[str], methods: list[str]) -> None:
    """Fleet sizes an evaluation can play, refused in one line: each K within the env's
    bounds, the grid simulator only (a fleet's missions fly in physics with ``pirl fly``),
    and methods that can fly in a fleet (:attr:`~pirl.agents.methods.Method.fleet`)."""
    for k in uavs:
        env.replace(uavs=k)  # the env's own bounds and message
    if any(sim != Sim.GRID for sim in sims):
        raise ConfigError(
            f"--uavs {','.join(map(str, uavs))} plays fleets on the grid only (--sim grid); "
            "a fleet's missions fly together in physics with pirl fly"
        )
    for name in methods:
        found = METHODS.get(name)
        if found is not None and not found.fleet:
            raise ConfigError(f"--uavs: {found.label} flies one UAV; leave it out of a fleet")


def check_fleet_starts(env: VCPPConfig, uavs: int) -> None:
    """Refuse (one line) a fleet larger than the free cells next to a world's start can hold:
    one world of ``uavs`` UAVs is reset as every scenario is."""
    EnvCore(env.replace(uavs=uavs), 1).reset_world(0, seeding.np_random(0)[0])


def fleet_records(
    cfg: VCPPConfig, policy: Policy, seeds: list[int], base: dict, ids: dict
) -> list[dict[str, Any]]:
    """One evaluation record per seed of ``policy`` flown as a fleet of ``cfg.uavs`` UAVs:
    ``base`` (method, label, sim, act, world), the seed, ``ids`` (train seed, source) and
    the fleet's row."""
    team = team_for(policy)
    records = []
    for seed in seeds:
        calls = getattr(policy, "calls", 0)
        row = run_fleet_episode(cfg, seed, team).row
        records.append({
            **base, "uavs": cfg.uavs, "seed": seed, **ids, **row,
            "llm_calls": getattr(policy, "calls", 0) - calls,
        })  # fmt: skip
    return records


def uav_seed(seed: int, u: int) -> int:
    """The seed UAV ``u``'s policy is reset with: the scenario's for UAV 1 (index 0), so a
    fleet of one acts as the single UAV acts, a distinct one for each teammate."""
    if u == 0:
        return seed
    return int(np.random.SeedSequence([seed, _UAV_SALT, u]).generate_state(1)[0])


def team_for(policy: Policy) -> Team:
    """The fleet version of a method's policy: the planner flies the area split, a learned
    policy is shared, a random policy and LLM-only are one per UAV; anything else cannot fly
    in a fleet."""
    if isinstance(policy, BoustrophedonPolicy):
        return PolicyTeam(fleet_planners)
    if isinstance(policy, LearnedPolicy):
        return SharedTeam(policy)
    if isinstance(policy, RandomPolicy):
        return PolicyTeam(lambda world, g: [RandomPolicy() for _ in range(world.uavs)])
    if isinstance(policy, LLMOnlyPolicy):  # each UAV asks about itself, teammates named
        return PolicyTeam(lambda world, g: [policy.teammate() for _ in range(world.uavs)])
    raise ConfigError(f"{policy.label} flies one UAV; a fleet (--uavs above 1) cannot use it")


@dataclass
class FleetEpisode:
    """One fleet episode: its row, the fleet's coverage after each step and, when recorded,
    its frames."""

    seed: int
    row: dict[str, Any]
    coverage: list[float] = field(default_factory=list)
    frames: list[np.ndarray] = field(default_factory=list)


def run_fleet_episode(
    cfg: VCPPConfig, seed: int, team: Team | None = None, record: bool = False
) -> FleetEpisode:
    """Reset a world of ``cfg.uavs`` UAVs with ``seed`` (as ``VCPPEnv.reset(seed=seed)`` and
    :class:`~pirl.env.fleet.FleetParallelEnv` do) and let ``team`` (default: the planner's
    split) fly it until the fleet's episode ends; ``record`` keeps a frame per step (each
    UAV in its colour)."""
    team = team or PolicyTeam(fleet_planners)
    core = EnvCore(cfg, 1)
    core.reset_world(0, seeding.np_random(seed)[0])
    world = core.world
    team.reset(world, 0, seed)
    infos = core.infos()
    coverage = [_coverage(world)]
    frames = [render_world(world, 0, None, cfg.render_cell_px)] if record else []
    while True:
        core.step(team.act(core.obs, infos, ~world.left[: world.uavs].astype(bool)))
        infos = core.infos()
        coverage.append(_coverage(world))
        if record:
            frames.append(render_world(world, 0, None, cfg.render_cell_px))
        if len(core.worlds_over()):
            break
    return FleetEpisode(seed, fleet_row(world, 0, coverage), coverage, frames)


def fleet_row(world: WorldBatch, g: int, coverage: Sequence[float]) -> dict[str, Any]:
    """The row of world ``g``'s fleet episode (see the module's docstring); ``coverage`` is
    the fleet's coverage after each step, from the reset on."""
    k = world.uavs
    rows = slice(g * k, g * k + k)
    st = world.status[rows]
    fleet = fleet_metrics(world, g)
    covered = fleet["covered"]
    battery_left = float(np.mean([world.battery(s) for s in range(g * k, g * k + k)]))
    everything = int(world.coverable_all[g])
    guarded = int(world.guarded[rows].sum())
    uav_steps = int(st["steps"].sum())
    curve = np.asarray(coverage)
    return {
        **fleet,
        "vcr_all": covered / everything if everything else 0.0,
        "be": fleet["vcr"] / (2.0 - battery_left),
        "rvc": int(st["redundant_cells"].sum()) / covered if covered else 0.0,
        "overlap": int(st["multi_cells"].sum()) / covered if covered else 0.0,
        "steps": fleet["fleet_steps"],
        "uav_steps": uav_steps,
        "battery_left": battery_left,
        "guarded_steps": guarded,
        "guarded_share": guarded / uav_steps if uav_steps else 0.0,
        "steps_to_99": _first(curve, 0.99),
        "makespan_95": _first(curve, 0.95),
        "makespan_99": _first(curve, 0.99),
        "coverage_steps": [_first(curve, share) for share in CURVE],
    }


def _first(curve: np.ndarray, share: float) -> int | None:
    reached = np.flatnonzero(curve >= share - 1e-12)
    return int(reached[0]) if len(reached) else None


def _coverage(world: WorldBatch) -> float:
    st = world.status[0]
    return float(st["covered"]) / max(1, int(st["coverable"]))


def speed_ups(rows: dict[int, list[dict]], key: str = "makespan_99") -> dict[int, float | None]:
    """The mean over seeds of makespan(K) / makespan(1), per fleet size K (``rows[K]``: the
    episodes of K UAVs, seed by seed in the same order as ``rows[1]``); None where a
    makespan was never reached."""
    out: dict[int, float | None] = {}
    for k, episodes in rows.items():
        ratios = []
        for one, many in zip(rows[1], episodes, strict=True):
            if one[key] is None or many[key] is None:
                ratios = None
                break
            ratios.append(many[key] / one[key])
        out[k] = float(np.mean(ratios)) if ratios else None
    return out


__all__ = [
    "CURVE",
    "check_fleet_starts",
    "check_fleets",
    "fleet_records",
    "FleetEpisode",
    "PolicyTeam",
    "SharedTeam",
    "Team",
    "fleet_row",
    "run_fleet_episode",
    "speed_ups",
    "team_for",
    "uav_seed",
]
