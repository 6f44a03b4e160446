"""``pirl plan``: one episode of a policy or the planner, written as missions a drone can take.

The episode (wind off: a real flight has its own) becomes mission items: take-off, the
camera commands where the camera changes, waypoints (straight runs of moves with an unchanged
camera merged into one leg, photos triggered by distance along it), an image capture wherever
a view adds cells, return to launch; split into sorties that each fit one battery and
``mission.max_items``. Files: QGroundControl ``.plan`` (JSON), ``QGC WPL 110`` ``.waypoints``
(``mavwp``'s layout, 8 decimals of a degree), ``path.geojson``, ``path.kml`` and
``summary.json`` (with a checksum of every other file), staged beside ``--out`` and renamed
into place whole. The files' formats: :mod:`pirl.missions.formats`; the data they are made
of: :mod:`pirl.missions.items`. Axes and angles: docs/missions.md.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.methods import PPO_ARTIFACT
from pirl.config.errors import ConfigError
from pirl.config.mission import DEFAULT_ORIGIN, MissionSettings
from pirl.config.world import VCPPConfig
from pirl.missions.formats import fences, geojson, kml, mavlink_items, plan_json, write_waypoints
from pirl.missions.items import Episode, Geo, Item, Point, Sortie, Step
from pirl.missions.staging import host_name, remove_stale_staging
from pirl.missions.terrain import check_profile, follow_ground, profile_figure


def file_digest(path: Path) -> str:
    """``sha256:HEX`` of a file's bytes (the checksums ``summary.json`` keeps)."""
    import hashlib

    return "sha256:" + hashlib.sha256(path.read_bytes()).hexdigest()


# -- the episode ------------------------------------------------------------------------------
def record_episode(cfg: VCPPConfig, policy: Any, seed: int) -> Episode:
    """Play ``policy`` on scenario ``seed`` of ``cfg`` with wind off, recording each step."""
    from pirl.env.vcpp_env import VCPPEnv

    env = VCPPEnv(cfg.replace(wind_prob=0.0))
    obs, info = env.reset(seed=seed)
    policy.reset(env.world, 0, seed=seed)
    world = env.world
    start, camera = world.position(0), world.camera_setting(0)
    first = world.footprint(0)
    steps = []
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        done = terminated or truncated
        captured = int(world.flags[0]["new_cells"]) > 0
        steps.append(
            Step(
                world.position(0), world.camera_setting(0), captured,
                world.footprint(0) if captured else np.zeros((0, 2), dtype=np.int64),
            )
        )  # fmt: skip
    return Episode(start, camera, first, steps, info["episode_metrics"])


# -- items ------------------------------------------------------------------------------------
def mission_items(ep: Episode, cell_m: float, merge: bool = True) -> list[Item]:
    """The flight as items (no take-off or return: :func:`sorties` adds them). ``merge``
    joins straight runs of moves with an unchanged camera and the same capture status into
    one leg."""
    items: list[Item] = [Item("gimbal", camera=ep.camera), Item("zoom", camera=ep.camera)]
    items.append(Item("capture", ep.start))
    prev_cell, prev_cam = ep.start, ep.camera
    k = 0
    while k < len(ep.steps):
        step = ep.steps[k]
        if step.cell != prev_cell:
            d = tuple(b - a for a, b in zip(prev_cell, step.cell, strict=True))
            end = k
            if merge:
                while end + 1 < len(ep.steps):
                    nxt = ep.steps[end + 1]
                    nd = tuple(b - a for a, b in zip(ep.steps[end].cell, nxt.cell, strict=True))
                    if nd != d or nxt.camera != step.camera or nxt.captured != step.captured:
                        break
                    end += 1
            last = ep.steps[end]
            if step.captured and end > k:
                items.append(Item("trigger", value=cell_m))
                # value: the photos the trigger takes along the leg (one per cell moved)
                items.append(Item("waypoint", last.cell, last.camera, value=end - k + 1))
                items.append(Item("trigger", value=0.0))
            else:
                items.append(Item("waypoint", last.cell, last.camera))
                if step.captured:
                    items.append(Item("capture", last.cell))
            prev_cell = last.cell
            k = end + 1
            continue
        if step.camera != prev_cam:
            if step.camera[:2] != prev_cam[:2]:
                items.append(Item("gimbal", camera=step.camera))
            if step.camera[2] != prev_cam[2]:
                items.append(Item("zoom", camera=step.camera))
            prev_cam = step.camera
        if step.captured:
            items.append(Item("capture", step.cell))
        k += 1
    return items


