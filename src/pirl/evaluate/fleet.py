"""A fleet's episodes: K UAVs cover one world, each with its own policy (the planner's split,
or one learned policy shared by every UAV), measured by the fleet's coverage over time.

Rows carry ``uavs``, the fleet VCR, ``makespan_95`` and ``makespan_99`` (the fleet's steps
until it had covered 0.95 and 0.99 of the seeable cells; None when never), the energy used
(full batteries), ``uav_overlap`` (cells seen by more than one UAV, over cells seen),
``near_misses`` (pairs of UAVs in face-adjacent cells, summed over steps), yields and
collisions. The speed-up of K UAVs is ``makespan(K) / makespan(1)`` from the same seed (UAV
1 starts where the single UAV starts).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from gymnasium.utils import seeding

from pirl.agents.boustrophedon import fleet_planners
from pirl.agents.policy import Policy
from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore
from pirl.world import dynamics as D
from pirl.world.metrics import fleet_metrics
from pirl.world.state import WorldBatch

MILESTONES = (0.95, 0.99)
"""Shares of the seeable cells whose first step is a fleet's makespan."""

PolicyFactory = Callable[[WorldBatch, int], Sequence[Policy]]
"""Builds the K policies of world ``g`` (after its reset), one per UAV in slot order."""


@dataclass
class FleetEpisode:
    """One fleet episode: its row, and the fleet's coverage after each step."""

    seed: int
    row: dict[str, float | int | None | list[int]]
    coverage: list[float] = field(default_factory=list)


def planner_fleet(world: WorldBatch, g: int) -> Sequence[Policy]:
    """The classical baseline: the area split, then the boustrophedon planner per part."""
    return fleet_planners(world, g)


def run_fleet_episode(
    cfg: VCPPConfig, seed: int, policies: PolicyFactory = planner_fleet
) -> FleetEpisode:
    """Reset a world of ``cfg.uavs`` UAVs with ``seed`` (as ``VCPPEnv.reset(seed=seed)`` and
    :class:`~pirl.env.fleet.FleetParallelEnv` do) and fly every UAV with its policy until the
    fleet's episode ends."""
    core = EnvCore(cfg, 1)
    core.reset_world(0, seeding.np_random(seed)[0])
    world = core.world
    k = world.uavs
    team = list(policies(world, 0))
    for u, policy in enumerate(team):
        policy.reset(world, u, seed=seed)
    infos = core.infos()
    coverage = [_coverage(world)]
    first = dict.fromkeys(MILESTONES)
    while True:
        actions = np.full(k, D.PARKED, dtype=np.int64)
        for u, policy in enumerate(team):
            if not world.left[u]:
                actions[u] = policy.act(core.obs[u], infos[u])
        core.step(actions)
        infos = core.infos()
        coverage.append(_coverage(world))
        for share in MILESTONES:
            if first[share] is None and coverage[-1] >= share:
                first[share] = len(coverage) - 1
        if len(core.worlds_over()):
            break
    row = {
        **fleet_metrics(world, 0),
        "makespan_95": first[0.95],
        "makespan_99": first[0.99],
    }
    return FleetEpisode(seed, row, coverage)


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


__all__ = ["FleetEpisode", "planner_fleet", "run_fleet_episode", "speed_ups"]
