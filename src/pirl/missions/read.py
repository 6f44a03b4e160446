"""Mission files read as a ground station reads them: QGroundControl ``.plan`` (JSON) and
``QGC WPL 110`` text, every field checked before anything flies.

A reader returns a :class:`MissionFile` (its home and items, every number finite, every flown
position on the Earth) or raises one :class:`~pirl.config.errors.UserError` line naming the
file, the item (1-based, as QGroundControl numbers them) and the field. Which commands are
flown, which are reported and skipped, and which refuse the mission: :func:`role` and
docs/missions.md. Command and frame numbers and names are pymavlink's (its ``ardupilotmega``
dialect, which holds the common one).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pirl.config.errors import UserError

MAX_BYTES = 16 * 2**20
"""The largest mission file read: a full 500-item sortie is about 120 KB, and a bound here
bounds the memory any file can make the reader take."""

NAN = float("nan")


def dialect() -> Any:
    """pymavlink's ardupilotmega dialect (common plus ArduPilot's own commands)."""
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega


def command_name(command: int) -> str:
    """MAVLink's name of a command number, or ``command N`` for a number MAVLink lacks."""
    entry = dialect().enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else f"command {command}"


def frame_name(frame: int) -> str:
    """MAVLink's name of a frame number, or ``frame N``."""
    entry = dialect().enums["MAV_FRAME"].get(frame)
    return entry.name if entry is not None else f"frame {frame}"


def _sets() -> tuple[frozenset[int], frozenset[int], frozenset[int], frozenset[int]]:
    m = dialect()
    goto = frozenset({m.MAV_CMD_NAV_TAKEOFF, m.MAV_CMD_NAV_WAYPOINT})
    camera = frozenset(
        {m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, m.MAV_CMD_DO_MOUNT_CONTROL,
         m.MAV_CMD_SET_CAMERA_ZOOM}
    )  # fmt: skip
    # Understood, nothing to fly: the camera's view is booked at every cell anyway, and the way
    # home covers nothing new.
    booked = frozenset(
        {m.MAV_CMD_IMAGE_START_CAPTURE, m.MAV_CMD_DO_SET_CAM_TRIGG_DIST,
         m.MAV_CMD_NAV_RETURN_TO_LAUNCH}
    )  # fmt: skip
    frames = frozenset(
        {m.MAV_FRAME_GLOBAL_RELATIVE_ALT, m.MAV_FRAME_GLOBAL, m.MAV_FRAME_GLOBAL_TERRAIN_ALT}
    )
    return goto, camera, booked, frames


GOTO, CAMERA, BOOKED, FRAMES = _sets()
"""Commands flown as a position, as a camera setting; understood with nothing to fly; the
frames a flown position may be given in."""


def role(command: int) -> str:
    """``flown``, ``booked`` (understood, nothing to fly), ``skipped`` (a MAVLink command
    ``pirl fly`` does not fly: reported with its count) or ``unknown`` (not MAVLink: refused)."""
    if command in GOTO or command in CAMERA:
        return "flown"
    if command in BOOKED:
        return "booked"
    return "skipped" if command in dialect().enums["MAV_CMD"] else "unknown"


@dataclass(frozen=True)
class MissionItem:
    """One item: its 1-based index, command, frame and params[7] (NaN: unused)."""

    index: int
    command: int
    frame: int
    params: tuple[float, ...]

    @property
    def name(self) -> str:
        """MAVLink's name of the command."""
        return command_name(self.command)


@dataclass(frozen=True)
class MissionFile:
    """A mission file read and checked: home (lat, lon, metres above sea level), items."""

    path: Path
    home: tuple[float, float, float]
    items: list[MissionItem]


def _show(value: Any) -> str:
    """A bad value for a one-line message: repr, shortened."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _read_text(path: Path) -> str:
    """The file's text (UTF-8, a byte-order mark allowed), refused above :data:`MAX_BYTES`."""
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise UserError(
                f"{path}: {size / 2**20:.0f} MB; a mission file is at most "
                f"{MAX_BYTES // 2**20} MB (a full 500-item sortie is about 0.1 MB)"
            )
        data = path.read_bytes()[: MAX_BYTES + 1]  # the file may grow between stat and read
    except OSError as exc:
        raise UserError(f"{path}: cannot be read ({exc.strerror or type(exc).__name__})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise UserError(
            f"{path}: not UTF-8 text (byte {exc.start}); ground stations write mission files "
            "in UTF-8"
        ) from None