def geo_for(cfg: VCPPConfig, settings: MissionSettings, start: tuple[int, int, int]) -> Geo:
    """A site's geo-reference, or the documented default origin (not a real place); over a
    site's terrain model, its ground profile and the frame of the heights written."""
    from pirl.missions.terrain import altitude_frame
    from pirl.world.site import GeoRef, load_site, local_crs

    home = (start[0] + 0.5, start[1] + 0.5, start[2])
    if cfg.site:
        site = load_site(cfg.site)
        frame = altitude_frame(settings, site.has_terrain)
        if site.georef.real:
            geo = Geo(site.georef, site.level_height_m, True, (0.0, 0.0), frame, home_point=home)
        else:
            ref = GeoRef(local_crs(DEFAULT_ORIGIN), 0.0, 0.0, site.georef.cell_size_m)
            geo = Geo(ref, site.level_height_m, False, (0.0, 0.0), frame, home_point=home)
        if site.has_terrain:
            from pirl.missions.terrain import WayHome

            geo.ground = site.ground_profile()
            geo.home_ground_m = float(geo.ground.terrain([home[0]], [home[1]])[0])
            geo.way_home = WayHome(site.blocked, tuple(int(v) for v in start))
    else:
        frame = altitude_frame(settings, False)
        ref = GeoRef(local_crs(DEFAULT_ORIGIN), 0.0, 0.0, settings.cell_size_m)
        geo = Geo(ref, settings.level_height_m, False, (0.0, 0.0), frame, home_point=home)
    lat, lon, _ = geo.position(start)
    geo.home = (lat, lon)
    return geo


# -- sorties -----------------------------------------------------------------------------------
def _metres(geo: Geo, a: Point, b: Point) -> tuple[float, float]:
    c = geo.georef.cell_size_m
    return math.hypot(a[0] - b[0], a[1] - b[1]) * c, abs(a[2] - b[2]) * geo.level_m


def leg_seconds(geo: Geo, s: MissionSettings, a: Point, b: Point) -> tuple[float, float]:
    """(seconds, metres) of the leg a -> b: cruise plus level changes at ``climb_m_s``; over
    terrain a leg whose ground rises or falls faster than ``max_climb_m_s`` or
    ``max_descent_m_s`` allows at cruise speed is flown slower."""
    h, v = _metres(geo, a, b)
    t = h / s.speed_m_s + v / s.climb_m_s
    if geo.ground is None:
        return t, h + v
    rise = geo.amsl(b) - geo.amsl(a) - (b[2] - a[2]) * geo.level_m  # the ground's part
    rate = s.max_climb_m_s if rise > 0 else s.max_descent_m_s
    return max(t, abs(rise) / rate + v / s.climb_m_s), h + v + abs(rise)


