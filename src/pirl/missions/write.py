"""``pirl plan``: one episode of a policy or the planner, written as missions a drone can take.

The episode (wind off: a real flight has its own) becomes mission items: take-off, the
camera commands where the camera changes, waypoints (straight runs of moves with an unchanged
camera merged into one leg, photos triggered by distance along it), an image capture wherever
a view adds cells, return to launch; split into sorties that each fit one battery and
``mission.max_items``. Files: QGroundControl ``.plan`` (JSON), ``QGC WPL 110`` ``.waypoints``
(``mavwp``'s layout, 8 decimals of a degree), ``path.geojson``, ``path.kml`` and
``summary.json`` (with a checksum of every other file), staged beside ``--out`` and renamed
into place whole.
Every MAVLink number comes from pymavlink's dialect. Axes and angles: docs/missions.md.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.methods import PPO_ARTIFACT
from pirl.config.errors import ConfigError
from pirl.config.grid import ZOOM_MAX10, ZOOM_MIN10
from pirl.config.mission import DEFAULT_ORIGIN, MissionSettings
from pirl.config.world import VCPPConfig
from pirl.missions.staging import host_name, remove_stale_staging

NAN = float("nan")


def file_digest(path: Path) -> str:
    """``sha256:HEX`` of a file's bytes (the checksums ``summary.json`` keeps)."""
    import hashlib

    return "sha256:" + hashlib.sha256(path.read_bytes()).hexdigest()


def mav() -> Any:
    """pymavlink's MAVLink 2 common dialect: every command, frame and enum number."""
    from pymavlink.dialects.v20 import common

    return common


# -- angles -----------------------------------------------------------------------------------
def gimbal_pitch(tilt: int) -> float:
    """Gimbal pitch, degrees, of a tilt below the horizon: 90 down is pitch -90."""
    return -float(tilt)


def gimbal_yaw(pan: int) -> float:
    """Earth-frame gimbal yaw, degrees clockwise from north, of a pan (degrees counter-
    clockwise from +x = east): pan 0 looks east (90), pan 90 north (0)."""
    return float((90 - pan) % 360)


def zoom_percent(zoom10: int) -> float:
    """``SET_CAMERA_ZOOM`` with ``ZOOM_TYPE_RANGE``: zoom 0.5 is 0 % of the lens's range,
    2.0 is 100 %, linear between."""
    return 100.0 * (zoom10 - ZOOM_MIN10) / (ZOOM_MAX10 - ZOOM_MIN10)


# The inverses, for a mission read back from its file (``pirl fly``).
def tilt_from_pitch(pitch: float) -> int:
    """The tilt (degrees below the horizon) of a gimbal pitch: :func:`gimbal_pitch` undone."""
    return round(-pitch)


def pan_from_yaw(yaw: float) -> int:
    """The pan (degrees counter-clockwise from east, in [-180, 180)) of an earth-frame yaw:
    :func:`gimbal_yaw` undone."""
    return round((90.0 - yaw + 180.0) % 360.0 - 180.0)


def zoom10_from_percent(percent: float) -> int:
    """The zoom in tenths of a ``ZOOM_TYPE_RANGE`` percentage: :func:`zoom_percent` undone."""
    return round(ZOOM_MIN10 + percent / 100.0 * (ZOOM_MAX10 - ZOOM_MIN10))


# -- the episode ------------------------------------------------------------------------------
@dataclass
class Step:
    """One grid step: where the UAV ended, its camera, whether its view added cells."""

    cell: tuple[int, int, int]
    camera: tuple[int, int, int]
    captured: bool
    footprint: np.ndarray  # (k, 2) cells seen, when captured


@dataclass
class Episode:
    """The episode a mission is written from."""

    start: tuple[int, int, int]
    camera: tuple[int, int, int]
    first_view: np.ndarray
    steps: list[Step]
    metrics: dict[str, float]


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
@dataclass
class Item:
    """One mission item in grid terms; ``kind`` names it (see :func:`_command`)."""

    kind: str  # takeoff, waypoint, gimbal, zoom, capture, trigger, rtl
    cell: tuple[int, int, int] | None = None
    camera: tuple[int, int, int] | None = None
    value: float = 0.0  # trigger: its distance (m); waypoint: photos triggered on the way


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