# -- the numbers ------------------------------------------------------------------------------
def _number(value: Any, where: str, unused: bool = False) -> float:
    """A finite float from a JSON value; ``None`` is NaN (unused) where ``unused``."""
    if value is None and unused:
        return NAN
    if isinstance(value, bool) or not isinstance(value, int | float):
        kind = "null" if value is None else type(value).__name__
        raise UserError(f"{where}: {_show(value)} is {kind}, not a number")
    try:
        out = float(value)
    except OverflowError:
        raise UserError(f"{where}: {_show(value)} is too large") from None
    if not math.isfinite(out):
        hint = " (QGroundControl writes an unused param as null)" if unused else ""
        raise UserError(f"{where}: {out} is not a finite number{hint}")
    return out


def _integer(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise UserError(f"{where}: {_show(value)} is not a whole number")
    if not 0 <= value < 2**32:
        raise UserError(f"{where}: {value} is out of range")
    return value


_FLOAT = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]{1,4})?", re.ASCII)
_INT = re.compile(r"[-+]?[0-9]{1,12}", re.ASCII)


def _text_number(token: str, where: str, unused: bool = False) -> float:
    """A finite float from a ``.waypoints`` column; ``nan`` is unused where ``unused``."""
    if unused and token.lower() in ("nan", "+nan", "-nan"):
        return NAN
    if token.lower().lstrip("+-") in ("inf", "infinity", "nan"):
        raise UserError(f"{where}: {_show(token)} is not a finite number")
    if not _FLOAT.fullmatch(token):
        raise UserError(f"{where}: {_show(token)} is not a number")
    out = float(token)
    if not math.isfinite(out):
        raise UserError(f"{where}: {_show(token)} is not a finite number")
    return out


def _text_integer(token: str, where: str) -> int:
    if not _INT.fullmatch(token):
        raise UserError(f"{where}: {_show(token)} is not a whole number")
    value = int(token)
    if not 0 <= value < 2**32:
        raise UserError(f"{where}: {value} is out of range")
    return value


def _home(lat: float, lon: float, where: str) -> None:
    if not -90.0 <= lat <= 90.0:
        raise UserError(f"{where} (latitude): {lat:g} is outside [-90, 90]")
    if not -180.0 <= lon <= 180.0:
        raise UserError(f"{where} (longitude): {lon:g} is outside [-180, 180]")


# -- what each item means ---------------------------------------------------------------------
def param_label(command: int, k: int) -> str:
    """What params[k] (0-based) of a flown command holds, as `` (latitude)``; "" otherwise."""
    m = dialect()
    labels: dict[int, dict[int, str]] = {
        m.MAV_CMD_NAV_TAKEOFF: {4: "latitude", 5: "longitude", 6: "altitude"},
        m.MAV_CMD_NAV_WAYPOINT: {4: "latitude", 5: "longitude", 6: "altitude"},
        m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW: {0: "pitch", 1: "yaw"},
        m.MAV_CMD_DO_MOUNT_CONTROL: {0: "pitch", 2: "yaw"},
        m.MAV_CMD_SET_CAMERA_ZOOM: {0: "zoom type", 1: "zoom"},
    }
    label = labels.get(command, {}).get(k)
    return f" ({label})" if label else ""


def check_item(item: MissionItem, where: str, field: Any) -> None:
    """Refuse an item ``pirl fly`` would misread: a command MAVLink lacks, a flown position
    in another frame, off the Earth or without coordinates, a camera value out of range.
    ``field(k)`` names params[k] as the file spells it, with what it holds."""
    m = dialect()
    p, c = item.params, item.command
    kind = role(c)
    if kind == "unknown":
        raise UserError(f"{where}, command: {c} is no MAVLink command (pymavlink's dialect)")
    if c in GOTO:
        if item.frame not in FRAMES:
            raise UserError(
                f"{where}, frame: {item.frame} ({frame_name(item.frame)}); pirl fly reads a "
                "position relative to home (3), above sea level (0) or above terrain (10)"
            )
        for k in (4, 5, 6):
            if math.isnan(p[k]):
                raise UserError(f"{where}, {field(k)}: missing (a position needs it)")
        if not -90.0 <= p[4] <= 90.0:
            raise UserError(f"{where}, {field(4)}: {p[4]:g} is outside [-90, 90]")
        if not -180.0 <= p[5] <= 180.0:
            raise UserError(f"{where}, {field(5)}: {p[5]:g} is outside [-180, 180]")
    elif c in (m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, m.MAV_CMD_DO_MOUNT_CONTROL):
        yaw = 1 if c == m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW else 2
        # NaN (null) leaves the angle as it is, as MAVLink defines for the gimbal manager.
        if not math.isnan(p[0]) and not -180.0 <= p[0] <= 180.0:
            raise UserError(f"{where}, {field(0)}: {p[0]:g} is outside [-180, 180]")
        if not math.isnan(p[yaw]) and not -360.0 <= p[yaw] <= 360.0:
            raise UserError(f"{where}, {field(yaw)}: {p[yaw]:g} is outside [-360, 360]")
    elif c == m.MAV_CMD_SET_CAMERA_ZOOM:
        if p[0] != m.ZOOM_TYPE_RANGE:
            raise UserError(
                f"{where}, {field(0)}: {p[0]:g}; pirl fly reads ZOOM_TYPE_RANGE "
                f"({m.ZOOM_TYPE_RANGE}), a share of the lens's range"
            )
        if math.isnan(p[1]) or not 0.0 <= p[1] <= 100.0:
            raise UserError(f"{where}, {field(1)}: {p[1]:g} is outside [0, 100] %")


