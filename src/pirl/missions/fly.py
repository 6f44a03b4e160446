"""``pirl fly``: a mission folder written by ``pirl plan`` read back from its files and flown
in the PyFlyt backend, with wind.

Nothing of the episode the mission was written from is used: the ``.plan`` files (one per
sortie, in order, as ``summary.json`` lists them) are read from disk and checked by
:mod:`pirl.missions.read`, every waypoint's latitude, longitude and altitude (in its frame) is
turned back into a grid cell through the same geo-reference the writer used, every gimbal and
zoom command into a camera setting (the inverse functions of :mod:`pirl.missions.formats`),
and a :class:`FileFollower` flies them as the grid's own actions: one-cell moves towards the
next waypoint from wherever the wind left the drone, camera steps towards the next setting.
The :class:`~pirl.physics.flight.Mission` books coverage and energy with the same rules as
every physics episode. What is flown and what is not: docs/missions.md.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pirl._atomic import write_atomic
from pirl.config.errors import ConfigError, UserError
from pirl.config.mission import MissionSettings
from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.missions.formats import pan_from_yaw, tilt_from_pitch, zoom10_from_percent
from pirl.missions.items import Geo
from pirl.missions.read import (
    GOTO,
    MissionFile,
    MissionItem,
    dialect,
    disagreement,
    read_plan,
    read_waypoints,
    role,
)
from pirl.missions.staging import pid_alive
from pirl.missions.write import file_digest, geo_for
from pirl.world import dynamics as D

Cell = tuple[int, int, int]

_MOVE_ACTION = {delta: action for action, delta in enumerate(D.MOVE_DELTAS)}
"""The move action of each unit step (x, y, z), from the grid's one move table."""


def _unit(axis: int, diff: int) -> tuple[int, ...]:
    """The unit step along ``axis`` towards a difference ``diff``."""
    return tuple((1 if diff > 0 else -1) if k == axis else 0 for k in range(3))


@dataclass(frozen=True)
class Op:
    """One thing the follower does: fly to ``cell`` or set the camera to ``camera``."""

    kind: str  # "goto" or "camera"
    cell: Cell | None = None
    camera: tuple[int, int, int] | None = None


@dataclass
class FlightFiles:
    """A mission folder read back: its summary, world, the ops of its sorties in order, the
    items not flown (MAVLink name: count) and one line per warning (an edited file, a
    ``.waypoints`` that disagrees with its ``.plan``)."""

    folder: Path
    summary: dict[str, Any]
    env: VCPPConfig
    start: Cell
    ops: list[Op]
    plans: list[str]
    items: int
    skipped: dict[str, int] = dataclasses.field(default_factory=dict)
    warnings: list[str] = dataclasses.field(default_factory=list)
    edited: list[str] = dataclasses.field(default_factory=list)


def sortie_names(count: int) -> list[str]:
    """The file stems of a mission of ``count`` sorties, in flying order."""
    return ["mission"] if count == 1 else [f"sortie-{n}" for n in range(1, count + 1)]


def _plan_files(folder: Path, summary: dict[str, Any], summary_file: Path) -> list[Path]:
    """The sorties ``summary.json`` lists, all present, in order; a stray plan is refused."""
    count = summary.get("sorties")
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise UserError(f"{summary_file}, sorties: {count!r} is not a count of sorties")
    names = sortie_names(count)
    missing = [f"{n}.plan" for n in names if not (folder / f"{n}.plan").is_file()]
    if missing:
        raise UserError(
            f"{folder}: summary.json lists {count} sortie(s) but {', '.join(missing)} "
            f"{'is' if len(missing) == 1 else 'are'} missing; nothing flown (restore the "
            "file or write the mission again)"
        )
    stray = sorted(
        p.name for p in [*folder.glob("sortie-*.plan"), *folder.glob("mission.plan")]
        if p.stem not in names
    )  # fmt: skip
    if stray:
        raise UserError(
            f"{folder}: {', '.join(stray)} is not among the {count} sortie(s) summary.json "
            "lists; nothing flown"
        )
    return [folder / f"{n}.plan" for n in names]