@dataclass
class Geo:
    """Cells to the Earth: latitude, longitude and altitude above home."""

    georef: Any
    level_m: float
    real: bool
    home: tuple[float, float]

    def lonlat(self, cells: np.ndarray) -> np.ndarray:
        """(n, 2) lon, lat of grid coordinates (cell centres at +0.5)."""
        cells = np.asarray(cells, dtype=float).reshape(-1, 2)
        lon, lat = self.georef.lonlat_from_cells(cells[:, 0], cells[:, 1])
        return np.stack([lon, lat], axis=1)

    def position(self, cell: tuple[int, int, int]) -> tuple[float, float, float]:
        """(lat, lon, altitude above home in metres) of a cell's centre."""
        lon, lat = self.lonlat(np.array([[cell[0] + 0.5, cell[1] + 0.5]]))[0]
        return float(lat), float(lon), (cell[2] + 1) * self.level_m


def geo_for(cfg: VCPPConfig, settings: MissionSettings, start: tuple[int, int, int]) -> Geo:
    """A site's geo-reference, or the documented default origin (not a real place)."""
    from pirl.world.site import GeoRef, load_site, local_crs

    if cfg.site:
        site = load_site(cfg.site)
        if site.georef.real:
            geo = Geo(site.georef, site.level_height_m, True, (0.0, 0.0))
        else:
            ref = GeoRef(local_crs(DEFAULT_ORIGIN), 0.0, 0.0, site.georef.cell_size_m)
            geo = Geo(ref, site.level_height_m, False, (0.0, 0.0))
    else:
        ref = GeoRef(local_crs(DEFAULT_ORIGIN), 0.0, 0.0, settings.cell_size_m)
        geo = Geo(ref, settings.level_height_m, False, (0.0, 0.0))
    lat, lon, _ = geo.position(start)
    geo.home = (lat, lon)
    return geo


# -- sorties -----------------------------------------------------------------------------------
@dataclass
class Sortie:
    """One battery's mission: its items (take-off first, return last) and its figures."""

    items: list[Item] = field(default_factory=list)
    seconds: float = 0.0
    distance_m: float = 0.0
    photos: int = 0


def _metres(geo: Geo, a: tuple[int, int, int], b: tuple[int, int, int]) -> tuple[float, float]:
    c = geo.georef.cell_size_m
    return math.hypot(a[0] - b[0], a[1] - b[1]) * c, abs(a[2] - b[2]) * geo.level_m


def sorties(items: list[Item], ep: Episode, geo: Geo, s: MissionSettings) -> list[Sortie]:
    """Split the flight into sorties that each fit ``battery_s * (1 - reserve)`` with the way
    home, and ``max_items``; each takes off at home, flies to where the last one stopped, sets
    the camera it had, and returns to launch."""
    budget = s.battery_s * (1.0 - s.reserve)
    home = (ep.start[0], ep.start[1], -1)

    def leg_s(a: tuple[int, int, int], b: tuple[int, int, int]) -> tuple[float, float]:
        h, v = _metres(geo, a, b)
        return h / s.speed_m_s + v / s.climb_m_s, h + v

    out: list[Sortie] = []
    where, camera = ep.start, ep.camera

    def open_sortie() -> Sortie:
        sortie = Sortie()
        sortie.items.append(Item("takeoff", where))
        t, d = leg_s(home, where)
        sortie.seconds, sortie.distance_m = t, d
        if out:  # resume: back where the last sortie stopped, with its camera
            sortie.items.append(Item("waypoint", where, camera))
            sortie.items += [Item("gimbal", camera=camera), Item("zoom", camera=camera)]
            sortie.seconds += 2 * s.photo_s
        return sortie

    current = open_sortie()
    for item in items:
        t, d, to = 0.0, 0.0, where
        if item.kind == "waypoint":
            t, d = leg_s(where, item.cell)
            to = item.cell
        elif item.kind in ("gimbal", "zoom", "capture"):
            t = s.photo_s
        back, _ = leg_s(to, home)
        if current.seconds + t + back > budget or len(current.items) + 2 > s.max_items:
            if len(current.items) <= 1 + 3 * bool(out):
                raise ConfigError(
                    f"mission.battery_s={s.battery_s:g}: one battery (less the reserve "
                    f"{s.reserve:g}) cannot reach cell {to} and return; raise battery_s or "
                    "lower reserve"
                )
            current.items.append(Item("rtl"))
            current.seconds += leg_s(where, home)[0]
            current.distance_m += leg_s(where, home)[1]
            out.append(current)
            current = open_sortie()
            if item.kind == "waypoint":
                t, d = leg_s(where, item.cell)
        current.items.append(item)
        current.seconds += t
        current.distance_m += d
        if item.kind == "waypoint":
            where, camera = item.cell, item.camera or camera
            current.photos += int(item.value)
        if item.kind in ("gimbal", "zoom") and item.camera is not None:
            camera = item.camera
        if item.kind == "capture":
            current.photos += 1
    current.items.append(Item("rtl"))
    t, d = leg_s(where, home)
    current.seconds += t
    current.distance_m += d
    out.append(current)
    return out


