"""``pirl plan --uavs K``: one fleet episode written as K missions that never meet.

The fleet's episode (wind off) is played as :func:`pirl.evaluate.fleet.run_fleet_episode`
plays it; each UAV's steps become its own mission folder ``uav-1/``, ``uav-2/``, ... (the
files and ``summary.json`` of a single mission, :mod:`pirl.missions.write`, with home at
that UAV's start cell), and ``fleet.json`` says what the fleet does together: its coverage,
makespan, each UAV's take-off delay per wave and the closest approach
(:mod:`pirl.missions.separation`). The whole folder is staged and renamed into place at once.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from pirl._atomic import write_atomic
from pirl.config.errors import ConfigError
from pirl.config.mission import MissionSettings
from pirl.config.physics import PhysicsConfig
from pirl.config.run import RunConfig
from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore
from pirl.evaluate.fleet import Team, fleet_row, team_for
from pirl.missions.fly import (
    FileFollower,
    flight_mission,
    flown_figures,
    read_flight,
    write_flown,
)
from pirl.missions.items import Episode, Step
from pirl.missions.separation import Separation, separate, track
from pirl.missions.write import (
    Planned,
    check_new_folder,
    geo_for,
    mission_source,
    plan_episode,
    staged,
    write_files,
    write_mission,
)

FLEET_FILE = "fleet.json"


def uav_folder(u: int) -> str:
    """The folder of UAV ``u`` (0-based) in a fleet's missions: ``uav-1``, ``uav-2``, ..."""
    return f"uav-{u + 1}"


def record_fleet(cfg: VCPPConfig, team: Team, seed: int) -> tuple[list[Episode], dict[str, Any]]:
    """Play ``team`` on scenario ``seed`` of ``cfg`` (``cfg.uavs`` UAVs) with wind off,
    recording each UAV's steps until it leaves; returns the episodes and the fleet's row."""
    core = EnvCore(cfg.replace(wind_prob=0.0), 1)
    core.reset_world(0, seeding.np_random(seed)[0])
    world, k = core.world, cfg.uavs
    team.reset(world, 0, seed)
    starts = [world.position(u) for u in range(k)]
    cameras = [world.camera_setting(u) for u in range(k)]
    firsts = [world.footprint(u) for u in range(k)]
    steps: list[list[Step]] = [[] for _ in range(k)]
    infos = core.infos()
    coverage = [_coverage(world)]
    while True:
        active = ~world.left[:k].astype(bool)
        core.step(team.act(core.obs, infos, active))
        infos = core.infos()
        coverage.append(_coverage(world))
        for u in np.flatnonzero(active):
            captured = int(world.flags[u]["new_cells"]) > 0
            view = world.footprint(u) if captured else np.zeros((0, 2), dtype=np.int64)
            steps[u].append(Step(world.position(u), world.camera_setting(u), captured, view))
        if len(core.worlds_over()):
            break
    row = fleet_row(world, 0, coverage)
    episodes = [
        Episode(
            starts[u],
            cameras[u],
            firsts[u],
            steps[u],
            _uav_metrics(row, u, world.battery(u), int(world.status[u]["steps"])),
        )  # fmt: skip
        for u in range(k)
    ]
    return episodes, row


def _uav_metrics(row: dict[str, Any], u: int, battery: float, steps: int) -> dict[str, Any]:
    """UAV ``u``'s share of the fleet's row: its own ``vcr`` is the cells credited to it (what
    ``pirl fly`` of its folder alone is compared with: flown alone it sees at least those),
    beside ``fleet_vcr``."""
    share = row["credit"][u] / row["coverable"] if row["coverable"] else 0.0
    everything = row["covered"] / row["vcr_all"] if row["vcr_all"] else 0
    return {
        **row, "fleet_vcr": row["vcr"], "vcr": share,
        "vcr_all": row["credit"][u] / everything if everything else 0.0,
        "battery_left": battery, "steps": steps,
    }  # fmt: skip


def _coverage(world: Any) -> float:
    st = world.status[0]
    return float(st["covered"]) / max(1, int(st["coverable"]))