def _edited(folder: Path, summary: dict[str, Any]) -> tuple[list[str], list[str]]:
    """(files changed or gone since ``pirl plan`` wrote them, the warning lines)."""
    sums = summary.get("checksums")
    if not isinstance(sums, dict):
        return [], ["summary.json holds no checksums (an older pirl plan): an edited file "
                    "cannot be told from a written one"]  # fmt: skip
    changed, gone = [], []
    for name, digest in sorted(sums.items()):
        path = folder / str(name)
        if "/" in str(name) or not path.is_file():
            gone.append(str(name))
        elif file_digest(path) != digest:
            changed.append(str(name))
    lines = []
    if changed:
        them = "it" if len(changed) == 1 else "them"
        lines.append(
            f"{', '.join(changed)} changed since pirl plan wrote {them} (checksum in "
            "summary.json): this check is of the edited mission"
        )
    if gone:
        lines.append(f"{', '.join(gone)} missing (summary.json lists it)")
    return changed + gone, lines


def _cell(
    geo: Geo, item: MissionItem, home: tuple[float, float, float], size: tuple[int, ...],
    where: str,
) -> Cell:  # fmt: skip
    """The grid cell of a flown position: its map cell, and the level its height above the
    ground (:func:`above_ground`) is nearest."""
    lat, lon = item.params[4], item.params[5]
    x, y = geo.georef.cells_from_lonlat(np.array([lon]), np.array([lat]))
    if not (math.isfinite(x[0]) and math.isfinite(y[0])):
        raise UserError(f"{where}, position: lat {lat:.7f}, lon {lon:.7f} is off the grid's map")
    agl = above_ground(item, home, geo, float(x[0]), float(y[0]), where)
    cell = (int(math.floor(x[0])), int(math.floor(y[0])), round(agl / geo.level_m) - 1)
    if not all(0 <= c < s for c, s in zip(cell, size, strict=True)):
        raise UserError(
            f"{where}, position: lat {lat:.7f}, lon {lon:.7f}, {agl:g} m above "
            f"{'home' if geo.ground is None else 'the ground'} lies outside the "
            f"{'x'.join(map(str, size))} world the mission was written for"
        )
    return cell


def above_ground(
    item: MissionItem, home: tuple[float, float, float], geo: Geo, x: float, y: float, where: str
) -> float:
    """A flown position's height above the ground under it, metres, from its frame. On flat
    ground: relative (3) as it is, above sea level (0) less home's altitude
    (``plannedHomePosition``). Over a site's terrain model (at grid point x, y): above sea
    level less the terrain there, relative plus home's altitude less it, above terrain (10)
    as it is. Above terrain on flat ground is refused: there is no ground model to read."""
    m = dialect()
    alt = item.params[6]
    ground = None if geo.ground is None else float(geo.ground.terrain([x], [y])[0])
    if item.frame == m.MAV_FRAME_GLOBAL_RELATIVE_ALT:
        return alt if ground is None else alt + home[2] - ground
    if item.frame == m.MAV_FRAME_GLOBAL:
        return alt - (home[2] if ground is None else ground)
    if ground is not None:
        return alt
    raise UserError(
        f"{where}, frame: {item.frame} (above terrain) needs a site with a terrain model; this "
        "one is flat ground: write it relative to home (3) or above sea level (0)"
    )


