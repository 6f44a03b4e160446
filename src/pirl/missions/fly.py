"""``pirl fly``: a mission folder written by ``pirl plan`` read back from its files and flown
in the PyFlyt backend, with wind.

Nothing of the episode the mission was written from is used: the ``.plan`` files (one per
sortie, in order) are read from disk, every waypoint's latitude, longitude and altitude is
turned back into a grid cell through the same geo-reference the writer used, every gimbal and
zoom command into a camera setting (the inverse functions of :mod:`pirl.missions.write`),
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
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.mission import MissionSettings
from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.missions.write import (
    Geo,
    geo_for,
    mav,
    pan_from_yaw,
    tilt_from_pitch,
    zoom10_from_percent,
)
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
    """A mission folder read back: its summary, world, the ops of its sorties in order."""

    folder: Path
    summary: dict[str, Any]
    env: VCPPConfig
    start: Cell
    ops: list[Op]
    plans: list[str]
    items: int


def _plan_files(folder: Path) -> list[Path]:
    one = folder / "mission.plan"
    if one.is_file():
        return [one]
    parts = sorted(folder.glob("sortie-*.plan"), key=lambda p: int(p.stem.split("-")[1]))
    if not parts:
        raise ConfigError(f"{folder}: no mission.plan or sortie-N.plan (not a pirl plan folder)")
    return parts


def _cell(geo: Geo, lat: float, lon: float, alt: float, size: tuple[int, ...]) -> Cell:
    x, y = geo.georef.cells_from_lonlat(np.array([lon]), np.array([lat]))
    cell = (int(math.floor(x[0])), int(math.floor(y[0])), round(alt / geo.level_m) - 1)
    if not all(0 <= c < s for c, s in zip(cell, size, strict=True)):
        raise ConfigError(
            f"waypoint at lat {lat:.7f}, lon {lon:.7f}, {alt:g} m lies outside the "
            f"{'x'.join(map(str, size))} world the mission was written for"
        )
    return cell


def read_flight(folder: str | os.PathLike[str]) -> FlightFiles:
    """Read a ``pirl plan`` folder: ``summary.json`` for the world, the ``.plan`` files for
    what to fly. Bad or foreign files are refused in one line."""
    folder = Path(folder)
    summary_file = folder / "summary.json"
    if not summary_file.is_file():
        raise ConfigError(f"{folder}: no summary.json (not a folder written by pirl plan)")
    try:
        summary = json.loads(summary_file.read_text())
        if "env" not in summary:
            raise ConfigError(
                f"{summary_file}: no grid settings (written by an older pirl plan); write the "
                "mission again to fly it"
            )
        env = VCPPConfig.from_dict(summary["env"])
        settings = MissionSettings.from_dict(summary.get("mission", {}))
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ConfigError(
            f"{summary_file}: unreadable ({exc}); write the mission again with pirl plan"
        ) from None
    if env.site and not Path(env.site).exists():
        raise ConfigError(f"{summary_file}: its site {env.site} is not there (run from where "
                          "pirl plan ran, or copy the site back)")  # fmt: skip
    m = mav()
    size = env.size
    geo: Geo | None = None
    ops: list[Op] = []
    start: Cell | None = None
    camera = [0, 0, 10]
    items = 0
    plans = _plan_files(folder)
    for path in plans:
        try:
            plan = json.loads(path.read_text())
            simple = plan["mission"]["items"]
            home = plan["mission"]["plannedHomePosition"]
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            raise ConfigError(f"{path}: not a QGroundControl plan ({exc})") from None
        if geo is None:
            # The writer's geo-reference; its home is only a label here.
            geo = geo_for(env, settings, (0, 0, 0))
            geo.home = (float(home[0]), float(home[1]))
        for item in simple:
            items += 1
            cmd = item.get("command")
            p = [float("nan") if v is None else float(v) for v in item.get("params", [])]
            if len(p) != 7:
                raise ConfigError(f"{path}: item {item.get('doJumpId')} has no 7 params")
            if cmd in (m.MAV_CMD_NAV_TAKEOFF, m.MAV_CMD_NAV_WAYPOINT):
                cell = _cell(geo, p[4], p[5], p[6], size)
                if start is None:
                    start = cell
                ops.append(Op("goto", cell=cell))
            elif cmd == m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW:
                camera[:2] = [tilt_from_pitch(p[0]), pan_from_yaw(p[1])]
                ops.append(Op("camera", camera=(camera[0], camera[1], camera[2])))
            elif cmd == m.MAV_CMD_DO_MOUNT_CONTROL:
                camera[:2] = [tilt_from_pitch(p[0]), pan_from_yaw(p[2])]
                ops.append(Op("camera", camera=(camera[0], camera[1], camera[2])))
            elif cmd == m.MAV_CMD_SET_CAMERA_ZOOM:
                camera[2] = zoom10_from_percent(p[1])
                ops.append(Op("camera", camera=(camera[0], camera[1], camera[2])))
            # IMAGE_START_CAPTURE, DO_SET_CAM_TRIGG_DIST: photos; the camera's view is booked
            # at every cell anyway. RETURN_TO_LAUNCH: the way home covers nothing new.
    if start is None:
        raise ConfigError(f"{folder}: its plan has no take-off or waypoint")
    return FlightFiles(folder, summary, env, start, ops, [p.name for p in plans], items)


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
    from pirl.physics.flight import Mission, scenario_for_seed
    from pirl.physics.pyflyt_backend import PyFlytFlight

    physics = physics or PhysicsConfig()
    if not wind:
        physics = physics.replace(wind_mean=(0.0, 0.0, 0.0), wind_gust=0.0)
    # The file is flown as written: it already holds the stall guard's moves, and a guard
    # counting stalls on the flown coverage would steer the drone off the written route.
    env = files.env.replace(wind_prob=0.0, stall_guard=0)
    seed = int(files.summary.get("seed", 0))
    scenario = dataclasses.replace(scenario_for_seed(env, seed), start=files.start)
    mission = Mission(env, physics)
    mission.reset(scenario=scenario)
    follower = FileFollower(files.ops)
    follower.reset(mission.world, 0, seed)
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
    wall = time.perf_counter() - began
    m = mission.metrics()
    s = files.summary
    return {
        "method": s.get("method"),
        "site": s.get("site"),
        "size": list(env.size),
        "seed": seed,
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
        "sim_seconds": round(float(m["sim_seconds"]), 1),
        "wall_seconds": round(wall, 1),
        "timeouts": int(m["timeouts"]),
        "contacts": int(m["contacts"]),
        "recoveries": int(m["recoveries"]),
        "wind": {"mean_m_s": list(physics.wind_mean), "gust_m_s": physics.wind_gust},
        "physics": "PyFlyt QuadX (cf2x) at physics.cell_size_m per cell (docs/physics.md)",
        "covered": mission.world.covered(0).copy(),
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
    figures = {k: v for k, v in flown.items() if k != "covered"}
    _write(files.folder / "flown.json", json.dumps(figures, indent=1) + "\n")
    return flown


def _write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically, with the permissions of any new file (a temporary
    file of mkstemp's would keep its owner-only mode)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


__all__ = ["FileFollower", "FlightFiles", "Op", "fly_files", "fly_mission", "read_flight"]