# -- MAVLink ----------------------------------------------------------------------------------
def mavlink_items(sortie: Sortie, geo: Geo, gimbal: str) -> list[dict[str, Any]]:
    """Each item as MAVLink: command, frame and params[7] (NaN for "unused")."""
    m = mav()
    rel, none = m.MAV_FRAME_GLOBAL_RELATIVE_ALT, m.MAV_FRAME_MISSION
    out = []
    for item in sortie.items:
        if item.kind in ("takeoff", "waypoint"):
            lat, lon, alt = geo.position(item.cell)
            cmd = m.MAV_CMD_NAV_TAKEOFF if item.kind == "takeoff" else m.MAV_CMD_NAV_WAYPOINT
            params = [0.0, 0.0, 0.0, NAN, lat, lon, alt]
            out.append({"command": cmd, "frame": rel, "params": params})
        elif item.kind == "gimbal":
            tilt, pan, _ = item.camera
            if gimbal == "v2":
                flags = m.GIMBAL_MANAGER_FLAGS_YAW_LOCK  # yaw in the earth frame
                params = [gimbal_pitch(tilt), gimbal_yaw(pan), NAN, NAN, float(flags), 0.0, 0.0]
                out.append(
                    {"command": m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, "frame": none,
                     "params": params}
                )  # fmt: skip
            else:
                mode = float(m.MAV_MOUNT_MODE_MAVLINK_TARGETING)
                params = [gimbal_pitch(tilt), 0.0, gimbal_yaw(pan), 0.0, 0.0, 0.0, mode]
                out.append({"command": m.MAV_CMD_DO_MOUNT_CONTROL, "frame": none,
                            "params": params})  # fmt: skip
        elif item.kind == "zoom":
            value = zoom_percent(item.camera[2])
            params = [float(m.ZOOM_TYPE_RANGE), value, NAN, NAN, 0.0, 0.0, 0.0]
            out.append({"command": m.MAV_CMD_SET_CAMERA_ZOOM, "frame": none, "params": params})
        elif item.kind == "capture":
            params = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]  # one image now
            out.append({"command": m.MAV_CMD_IMAGE_START_CAPTURE, "frame": none, "params": params})
        elif item.kind == "trigger":
            params = [item.value, 0.0, 1.0 if item.value else 0.0, 0.0, 0.0, 0.0, 0.0]
            out.append(
                {"command": m.MAV_CMD_DO_SET_CAM_TRIGG_DIST, "frame": none, "params": params}
            )
        elif item.kind == "rtl":
            params = [0.0] * 7
            out.append({"command": m.MAV_CMD_NAV_RETURN_TO_LAUNCH, "frame": none, "params": params})
    return out


def _json_params(params: list[float]) -> list[float | None]:
    return [None if isinstance(p, float) and math.isnan(p) else p for p in params]


def plan_json(items: list[dict[str, Any]], geo: Geo, s: MissionSettings, fences: dict) -> dict:
    """A QGroundControl ``.plan``: home, items, geofence, rally points."""
    m = mav()
    firmware = m.MAV_AUTOPILOT_PX4 if s.autopilot == "px4" else m.MAV_AUTOPILOT_ARDUPILOTMEGA
    simple = [
        {
            "type": "SimpleItem", "autoContinue": True, "command": it["command"],
            "doJumpId": n + 1, "frame": it["frame"], "params": _json_params(it["params"]),
        }
        for n, it in enumerate(items)
    ]  # fmt: skip
    return {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "PIRL",
        "mission": {
            "version": 2,
            "firmwareType": int(firmware),
            "vehicleType": int(m.MAV_TYPE_QUADROTOR),
            "cruiseSpeed": s.speed_m_s,
            "hoverSpeed": s.speed_m_s,
            "plannedHomePosition": [geo.home[0], geo.home[1], 0.0],
            "items": simple,
        },
        "geoFence": {"version": 2, "circles": [], "polygons": fences["polygons"]},
        "rallyPoints": {"version": 2, "points": []},
    }