# -- .plan ------------------------------------------------------------------------------------
def read_plan(path: str | Path) -> MissionFile:
    """A QGroundControl ``.plan`` (``fileType`` Plan, version 1, mission version 2, simple
    items), checked; one :class:`UserError` line otherwise."""
    path = Path(path)
    text = _read_text(path)
    try:
        doc = json.loads(text)
    except RecursionError:
        raise UserError(f"{path}: not a QGroundControl plan (nested too deep)") from None
    except ValueError as exc:  # JSONDecodeError, and an integer of too many digits
        raise UserError(f"{path}: not a QGroundControl plan (not JSON: {exc})") from None
    if not isinstance(doc, dict):
        raise UserError(f"{path}: not a QGroundControl plan (a JSON {type(doc).__name__})")
    if doc.get("fileType") != "Plan":
        raise UserError(
            f"{path}, fileType: {_show(doc.get('fileType'))}, not 'Plan' (not a mission plan)"
        )
    if doc.get("version") != 1 or isinstance(doc.get("version"), bool):
        raise UserError(f"{path}, version: {_show(doc.get('version'))}; pirl reads version 1")
    mission = doc.get("mission")
    if not isinstance(mission, dict):
        raise UserError(f"{path}, mission: {_show(mission)} is not an object")
    if mission.get("version") != 2 or isinstance(mission.get("version"), bool):
        raise UserError(
            f"{path}, mission.version: {_show(mission.get('version'))}; pirl reads version 2"
        )
    home = mission.get("plannedHomePosition")
    if not isinstance(home, list) or len(home) != 3:
        raise UserError(
            f"{path}, mission.plannedHomePosition: {_show(home)} is not [lat, lon, alt]"
        )
    where = f"{path}, mission.plannedHomePosition"
    lat, lon, alt = (_number(v, f"{where}[{k}]") for k, v in enumerate(home))
    _home(lat, lon, where)
    raw = mission.get("items")
    if not isinstance(raw, list):
        raise UserError(f"{path}, mission.items: {_show(raw)} is not a list")
    items = [_plan_item(path, n, it) for n, it in enumerate(raw, start=1)]
    return MissionFile(path, (lat, lon, alt), items)


def _plan_item(path: Path, n: int, raw: Any) -> MissionItem:
    where = f"{path}: item {n}"
    if not isinstance(raw, dict):
        raise UserError(f"{where}: {_show(raw)} is not an object")
    kind = raw.get("type")
    if kind == "ComplexItem":
        raise UserError(
            f"{where}, type: a ComplexItem ({_show(raw.get('complexItemType'))}); pirl fly "
            "reads simple items only (QGroundControl turns a survey into them on upload)"
        )
    if kind != "SimpleItem":
        raise UserError(f"{where}, type: {_show(kind)}, not SimpleItem")
    command = _integer(raw.get("command"), f"{where}, command")
    frame = _integer(raw.get("frame"), f"{where}, frame")
    where = f"{where} ({command_name(command)})"
    params = raw.get("params")
    if not isinstance(params, list) or len(params) != 7:
        raise UserError(f"{where}, params: {_show(params)} is not a list of 7")

    def field(k: int) -> str:
        return f"params[{k}]{param_label(command, k)}"

    values = tuple(_number(v, f"{where}, {field(k)}", unused=True) for k, v in enumerate(params))
    item = MissionItem(n, command, frame, values)
    check_item(item, where, field)
    return item


# -- QGC WPL 110 ------------------------------------------------------------------------------
WPL_HEADER = "QGC WPL 110"