def sorties(items: list[Item], ep: Episode, geo: Geo, s: MissionSettings) -> list[Sortie]:
    """Split the flight into sorties that each fit ``battery_s * (1 - reserve)`` with the way
    home, and ``max_items``; each takes off at home, flies to where the last one stopped, sets
    the camera it had, and returns to launch. Over terrain the ways out and home go through
    the grid's free cells as level legs that follow the ground (:mod:`pirl.missions.terrain`),
    ending above home before the return to launch (whose own altitude is above home, not
    above the ground, so it must not fly the way itself)."""
    from pirl.missions.terrain import via_points

    budget = s.battery_s * (1.0 - s.reserve)
    home: Point = (geo.home_point[0], geo.home_point[1], -1)
    over = geo.way_home is not None

    def leg_s(a: Point, b: Point) -> tuple[float, float]:
        return leg_seconds(geo, s, a, b)

    def route(a: Point, cells: list[tuple[int, int, int]]) -> tuple[list[Item], float, float]:
        """Waypoints from a through ``cells`` (level legs following the ground), with their
        seconds and metres."""
        out, t, d, here = [], 0.0, 0.0, a
        for c in cells:
            p = (c[0] + 0.5, c[1] + 0.5, c[2])
            inserted = via_points(geo, here, p, s.terrain_tolerance_m)
            out += [Item("waypoint", c, xy=(q[0], q[1])) for q in inserted]
            out.append(Item("waypoint", c))
            dt, dd = leg_s(here, p)
            t, d, here = t + dt, d + dd, p
        return out, t, d

    def cells_home(p: Point) -> list[tuple[int, int, int]]:
        cell = (int(p[0]), int(p[1]), p[2])
        first = [cell] if (p[0] % 1, p[1] % 1) != (0.5, 0.5) else []  # off-centre: its centre
        return first + geo.way_home.corners(cell)

    def way_home(p: Point) -> tuple[list[Item], float, float]:
        """The way from p home and down: items (the return to launch last), seconds, metres."""
        if not over:
            t, d = leg_s(p, home)
            return [Item("rtl")], t, d
        out, t, d = route(p, cells_home(p))
        dt, dd = leg_s(geo.home_point, home)
        return [*out, Item("rtl")], t + dt, d + dd

    out: list[Sortie] = []
    where, where_item, camera = ep.start_point(), Item("waypoint", ep.start), ep.camera

    def open_sortie() -> Sortie:
        sortie = Sortie()
        sortie.items.append(Item("takeoff", ep.start if over else where_item.cell))
        if over:
            t, d = leg_s(home, geo.home_point)
            if out:  # the way out: the way home from where the last sortie stopped, reversed
                back = cells_home(where)[::-1][1:] + [where_item.cell]
                way, dt, dd = route(geo.home_point, back[:-1])
                sortie.items += way
                last = way[-1].point() if way else geo.home_point
                t, d = t + dt, d + dd + leg_s(last, where)[1]
        else:
            t, d = leg_s(home, where)
        sortie.seconds, sortie.distance_m = t, d
        if out:  # resume: back where the last sortie stopped, with its camera
            sortie.items.append(Item("waypoint", where_item.cell, camera, xy=where_item.xy))
            sortie.items += [Item("gimbal", camera=camera), Item("zoom", camera=camera)]
            sortie.seconds += 2 * s.photo_s
        return sortie

    def close(sortie: Sortie) -> None:
        way, t, d = way_home(where)
        sortie.items += way
        sortie.seconds += t
        sortie.distance_m += d

    current = open_sortie()
    for item in items:
        t, d, to, to_cell = 0.0, 0.0, where, where_item.cell
        if item.kind == "waypoint":
            to, to_cell = item.point(), item.cell
            t, d = leg_s(where, to)
        elif item.kind in ("gimbal", "zoom", "capture"):
            t = s.photo_s
        back_items, back, _ = way_home(to)
        full = len(current.items) + 1 + len(back_items) > s.max_items
        if current.seconds + t + back > budget or full:
            if len(current.items) <= 1 + 3 * bool(out):
                raise ConfigError(
                    f"mission.battery_s={s.battery_s:g}: one battery (less the reserve "
                    f"{s.reserve:g}) cannot reach cell {to_cell} and return; raise battery_s or "
                    "lower reserve"
                )
            close(current)
            out.append(current)
            current = open_sortie()
            if item.kind == "waypoint":
                t, d = leg_s(where, to)
        current.items.append(item)
        current.seconds += t
        current.distance_m += d
        if item.kind == "waypoint":
            where, where_item = to, item
            camera = item.camera or camera
            current.photos += int(item.value)
        if item.kind in ("gimbal", "zoom") and item.camera is not None:
            camera = item.camera
        if item.kind == "capture":
            current.photos += 1
    close(current)
    out.append(current)
    return out