def write_waypoints(path: Path, items: list[dict[str, Any]], geo: Geo) -> None:
    """``QGC WPL 110``: home first (seq 0, above sea level), then the items, in the tab layout
    of pymavlink's ``mavwp`` with 8 decimals of a degree (1 mm; ``mavwp.save``'s 6 are 11 cm,
    and the ``.plan`` and the ``.waypoints`` of one mission agree within a centimetre)."""
    m = mav()
    rows = [(0, 1, m.MAV_FRAME_GLOBAL, m.MAV_CMD_NAV_WAYPOINT,
             [0.0, 0.0, 0.0, 0.0, geo.home[0], geo.home[1], 0.0])]  # fmt: skip
    rows += [(n, 0, it["frame"], it["command"], it["params"]) for n, it in enumerate(items, 1)]
    lines = ["QGC WPL 110"]
    for seq, current, frame, command, p in rows:
        cols = [f"{v:.6f}" for v in p[:4]] + [f"{p[4]:.8f}", f"{p[5]:.8f}", f"{p[6]:.6f}"]
        lines.append("\t".join([str(seq), str(current), str(frame), str(command), *cols, "1"]))
    path.write_text("\n".join(lines) + "\n")


# -- geodata ----------------------------------------------------------------------------------
def _cells_polygon(cells: np.ndarray, geo: Geo) -> Any:
    import shapely
    from shapely.geometry import box

    poly = shapely.union_all([box(i, j, i + 1, j + 1) for i, j in cells])
    return shapely.transform(poly, lambda xy: geo.lonlat(xy))


def fences(cfg: VCPPConfig, geo: Geo) -> dict:
    """A site's area (inclusion) and no-fly zones (exclusion) as .plan fence polygons."""
    polygons: list[dict[str, Any]] = []
    if not cfg.site:
        return {"polygons": polygons}
    from pirl.world.site import load_site

    site = load_site(cfg.site)
    for mask, inclusion in ((site.area, True), (site.no_fly, False)):
        if not mask.any() or (inclusion and mask.all()):
            continue
        shape = _cells_polygon(np.argwhere(mask), geo)
        for part in getattr(shape, "geoms", [shape]):
            ring = [[lat, lon] for lon, lat in list(part.exterior.coords)[:-1]]
            polygons.append({"inclusion": inclusion, "polygon": ring, "version": 1})
    return {"polygons": polygons}


def geojson(ep: Episode, all_items: list[Sortie], geo: Geo) -> dict:
    """The flight line, waypoints with their camera, and each captured footprint."""
    cells = [ep.start, *(s.cell for s in ep.steps)]
    flat = geo.lonlat(np.array([[c[0] + 0.5, c[1] + 0.5] for c in cells]))
    line = [
        [float(lo), float(la), (c[2] + 1) * geo.level_m]
        for (lo, la), c in zip(flat, cells, strict=True)
    ]
    feats: list[dict[str, Any]] = [
        {"type": "Feature", "properties": {"kind": "flight"},
         "geometry": {"type": "LineString", "coordinates": line}}
    ]  # fmt: skip
    for n, sortie in enumerate(all_items, start=1):
        for item in sortie.items:
            if item.kind == "waypoint" and item.camera is not None:
                lat, lon, alt = geo.position(item.cell)
                tilt, pan, zoom10 = item.camera
                feats.append({"type": "Feature", "geometry": {"type": "Point",
                              "coordinates": [lon, lat, alt]},
                              "properties": {"kind": "waypoint", "sortie": n, "tilt": tilt,
                                             "pan": pan, "zoom": zoom10 / 10}})  # fmt: skip
    from shapely.geometry import mapping

    views = [ep.first_view] + [s.footprint for s in ep.steps if s.captured]
    for k, cells in enumerate(views):
        if len(cells):
            feats.append({"type": "Feature", "properties": {"kind": "footprint", "photo": k},
                          "geometry": mapping(_cells_polygon(cells, geo))})  # fmt: skip
    return {"type": "FeatureCollection", "properties": {"real_place": geo.real},
            "features": feats}  # fmt: skip


KML = """<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2"><Document>
<name>{{ name }}</name>
<description>{{ description }}</description>
{% for f in features %}{% if f.geometry.type == "LineString" %}<Placemark><name>flight</name>
<LineString><altitudeMode>relativeToGround</altitudeMode><coordinates>{% for c in f.geometry.coordinates %}{{ c[0] }},{{ c[1] }},{{ c[2] }} {% endfor %}</coordinates></LineString></Placemark>
{% elif f.geometry.type == "Point" %}<Placemark><name>waypoint (tilt {{ f.properties.tilt }}, pan {{ f.properties.pan }}, zoom {{ f.properties.zoom }})</name>
<Point><altitudeMode>relativeToGround</altitudeMode><coordinates>{{ f.geometry.coordinates|join(",") }}</coordinates></Point></Placemark>
{% elif f.geometry.type == "Polygon" %}<Placemark><name>photo {{ f.properties.photo }}</name>
<Polygon><outerBoundaryIs><LinearRing><coordinates>{% for c in f.geometry.coordinates[0] %}{{ c[0] }},{{ c[1] }},0 {% endfor %}</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>
{% endif %}{% endfor %}</Document></kml>
"""  # noqa: E501 - KML is one tag per line