def mission_ops(
    mission: MissionFile, geo: Geo, size: tuple[int, ...], camera: list[int]
) -> tuple[list[Op], dict[str, int]]:
    """A checked mission file as ops (``camera`` is the setting so far, updated), and the
    items not flown (MAVLink name: count). A position outside the world is refused."""
    m = dialect()
    ops: list[Op] = []
    skipped: dict[str, int] = {}
    for item in mission.items:
        p, cmd = item.params, item.command
        where = f"{mission.path}: item {item.index} ({item.name})"
        kind = role(cmd)
        if kind != "flown":
            if kind == "skipped":
                skipped[item.name] = skipped.get(item.name, 0) + 1
            continue
        if cmd in GOTO:
            ops.append(Op("goto", cell=_cell(geo, item, mission.home, size, where)))
            continue
        if cmd == m.MAV_CMD_SET_CAMERA_ZOOM:
            camera[2] = zoom10_from_percent(p[1])
        else:
            # NaN (null): the angle stays as it is.
            yaw = p[1] if cmd == m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW else p[2]
            if not math.isnan(p[0]):
                camera[0] = tilt_from_pitch(p[0])
            if not math.isnan(yaw):
                camera[1] = pan_from_yaw(yaw)
        ops.append(Op("camera", camera=(camera[0], camera[1], camera[2])))
    return ops, skipped


def read_flight(folder: str | os.PathLike[str]) -> FlightFiles:
    """Read a ``pirl plan`` folder: ``summary.json`` for the world and the sorties, every
    ``.plan`` for what to fly, each ``.waypoints`` checked against its ``.plan``. Bad, foreign
    or missing files are refused in one line; edits and disagreements are warnings."""
    folder = Path(folder)
    summary_file = folder / "summary.json"
    if not summary_file.is_file():
        raise ConfigError(f"{folder}: no summary.json (not a folder written by pirl plan)")
    try:
        summary = json.loads(summary_file.read_text())
        if not isinstance(summary, dict):
            raise TypeError("not an object")
        if "env" not in summary:
            raise ConfigError(
                f"{summary_file}: no grid settings (written by an older pirl plan); write the "
                "mission again to fly it"
            )
        env = VCPPConfig.from_dict(summary["env"])
        settings = MissionSettings.from_dict(summary.get("mission", {}))
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(
            f"{summary_file}: unreadable ({exc}); write the mission again with pirl plan"
        ) from None
    if env.site and not Path(env.site).exists():
        raise ConfigError(f"{summary_file}: its site {env.site} is not there (run from where "
                          "pirl plan ran, or copy the site back)")  # fmt: skip
    plans = _plan_files(folder, summary, summary_file)
    edited, warnings = _edited(folder, summary)
    # The writer's geo-reference places the world's cells on the Earth; each file's home gives
    # only the height that positions above sea level are measured from.
    geo = geo_for(env, settings, (0, 0, 0))
    ops: list[Op] = []
    skipped: dict[str, int] = {}
    camera = [0, 0, 10]
    items = 0
    for path in plans:
        mission = read_plan(path)
        other = path.with_suffix(".waypoints")
        if other.is_file():
            differ = disagreement(mission, read_waypoints(other))
            if differ:
                warnings.append(
                    f"{other.name} disagrees with {path.name} ({differ}); the flight is of "
                    f"{path.name}"
                )
        items += len(mission.items)
        part, left = mission_ops(mission, geo, env.size, camera)
        ops += part
        for name, count in left.items():
            skipped[name] = skipped.get(name, 0) + count
    start = next((op.cell for op in ops if op.kind == "goto"), None)
    if start is None:
        raise ConfigError(f"{folder}: its plan has no take-off or waypoint")
    return FlightFiles(
        folder, summary, env, start, ops, [p.name for p in plans], items, skipped, warnings,
        edited,
    )  # fmt: skip