# -- the command ------------------------------------------------------------------------------
def mission_source(
    env: VCPPConfig,
    seed: int,
    policy: Path | None = None,
    method: str | None = None,
    act: str = "greedy",
    site: Path | str | None = None,
    size: tuple[int, int, int] | None = None,
) -> tuple[VCPPConfig, Any, str]:
    """What a mission is written from: (world, policy, label). ``policy`` a finished run
    (flown with its own observation and masks) or ``method`` a built-in; ``site`` or ``size``
    the world (``env`` supplies the rest for a built-in)."""
    if (site is None) == (size is None):
        raise ConfigError("give --site SITE or --size X Y Z (one of them)")
    if (policy is None) == (method is None):
        raise ConfigError("give --policy runs/NAME or --method boustrophedon (one of them)")
    from pirl.agents.loading import load_policy
    from pirl.agents.methods import PLAYED_ALONE

    if policy is not None:
        from pirl.agents.run_folder import RunFolder
        from pirl.evaluate.runner import run_label

        run = RunFolder(Path(policy))
        if not (run.path / PPO_ARTIFACT).is_file() or not run.has_config:
            raise ConfigError(
                f"--policy {policy}: not a finished run (no model.zip and config.yaml)"
            )
        if act not in ("greedy", "stochastic"):
            raise ConfigError(f"--act {act!r}: allowed values are greedy, stochastic")
        env = run.judged_config.env
        chosen = load_policy(run.path, seed=seed, act=act)
        name = run_label(run.meta) if run.meta else run.path.name
        what = f"{name} (run {run.path.name}, act {act})"
    else:
        if method not in PLAYED_ALONE:
            raise ConfigError(f"--method {method!r}: allowed values are {', '.join(PLAYED_ALONE)}")
        chosen = load_policy(str(method), seed=seed)
        what = str(getattr(chosen, "label", method))
    if site is not None:
        from pirl.world.seeable import with_site

        env = with_site(env, str(site))
    else:
        env = env.replace(size=tuple(size), site="", ground_cells=0)  # type: ignore[arg-type]
    return env, chosen, what


@dataclass
class Planned:
    """An episode made into a mission: its geo-reference, its items (merged, and unmerged
    for the summary's count) and its sorties."""

    ep: Episode
    geo: Geo
    items: list[Item]
    unmerged: list[Item]
    parts: list[Sortie]
    terrain: dict[str, Any] | None = None
    """Over terrain: the frame, the worst height error and clearance sampled along every leg
    (:func:`~pirl.missions.terrain.check_profile`)."""


def plan_episode(ep: Episode, cfg: VCPPConfig, settings: MissionSettings) -> Planned:
    """The mission of ``ep``: items and sorties; refused (one line) when it flies outside
    ``mission.min_alt_m`` and ``max_alt_m``."""
    geo = geo_for(cfg, settings, ep.start)
    levels = sorted({c[2] for c in [ep.start, *(s.cell for s in ep.steps)]})
    above = "the ground" if geo.ground is not None else "home"
    for z in (levels[0], levels[-1]):
        alt = (z + 1) * geo.level_m
        if not settings.min_alt_m <= alt <= settings.max_alt_m:
            key = "min_alt_m" if alt < settings.min_alt_m else "max_alt_m"
            raise ConfigError(
                f"mission.{key}={getattr(settings, key):g}: the plan flies at {alt:g} m above "
                f"{above} (level {z} of {geo.level_m:g} m levels); nothing written"
            )
    cell_m = geo.georef.cell_size_m
    items = follow_ground(mission_items(ep, cell_m), ep.start_point(), geo, settings)
    parts = sorties(items, ep, geo, settings)
    profile = check_profile(parts, geo, settings) if geo.ground is not None else None
    return Planned(ep, geo, items, mission_items(ep, cell_m, merge=False), parts, profile)


def check_new_folder(out: Path, gimbal: str) -> None:
    """Refuse (one line) an ``--out`` that exists or an unknown ``--gimbal``."""
    if out.exists():
        raise ConfigError(f"--out {out} already exists; choose a new folder")
    if gimbal not in ("v1", "v2"):
        raise ConfigError(f"--gimbal {gimbal!r}: allowed values are v1, v2")