def fleet_separation(plans: list[Planned], s: MissionSettings) -> Separation:
    """The separation check of the fleet's sorties (:func:`pirl.missions.separation.separate`)."""
    tracks = [
        [
            track(
                [(i.kind, i.cell) for i in sortie.items],
                p.ep.start[:2],
                p.geo.georef.cell_size_m,
                p.geo.level_m,
                s,
            )  # fmt: skip
            for sortie in p.parts
        ]
        for p in plans
    ]
    return separate(tracks, s)


def write_fleet_missions(
    out: Path,
    cfg: VCPPConfig,
    settings: MissionSettings,
    team: Team,
    seed: int,
    what: str,
    gimbal: str = "v2",
) -> dict[str, Any]:
    """Record the fleet's episode, check its separation and write ``uav-N/`` per UAV and
    ``fleet.json`` into the new folder ``out`` (atomically; refused if it exists, or in one
    line when a plan cannot keep its separation); returns the fleet's summary."""
    out = Path(out)
    check_new_folder(out, gimbal)
    episodes, row = record_fleet(cfg, team, seed)
    plans = [plan_episode(ep, cfg, settings) for ep in episodes]
    apart = fleet_separation(plans, settings)
    with staged(out) as tmp:
        uavs = []
        for u, plan in enumerate(plans):
            name = uav_folder(u)
            # A member flies alone (pirl fly uav-N): its world is the fleet's with one UAV.
            alone = cfg.replace(uavs=1)
            summary = write_files(tmp / name, plan, alone, settings, what, seed, gimbal, name)
            summary["takeoff_delay_s"] = apart.delays_s[u][: len(plan.parts)]
            summary["fleet_vcr"] = row["vcr"]  # its own "vcr" is the cells credited to it
            (tmp / name / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
            uavs.append({
                "folder": name, "home": summary["home"], "sorties": summary["sorties"],
                "flight_time_s": summary["flight_time_s"], "distance_m": summary["distance_m"],
                "photos": summary["photos"], "credited_cells": row["credit"][u],
                "takeoff_delay_s": summary["takeoff_delay_s"],
            })  # fmt: skip
        fleet = {
            "method": what,
            "seed": seed,
            "uavs": cfg.uavs,
            "site": cfg.site or None,
            "size": list(cfg.size),
            "vcr": row["vcr"],
            "makespan_95": row["makespan_95"],
            "makespan_99": row["makespan_99"],
            "grid_steps": row["steps"],
            "uav_overlap": row["uav_overlap"],
            "near_misses": row["near_misses"],
            "collisions": row["collisions"],
            "separation_m": settings.separation_m,
            "separation": apart.to_dict(),
            "flight_time_s": _fleet_seconds(plans, apart),
            "members": uavs,
            "env": cfg.to_dict(),
            "mission": settings.to_dict(),
        }
        (tmp / FLEET_FILE).write_text(json.dumps(fleet, indent=1) + "\n")
    return fleet


def _fleet_seconds(plans: list[Planned], apart: Separation) -> float:
    """The fleet's flight time: wave by wave, the latest landing (delay + sortie)."""
    waves = max(len(p.parts) for p in plans)
    return round(
        sum(
            max(
                apart.delays_s[u][n] + p.parts[n].seconds
                for u, p in enumerate(plans)
                if n < len(p.parts)
            )
            for n in range(waves)
        ),
        1,
    )


def plan_missions(
    out: Path,
    cfg: RunConfig,
    seed: int,
    policy: Path | None = None,
    method: str | None = None,
    act: str = "greedy",
    site: Path | None = None,
    size: tuple[int, int, int] | None = None,
    gimbal: str = "v2",
    uavs: int = 1,
    fly: bool = False,
) -> tuple[str, dict[str, Any]]:
    """``pirl plan``: one episode written into the new folder ``out``, as one mission or, with
    ``uavs`` K > 1, as a fleet's K missions; (the policy's label, the written summary)."""
    env, chosen, what = mission_source(cfg.env, seed, policy, method, act, site, size)
    if uavs == 1:
        return what, write_mission(out, env, cfg.mission, chosen, seed, what, gimbal)
    fleet = env.replace(uavs=uavs)
    return what, write_fleet_missions(out, fleet, cfg.mission, team_for(chosen), seed, what, gimbal)


def fly_fleet(
    folder: Path,
    physics: PhysicsConfig | None = None,
    wind: bool = True,
    log: Callable[[str], Any] | None = None,
) -> dict[str, Any]:
    """``pirl fly`` of a fleet's folder: every UAV's files read back and flown together in one
    PyFlyt ``Aviary``, one QuadX per UAV, each following its own files
    (:class:`~pirl.missions.fly.FileFollower`) from its own home, in one wind.

    Time: the drones fly at PyFlyt's pace in its scaled world (``physics.cell_size_m`` a
    cell), so each UAV's first take-off delay of ``fleet.json`` (seconds at
    ``mission.speed_m_s`` over the site's cells) is scaled to the same distance flown at
    ``physics.max_speed_m_s``; its sorties are flown back to back, as a single mission is
    flown. A UAV that has finished lands where it is. The fleet's flown coverage is what any
    of them saw. Writes each ``uav-N/flown.json`` and the fleet's ``flown.json`` (with the
    contacts between drones and their closest approach) and returns the fleet's figures."""
    from pirl.physics.pyflyt_backend import PyFlytFlight

    folder = Path(folder)
    try:
        fleet = json.loads((folder / FLEET_FILE).read_text())
        members = [folder / m["folder"] for m in fleet["members"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(
            f"{folder / FLEET_FILE}: not a fleet written by pirl plan ({exc})"
        ) from None
    physics = physics or PhysicsConfig()
    files = [read_flight(member) for member in members]
    missions = [flight_mission(f, physics, wind) for f in files]
    followers = [FileFollower(f.ops) for f in files]
    for follower, mission in zip(followers, missions, strict=True):
        follower.reset(mission.world, 0)
    take_off = []
    for f in files:
        settings = MissionSettings.from_dict(f.summary.get("mission", {}))
        cell_m = geo_for(f.env, settings, (0, 0, 0)).georef.cell_size_m
        delay = float((f.summary.get("takeoff_delay_s") or [0.0])[0])
        cells = delay * settings.speed_m_s / cell_m
        take_off.append(cells * physics.cell_size_m / physics.max_speed_m_s)
    say = None if log is None else (lambda t: log(f"fleet flown {t:,.0f} simulated s"))
    began = time.perf_counter()
    with PyFlytFlight(missions) as flight:
        together = flight.fly_fleet([f.next_action for f in followers], take_off, say)
    wall = time.perf_counter() - began
    seen = coverable = None
    flown_members = []
    for member, f, mission, follower in zip(members, files, missions, followers, strict=True):
        flown = flown_figures(f, mission, follower, wall)
        write_flown(member, flown)
        seen = flown["covered"] if seen is None else seen | flown["covered"]
        coverable = flown["coverable"]
        flown_members.append({
            "folder": member.name, "vcr_own": flown["vcr"], "vcr_grid": flown["vcr_grid"],
            "energy_used": flown["energy_used"], "energy_used_grid": flown["energy_used_grid"],
            "steps": flown["steps"], "end": flown["end"], "contacts": flown["contacts"],
            "ops_skipped": flown["ops_skipped"], "sim_seconds": flown["sim_seconds"],
        })  # fmt: skip
    assert seen is not None and coverable is not None
    figures = {
        "uavs": len(members),
        "vcr": round(float((seen & coverable).sum() / max(1, coverable.sum())), 4),
        "vcr_grid": fleet.get("vcr"),
        "energy_used": round(sum(m["energy_used"] for m in flown_members), 4),
        "contacts": sum(m["contacts"] for m in flown_members),
        "contacts_between_drones": together["contacts_between_drones"],
        "closest_approach_m": together["closest_approach_m"],
        "closest_to_waiting_m": together["closest_to_waiting_m"],
        "take_off_s": [round(t, 2) for t in take_off],
        "sim_seconds": together["sim_seconds"],
        "wall_seconds": round(wall, 1),
        "members": flown_members,
        "flown": "together, one PyFlyt Aviary (docs/fleets.md)",
    }
    write_atomic(folder / "flown.json", json.dumps(figures, indent=1) + "\n")
    return figures


__all__ = [
    "FLEET_FILE",
    "fly_fleet",
    "fleet_separation",
    "plan_missions",
    "record_fleet",
    "uav_folder",
    "write_fleet_missions",
]