class FileFollower:
    """Flies :class:`Op` s as grid actions: towards the next waypoint one cell at a time from
    the cell the drone is in (so wind drift is corrected), the camera one step at a time.

    An op that takes more than ``4 * distance + 10`` steps (a waypoint the drone keeps being
    blown or bounced away from) is given up and counted in ``skipped``.
    """

    def __init__(self, ops: list[Op]) -> None:
        self.ops = list(ops)
        self.skipped = 0
        self._budget_left = -1

    def reset(self, world: Any, index: int = 0, seed: int | None = None) -> None:
        self.world, self.index = world, index

    def _budget(self, op: Op, here: Cell) -> int:
        if op.kind == "goto" and op.cell is not None:
            return 4 * sum(abs(a - b) for a, b in zip(op.cell, here, strict=True)) + 10
        return 40

    def next_action(self) -> int | None:
        """The next grid action, or None when every op is done."""
        w, e = self.world, self.index
        while self.ops:
            op = self.ops[0]
            here = w.position(e)
            action = self._towards(op, here, w.camera_setting(e))
            if action is None:
                self.ops.pop(0)
                self._budget_left = -1
                continue
            if self._budget_left < 0:
                self._budget_left = self._budget(op, here)
            if self._budget_left == 0:
                self.ops.pop(0)
                self.skipped += 1
                self._budget_left = -1
                continue
            self._budget_left -= 1
            return action
        return None

    def _towards(self, op: Op, here: Cell, camera: tuple[int, int, int]) -> int | None:
        if op.kind == "goto":
            assert op.cell is not None
            diffs = [b - a for a, b in zip(here, op.cell, strict=True)]
            if not any(diffs):
                return None
            # The axis furthest from the waypoint first; a blocked neighbour tries the next.
            order = sorted((a for a in range(3) if diffs[a]), key=lambda a: -abs(diffs[a]))
            moves = [_MOVE_ACTION[_unit(a, diffs[a])] for a in order]
            for action in moves:
                d = D.MOVE_DELTAS[action]
                nxt = (here[0] + d[0], here[1] + d[1], here[2] + d[2])
                if not self.world.blocked[self.index][nxt]:
                    return action
            return moves[0]
        assert op.camera is not None
        for k, (plus, minus) in enumerate(
            ((D.TILT_PLUS, D.TILT_MINUS), (D.PAN_PLUS, D.PAN_MINUS), (D.ZOOM_PLUS, D.ZOOM_MINUS))
        ):
            if op.camera[k] != camera[k]:
                return plus if op.camera[k] > camera[k] else minus
        return None


def flight_mission(files: FlightFiles, physics: PhysicsConfig, wind: bool = True) -> Any:
    """The :class:`~pirl.physics.flight.Mission` that flies ``files`` (reset on its scenario,
    from the file's start) and the physics settings it flies under (no wind unless ``wind``)."""
    from pirl.physics.flight import Mission, scenario_for_seed

    if not wind:
        physics = physics.replace(wind_mean=(0.0, 0.0, 0.0), wind_gust=0.0)
    # The file is flown as written: it already holds the stall guard's moves, and a guard
    # counting stalls on the flown coverage would steer the drone off the written route.
    env = files.env.replace(wind_prob=0.0, stall_guard=0)
    seed = int(files.summary.get("seed", 0))
    scenario = dataclasses.replace(scenario_for_seed(env, seed), start=files.start)
    mission = Mission(env, physics)
    mission.reset(scenario=scenario)
    return mission


def fly_files(
    files: FlightFiles,
    physics: PhysicsConfig | None = None,
    wind: bool = True,
    log: Callable[[str], Any] | None = None,
    every_s: float = 30.0,
) -> dict[str, Any]:
    """Fly a mission read back by :func:`read_flight` in PyFlyt; the flown figures beside the
    grid episode's, and under ``"covered"`` the (X, Y) map of ground cells the flight saw.
    ``log`` gets one line per ``every_s`` wall seconds (a site's flight takes minutes)."""
    from pirl.physics.pyflyt_backend import PyFlytFlight

    mission = flight_mission(files, physics or PhysicsConfig(), wind)
    follower = FileFollower(files.ops)
    follower.reset(mission.world, 0)
    began = last = time.perf_counter()
    with PyFlytFlight(mission) as flight:
        while not mission.done:
            action = follower.next_action()
            if action is None:
                break
            mission.begin_step(action)
            pose = flight.fly(mission)
            mission.end_step(pose)
            if log is not None and time.perf_counter() - last >= every_s:
                last = time.perf_counter()
                log(f"flown {mission.world.status[0]['steps']:,} steps of about "
                    f"{files.summary.get('grid_steps', '?'):,}, {mission.sim_seconds:,.0f} "
                    f"simulated s")  # fmt: skip
    return flown_figures(files, mission, follower, time.perf_counter() - began)