@contextmanager
def staged(out: Path) -> Iterator[Path]:
    """A staging folder beside ``out``, renamed into ``out`` whole when the block ends (and
    removed if it fails): a kill at any moment leaves ``out`` absent or complete."""
    out.parent.mkdir(parents=True, exist_ok=True)
    # A run killed mid-write leaves its staging folder: the next run into this parent clears it.
    remove_stale_staging(out.parent)
    tmp = Path(
        tempfile.mkdtemp(prefix=f".{out.name}.staging-{host_name()}-{os.getpid()}-", dir=out.parent)
    )
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o777 & ~umask)  # a folder like any other, not mkdtemp's owner-only one
    try:
        yield tmp
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def write_files(
    folder: Path,
    plan: Planned,
    cfg: VCPPConfig,
    settings: MissionSettings,
    what: str,
    seed: int,
    gimbal: str,
    name: str,
) -> dict[str, Any]:
    """Write one UAV's mission files and its ``summary.json`` into ``folder`` (made here);
    ``name`` is what the KML calls it. Returns the summary."""
    folder.mkdir(exist_ok=True)
    ep, geo, parts = plan.ep, plan.geo, plan.parts
    fence = fences(cfg, geo)
    names = ["mission"] if len(parts) == 1 else [f"sortie-{n}" for n in range(1, len(parts) + 1)]
    for file, sortie in zip(names, parts, strict=True):
        mav_items = mavlink_items(sortie, geo, gimbal)
        text = json.dumps(plan_json(mav_items, geo, settings, fence), indent=1)
        (folder / f"{file}.plan").write_text(text + "\n")
        write_waypoints(folder / f"{file}.waypoints", mav_items, geo)
    features = geojson(ep, parts, geo)
    (folder / "path.geojson").write_text(json.dumps(features) + "\n")
    where = "a real place" if geo.real else (
        f"NOT A REAL PLACE: a generated world placed at {DEFAULT_ORIGIN} (PX4's simulated home)"
    )  # fmt: skip
    (folder / "path.kml").write_text(kml(features, name, f"{what}; {where}"))
    if geo.ground is not None:
        profile_figure(parts, geo, folder / "profile.png")
    m = ep.metrics
    cells = [ep.start, *(s.cell for s in ep.steps)]
    summary = {
        "method": what,
        "seed": seed,
        "site": cfg.site or None,
        "size": list(cfg.size),
        "real_place": geo.real,
        "home": list(geo.home),
        "gimbal": gimbal,
        "sorties": len(parts),
        "files": sorted(p.name for p in folder.iterdir()),
        # pirl fly names a file edited after writing (docs/missions.md).
        "checksums": {p.name: file_digest(p) for p in sorted(folder.iterdir())},
        "items_per_sortie": [len(p.items) for p in parts],
        "items_before_merging": len(plan.unmerged) + 2,
        "items_after_merging": len(plan.items) + 2,
        "distance_m": round(sum(p.distance_m for p in parts), 1),
        "flight_time_s": round(sum(p.seconds for p in parts), 1),
        "photos": sum(p.photos for p in parts),
        "climbs": sum(1 for a, b in zip(cells, cells[1:], strict=False) if b[2] > a[2]),
        "altitude_frame": geo.frame,
        "terrain": plan.terrain,
        "vcr": m["vcr"],
        "vcr_all": m.get("vcr_all", m["vcr"]),
        "energy_used_grid": round(1.0 - m["battery_left"], 4),
        "grid_steps": m["steps"],
        # What `pirl fly` needs to fly the files back in the same world.
        "env": cfg.to_dict(),
        "mission": settings.to_dict(),
    }
    (folder / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary


def write_mission(
    out: Path,
    cfg: VCPPConfig,
    settings: MissionSettings,
    policy: Any,
    seed: int,
    what: str,
    gimbal: str = "v2",
) -> dict[str, Any]:
    """Record the episode, write every file into the new folder ``out`` (atomically; refused
    if it exists) and return the summary."""
    out = Path(out)
    check_new_folder(out, gimbal)
    plan = plan_episode(record_episode(cfg, policy, seed), cfg, settings)
    with staged(out) as tmp:
        return write_files(tmp, plan, cfg, settings, what, seed, gimbal, out.name)


__all__ = [
    "Planned",
    "check_new_folder",
    "file_digest",
    "plan_episode",
    "staged",
    "write_files",
    "geo_for",
    "mission_items",
    "mission_source",
    "record_episode",
    "remove_stale_staging",
    "sorties",
    "write_mission",
]