def kml(features: dict, name: str, description: str) -> str:
    """The GeoJSON's flight line, waypoints and polygon footprints as KML (Google Earth)."""
    from jinja2 import Environment

    env = Environment(autoescape=True)
    polys = [f for f in features["features"] if f["geometry"]["type"] != "MultiPolygon"]
    return env.from_string(KML).render(name=name, description=description, features=polys)


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
    if out.exists():
        raise ConfigError(f"--out {out} already exists; choose a new folder")
    if gimbal not in ("v1", "v2"):
        raise ConfigError(f"--gimbal {gimbal!r}: allowed values are v1, v2")
    ep = record_episode(cfg, policy, seed)
    geo = geo_for(cfg, settings, ep.start)
    levels = sorted({c[2] for c in [ep.start, *(s.cell for s in ep.steps)]})
    for z in (levels[0], levels[-1]):
        alt = (z + 1) * geo.level_m
        if not settings.min_alt_m <= alt <= settings.max_alt_m:
            key = "min_alt_m" if alt < settings.min_alt_m else "max_alt_m"
            raise ConfigError(
                f"mission.{key}={getattr(settings, key):g}: the plan flies at {alt:g} m above "
                f"home (level {z} of {geo.level_m:g} m levels); nothing written"
            )
    cell_m = geo.georef.cell_size_m
    items = mission_items(ep, cell_m)
    unmerged = mission_items(ep, cell_m, merge=False)
    parts = sorties(items, ep, geo, settings)
    fence = fences(cfg, geo)
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
        names = (
            ["mission"] if len(parts) == 1 else [f"sortie-{n}" for n in range(1, len(parts) + 1)]
        )
        for name, sortie in zip(names, parts, strict=True):
            mav_items = mavlink_items(sortie, geo, gimbal)
            text = json.dumps(plan_json(mav_items, geo, settings, fence), indent=1)
            (tmp / f"{name}.plan").write_text(text + "\n")
            write_waypoints(tmp / f"{name}.waypoints", mav_items, geo)
        features = geojson(ep, parts, geo)
        (tmp / "path.geojson").write_text(json.dumps(features) + "\n")
        where = "a real place" if geo.real else (
            f"NOT A REAL PLACE: a generated world placed at {DEFAULT_ORIGIN} (PX4's simulated home)"
        )  # fmt: skip
        (tmp / "path.kml").write_text(kml(features, out.name, f"{what}; {where}"))
        m = ep.metrics
        summary = {
            "method": what,
            "seed": seed,
            "site": cfg.site or None,
            "size": list(cfg.size),
            "real_place": geo.real,
            "home": list(geo.home),
            "gimbal": gimbal,
            "sorties": len(parts),
            "files": sorted(p.name for p in tmp.iterdir()),
            # pirl fly names a file edited after writing (docs/missions.md).
            "checksums": {p.name: file_digest(p) for p in sorted(tmp.iterdir())},
            "items_per_sortie": [len(p.items) for p in parts],
            "items_before_merging": len(unmerged) + 2,
            "items_after_merging": len(items) + 2,
            "distance_m": round(sum(p.distance_m for p in parts), 1),
            "flight_time_s": round(sum(p.seconds for p in parts), 1),
            "photos": sum(p.photos for p in parts),
            "climbs": sum(
                1
                for a, b in zip(
                    [ep.start, *(s.cell for s in ep.steps)],
                    [s.cell for s in ep.steps],
                    strict=False,
                )
                if b[2] > a[2]
            ),  # fmt: skip
            "vcr": m["vcr"],
            "vcr_all": m.get("vcr_all", m["vcr"]),
            "energy_used_grid": round(1.0 - m["battery_left"], 4),
            "grid_steps": m["steps"],
            # What `pirl fly` needs to fly the files back in the same world.
            "env": cfg.to_dict(),
            "mission": settings.to_dict(),
        }
        (tmp / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return summary


__all__ = [
    "Episode",
    "gimbal_pitch",
    "gimbal_yaw",
    "mission_items",
    "mission_source",
    "pan_from_yaw",
    "record_episode",
    "remove_stale_staging",
    "sorties",
    "tilt_from_pitch",
    "write_mission",
    "zoom10_from_percent",
    "zoom_percent",
]