def read_waypoints(path: str | Path) -> MissionFile:
    """A ``QGC WPL 110`` file (home as item 0, then the items; 12 columns a line, ``#``
    comments), checked; one :class:`UserError` line otherwise."""
    path = Path(path)
    lines = _read_text(path).splitlines()
    if not lines or lines[0].strip() != WPL_HEADER:
        first = lines[0] if lines else ""
        raise UserError(f"{path}, line 1: {_show(first)}, not {WPL_HEADER!r}")
    home: tuple[float, float, float] | None = None
    items: list[MissionItem] = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cols = line.split()
        at = f"{path}, line {number}"
        if len(cols) != 12:
            raise UserError(f"{at}: {len(cols)} columns; a {WPL_HEADER} line has 12")
        seq = _text_integer(cols[0], f"{at}, column 1 (seq)")
        expected = 0 if home is None else len(items) + 1
        if seq != expected:
            raise UserError(f"{at}, column 1 (seq): {seq} where {expected} comes next")
        where = f"{path}: item {seq} (line {number})"
        for k, label in ((1, "current"), (11, "autocontinue")):
            if _text_integer(cols[k], f"{where}, column {k + 1} ({label})") > 1:
                raise UserError(f"{where}, column {k + 1} ({label}): {cols[k]} is not 0 or 1")
        frame = _text_integer(cols[2], f"{where}, column 3 (frame)")
        command = _text_integer(cols[3], f"{where}, column 4 (command)")
        if seq == 0:
            where = f"{path}: home (line {number})"
            lat, lon, alt = (
                _text_number(cols[k], f"{where}, column {k + 1}") for k in (8, 9, 10)
            )  # fmt: skip
            _home(lat, lon, f"{where}, columns 9-10")
            home = (lat, lon, alt)
            continue
        where = f"{where} ({command_name(command)})"

        def field(k: int, command: int = command) -> str:
            return f"column {k + 5}{param_label(command, k)}"

        values = tuple(
            _text_number(cols[k + 4], f"{where}, {field(k)}", unused=True) for k in range(7)
        )
        item = MissionItem(seq, command, frame, values)
        check_item(item, where, field)
        items.append(item)
    if home is None:
        raise UserError(f"{path}: no items (not even home, item 0)")
    return MissionFile(path, home, items)


def read_mission(path: str | Path) -> MissionFile:
    """A ``.plan`` or a ``.waypoints`` file, by its name, read and checked."""
    path = Path(path)
    if path.suffix == ".waypoints":
        return read_waypoints(path)
    return read_plan(path)


# -- two files of one mission -----------------------------------------------------------------
def _metres_apart(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Distance of two (lat, lon, alt) points, metres (local flat Earth: they are close)."""
    north = (a[0] - b[0]) * 111_320.0
    east = (a[1] - b[1]) * 111_320.0 * math.cos(math.radians(a[0]))
    return math.sqrt(north * north + east * east + (a[2] - b[2]) ** 2)


def _same(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return abs(a - b) <= 1e-6 * max(1.0, abs(a))


def disagreement(plan: MissionFile, other: MissionFile, tolerance_m: float = 0.01) -> str | None:
    """Where two files of one mission differ (home, item count, each item's command and
    frame, positions beyond ``tolerance_m``, other params), or None when they agree."""
    if _metres_apart(plan.home, other.home) > tolerance_m:
        return f"home {_metres_apart(plan.home, other.home):.3f} m apart"
    if len(plan.items) != len(other.items):
        return f"{len(plan.items)} items against {len(other.items)}"
    for a, b in zip(plan.items, other.items, strict=True):
        if (a.command, a.frame) != (b.command, b.frame):
            return (
                f"item {a.index}: {a.name} in frame {a.frame} against {b.name} in frame {b.frame}"
            )
        if a.command in GOTO:
            apart = _metres_apart(a.params[4:7], b.params[4:7])
            if apart > tolerance_m:
                return f"item {a.index} ({a.name}): positions {apart:.3f} m apart"
            rest = range(4)
        else:
            rest = range(7)
        for k in rest:
            if not _same(a.params[k], b.params[k]):
                return f"item {a.index} ({a.name}): param{k + 1} {a.params[k]:g} against " + (
                    f"{b.params[k]:g}"
                )
    return None


__all__ = [
    "BOOKED",
    "CAMERA",
    "FRAMES",
    "GOTO",
    "MAX_BYTES",
    "MissionFile",
    "MissionItem",
    "check_item",
    "command_name",
    "disagreement",
    "frame_name",
    "param_label",
    "read_mission",
    "read_plan",
    "read_waypoints",
    "role",
]