def flown_figures(
    files: FlightFiles, mission: Any, follower: FileFollower, wall: float
) -> dict[str, Any]:
    """What a flight of ``files`` did (``mission`` flown, ``follower`` its ops), beside the
    grid episode's figures; under ``"covered"`` the (X, Y) map of ground cells it saw."""
    m = mission.metrics()
    s = files.summary
    physics = mission.physics
    return {
        "method": s.get("method"),
        "site": s.get("site"),
        "size": list(files.env.size),
        "seed": int(s.get("seed", 0)),
        "plans": files.plans,
        "items": files.items,
        "vcr": round(float(m["vcr"]), 4),
        "vcr_grid": s.get("vcr"),
        "vcr_all": round(float(m.get("vcr_all", m["vcr"])), 4),
        "energy_used": round(1.0 - float(m["battery_left"]), 4),
        "energy_used_grid": s.get("energy_used_grid"),
        # The flight ends with the file's last item unless the battery or step limit came first.
        "end": m["end"] or "mission_complete",
        "steps": int(m["steps"]),
        "grid_steps": s.get("grid_steps"),
        "ops_skipped": follower.skipped,
        # Items read and not flown (DO_JUMP, LOITER, ...): MAVLink name and count.
        "items_skipped": dict(files.skipped),
        "edited": list(files.edited),
        "warnings": list(files.warnings),
        "sim_seconds": round(float(m["sim_seconds"]), 1),
        "wall_seconds": round(wall, 1),
        "timeouts": int(m["timeouts"]),
        "contacts": int(m["contacts"]),
        "recoveries": int(m["recoveries"]),
        "wind": {"mean_m_s": list(physics.wind_mean), "gust_m_s": physics.wind_gust},
        "physics": "PyFlyt QuadX (cf2x) at physics.cell_size_m per cell (docs/physics.md)",
        "covered": mission.world.covered(0).copy(),
        "coverable": mission.world.coverable[0].copy(),
    }


def fly_mission(
    folder: str | os.PathLike[str] | FlightFiles,
    physics: PhysicsConfig | None = None,
    wind: bool = True,
    log: Callable[[str], Any] | None = None,
) -> dict[str, Any]:
    """Read a mission folder's files (or take them read), fly them and write ``flown.json``
    beside them (atomically)."""
    files = folder if isinstance(folder, FlightFiles) else read_flight(folder)
    flown = fly_files(files, physics, wind, log)
    write_flown(files.folder, flown)
    return flown


def write_flown(folder: Path, flown: dict[str, Any]) -> None:
    """Write a flight's figures (its maps left out) to ``folder/flown.json``, atomically."""
    figures = {k: v for k, v in flown.items() if k not in ("covered", "coverable")}
    _write(folder / "flown.json", json.dumps(figures, indent=1) + "\n")


def _write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically, with the permissions of any new file (a temporary
    file of mkstemp's would keep its owner-only mode). A temporary left by a killed writer
    (its process gone) is removed first."""
    stale = re.compile(rf"^\.{re.escape(path.name)}\.(\d+)\.tmp$")
    for old in path.parent.glob(f".{path.name}.*.tmp"):
        found = stale.match(old.name)
        if found and not pid_alive(int(found.group(1))):
            old.unlink(missing_ok=True)
    write_atomic(path, text, path.with_name(f".{path.name}.{os.getpid()}.tmp"))


__all__ = [
    "FileFollower",
    "FlightFiles",
    "Op",
    "flight_mission",
    "flown_figures",
    "fly_files",
    "fly_mission",
    "read_flight",
    "write_flown",
]
