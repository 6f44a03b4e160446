"""The file formats of a mission: QGroundControl ``.plan`` (JSON), ``QGC WPL 110``
``.waypoints`` (``mavwp``'s layout, 8 decimals of a degree), GeoJSON and KML, and the camera
angles as MAVLink takes them, with their inverses (what ``pirl fly`` reads back).

Every MAVLink number comes from pymavlink's dialect. Axes and angles: docs/missions.md.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pirl.config.grid import ZOOM_MAX10, ZOOM_MIN10
from pirl.config.mission import MissionSettings
from pirl.config.world import VCPPConfig
from pirl.missions.items import Episode, Geo, Sortie

NAN = float("nan")


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


# -- MAVLink ----------------------------------------------------------------------------------
def altitude_frame_number(frame: str) -> int:
    """The MAVLink frame of ``mission.altitude_frame``'s heights: above home, above sea level
    (``MAV_FRAME_GLOBAL``) or above the terrain."""
    m = mav()
    return {
        "relative": m.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        "amsl": m.MAV_FRAME_GLOBAL,
        "terrain": m.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    }[frame]


def mavlink_items(sortie: Sortie, geo: Geo, gimbal: str) -> list[dict[str, Any]]:
    """Each item as MAVLink: command, frame and params[7] (NaN for "unused")."""
    m = mav()
    rel, none = altitude_frame_number(geo.frame), m.MAV_FRAME_MISSION
    out = []
    for item in sortie.items:
        if item.kind in ("takeoff", "waypoint"):
            lat, lon, alt = geo.position(item.cell, item.xy)
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
            "plannedHomePosition": [geo.home[0], geo.home[1], geo.home_ground_m],
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
             [0.0, 0.0, 0.0, 0.0, geo.home[0], geo.home[1], geo.home_ground_m])]  # fmt: skip
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
                # Heights above the ground, as the KML's relativeToGround reads them.
                lat, lon, _ = geo.position(item.cell, item.xy)
                alt = geo.agl(item.cell[2])
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


__all__ = [
    "altitude_frame_number",
    "fences",
    "geojson",
    "gimbal_pitch",
    "gimbal_yaw",
    "kml",
    "mavlink_items",
    "pan_from_yaw",
    "plan_json",
    "tilt_from_pitch",
    "write_waypoints",
    "zoom10_from_percent",
    "zoom_percent",
]
