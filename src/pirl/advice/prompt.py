"""The structured zero-shot prompt: task, request template and rules first, the state last.

The builder is deterministic and rounds every number (battery and coverage to ``decimals``,
obstacle coordinates and radii to 1 decimal), so equal situations give byte-equal prompts and the
advice cache can work. Two variants exist:

- ``paper``: the paper's three parts in full sentences, the request
  before the environment summary so that the state comes last.
- ``compact``: the same items in terse form, for small local models: about 40% fewer tokens,
  and the format line shows each value's range instead of sample values (a 135M model copies
  sample values verbatim).

Both variants put what is the same for every state of a world configuration first (task,
reply format, view rule, grid) and the state last, so a local model can reuse the key/value
cache of that shared prefix (:mod:`pirl.advice.local`). :data:`PROMPT_VERSION` changes with
the text, and keys of stored answers (:func:`prompt_id`) carry it.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pirl.advice.recommendation import FORMAT_EXAMPLE
from pirl.config.choices import Footprint
from pirl.config.errors import ConfigError
from pirl.config.grid import PAN_RANGE, TILT_RANGE, ZOOM_RANGE, paper_half_width
from pirl.config.run import TEMPLATE_VARIANT

__all__ = [
    "FLEET_LINE",
    "FOOTPRINTS",
    "PROMPT_VERSION",
    "PromptState",
    "STATE_MARKER",
    "VARIANTS",
    "TEMPLATE_PREFIX",
    "build_prompt",
    "load_template",
    "prompt_context",
    "prompt_id",
    "template_hash",
]

VARIANTS: tuple[str, ...] = ("paper", "compact")
"""Prompt variants :func:`build_prompt` knows."""
FOOTPRINTS: tuple[str, ...] = tuple(Footprint)
"""Footprint models a prompt can describe."""
STATE_MARKER = "State:\n"
"""The line after which a prompt describes the state; everything before it is the same for
every state of a world configuration."""
PROMPT_VERSION = 2
"""Version of the prompts' text (2: state last). Raise it whenever the text changes, so that
answers to older prompts are never served as answers to these (:func:`prompt_id`)."""


TEMPLATE_PREFIX = TEMPLATE_VARIANT
"""A prompt variant ``file:<path>`` is a Jinja2 template of the user's (``advisor.prompt_file``)."""


def prompt_id(variant: str) -> str:
    """The variant and text version, e.g. ``"compact-v2"``: what a key of stored answers
    (the teacher dataset) records about the prompt. A template is named by the hash of its
    text (``template-<sha>-v2``), so answers to one template are never reused for another."""
    if variant.startswith(TEMPLATE_PREFIX):
        return f"template-{template_hash(variant[len(TEMPLATE_PREFIX) :])}-v{PROMPT_VERSION}"
    return f"{variant}-v{PROMPT_VERSION}"


@functools.lru_cache(maxsize=16)
def _read_template(path: str, mtime_ns: int) -> tuple[Any, str]:
    import jinja2

    text = Path(path).read_text(encoding="utf-8")
    env = jinja2.Environment(undefined=jinja2.StrictUndefined, autoescape=False)
    return env.from_string(text), hashlib.sha256(text.encode()).hexdigest()[:12]


def load_template(path: str | Path) -> tuple[Any, str]:
    """The compiled Jinja2 template at ``path`` and its text's hash; one line (ConfigError)
    for a missing file or a template that does not compile."""
    import jinja2

    path = Path(path)
    try:
        return _read_template(str(path.resolve()), path.stat().st_mtime_ns)
    except OSError as exc:
        raise ConfigError(f"advisor.prompt_file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"advisor.prompt_file {path}: not UTF-8 text") from None
    except jinja2.TemplateSyntaxError as exc:
        raise ConfigError(f"advisor.prompt_file {path}, line {exc.lineno}: {exc.message}") from None


def template_hash(path: str | Path) -> str:
    """The hash of a template's text (12 hex digits)."""
    return load_template(path)[1]


SPHERES_HEADER = "Obstacles (spheres, center [x, y, z] and radius)"
"""The obstacle line's header in the paper variant (a site's prompt says Buildings)."""

COMPACT_TEMPLATE = (
    "pan: <-90..90>, tilt: <0..90>, zoom: <0.5..2.0>, X: <-1|0|1>, Y: <-1|0|1>, Z: <-1|0|1>"
)
"""The compact variant's format line: the exact format, with each value's range as placeholder."""


@dataclass(frozen=True)
class PromptState:
    """What the prompt tells the advisor about the current step.

    Attributes:
        position: UAV cell ``(x, y, z)``.
        tilt: camera tilt in degrees (0 = forward, 90 = straight down).
        pan: camera pan in degrees (0 = +x, world frame).
        zoom: camera zoom factor.
        battery: battery left, normalized to [0, 1].
        coverage: share of coverable ground cells seen so far, in [0, 1].
        size: grid size ``(X, Y, Z)`` in cells.
        footprint: active footprint model, ``"paper"`` or ``"frustum"``.
        fov_deg: horizontal field of view at zoom 1, degrees.
        resolution: image resolution, as text (the paper lists it among the camera parameters).
        obstacles: spheres ``(cx, cy, cz, r)`` in cell units.
        max_range: frustum model only: farthest ground distance seen, in cells.
        local_map: the ground around the UAV, rows of y (top = highest) with one character
            per x: ``U`` the UAV, ``#`` blocked at its altitude, ``o`` seen, ``.`` not yet,
            blank off the grid (templates only; the built-in prompts do not show it).
        coarse_map: the grid in blocks, one digit per block: the tenths seen (9 = 90% or
            more), rows of y, top = highest (templates only).
        buildings: a site's map (no spheres): the blocked columns near the UAV as
            ``x,y:n`` (blocked from the ground up through n levels), nearest first; shown in
            place of the obstacle list. Empty in generated worlds, whose text is unchanged.
        teammates: a fleet's other UAVs still flying, ``(x, y, z, battery)`` each, in slot
            order: the fleet prompt adds a line naming them (:data:`FLEET_LINE`). Empty for
            one UAV, whose prompt is unchanged.
    """

    position: tuple[int, int, int]
    tilt: int
    pan: int
    zoom: float
    battery: float
    coverage: float
    size: tuple[int, int, int]
    footprint: str = "paper"
    fov_deg: float = 90.0
    resolution: str = "640x480"
    obstacles: tuple[tuple[float, float, float, float], ...] = ()
    max_range: float = 8.0
    local_map: str = ""
    coarse_map: str = ""
    buildings: str = ""
    teammates: tuple[tuple[int, int, int, float], ...] = ()

    def __post_init__(self) -> None:
        if self.footprint not in FOOTPRINTS:
            raise ValueError(f"footprint must be one of {FOOTPRINTS}, got {self.footprint!r}")
        if len(self.position) != 3 or len(self.size) != 3:
            raise ValueError("position and size must have three components (x, y, z)")
        if any(int(n) < 1 for n in self.size):
            raise ValueError(f"size must be positive, got {self.size!r}")
        for obstacle in self.obstacles:
            if len(obstacle) != 4:
                raise ValueError(f"an obstacle is (cx, cy, cz, r), got {obstacle!r}")
        for mate in self.teammates:
            if len(mate) != 4:
                raise ValueError(f"a teammate is (x, y, z, battery), got {mate!r}")
        numbers = (self.zoom, self.battery, self.coverage, self.fov_deg, self.max_range)
        if not all(math.isfinite(float(v)) for v in numbers):
            raise ValueError("zoom, battery, coverage, fov_deg and max_range must be finite")
        if not 0.0 < float(self.fov_deg) < 180.0:
            raise ValueError(f"fov_deg must be in (0, 180), got {self.fov_deg!r}")
        if float(self.zoom) <= 0.0:
            raise ValueError(f"zoom must be positive, got {self.zoom!r}")


def _num(value: float, decimals: int) -> str:
    """``value`` rounded to ``decimals`` places, fixed width, never ``-0``."""
    v = round(float(value), decimals) + 0.0
    return f"{v:.{decimals}f}"


def _zoom(value: float) -> str:
    """Zoom with 1 decimal, or 2 when needed (1.0, 1.25)."""
    text = _num(value, 2)
    return text[:-1] if text.endswith("0") else text


def _obstacles(state: PromptState, compact: bool) -> str:
    if state.buildings:
        what = "blocked x,y:levels" if compact else "blocked columns near the UAV as x,y:levels"
        return f"{what} {state.buildings}"
    if not state.obstacles:
        return "none"
    items = []
    for cx, cy, cz, r in state.obstacles:
        if compact:
            items.append(f"[{_num(cx, 1)},{_num(cy, 1)},{_num(cz, 1)},{_num(r, 1)}]")
        else:
            items.append(f"[{_num(cx, 1)}, {_num(cy, 1)}, {_num(cz, 1)}] radius {_num(r, 1)}")
    return " ".join(items) if compact else "; ".join(items)


FLEET_LINE = (
    "Other drones of the fleet [x, y, z] and battery (they see ground too: go where they "
    "are not going)"
)
"""The fleet prompt's header: the line a fleet's prompt adds after the state, naming the UAVs
flying beside this one (the single UAV's prompt has no such line)."""


def _teammates(state: PromptState, compact: bool, decimals: int) -> str:
    """The fleet line's items: each teammate's cell and battery."""
    items = []
    for x, y, z, battery in state.teammates:
        b = _num(min(max(float(battery), 0.0), 1.0), decimals)
        if compact:
            items.append(f"[{int(x)},{int(y)},{int(z)},{b}]")
        else:
            items.append(f"[{int(x)}, {int(y)}, {int(z)}] battery {b}")
    return " ".join(items) if compact else "; ".join(items)


def _fleet_line(state: PromptState, compact: bool, decimals: int) -> str:
    """The fleet prompt's last line (a newline first), or nothing for one UAV."""
    if not state.teammates:
        return ""
    header = "Teammates [x,y,z,battery]" if compact else FLEET_LINE
    return f"\n{header}: {_teammates(state, compact, decimals)}"


def _view_rule(state: PromptState, compact: bool) -> str:
    """The view cone's rule for the active footprint model: the same for every state of a
    world configuration, so it belongs to the shared part of the prompt."""
    if state.footprint == "paper":
        if compact:
            return (
                "ground square centered below the drone, half-width floor(m*zoom+0.5), "
                "m=2 if tilt<80 else 1"
            )
        return (
            "a square of ground cells centered below the drone, half-width floor(m*zoom+0.5) "
            "cells with m=2 if tilt < 80 else m=1; altitude and pan do not change it."
        )
    fov0 = _num(state.fov_deg, 0)
    reach = _num(state.max_range, 1)
    if compact:
        return (
            f"pinhole camera z+1 cells above ground, horizontal FOV 2*atan(tan({fov0}/2)/zoom), "
            f"aimed by tilt and pan, range {reach} cells"
        )
    return (
        f"a pinhole camera at altitude z+1 cells, horizontal field of view "
        f"2*atan(tan({fov0}/2)/zoom) degrees (zooming in narrows it), aspect 4:3, pointed by "
        "tilt (below the horizon, 90 = straight down) and pan (heading, 0 = +x); it sees the "
        f"ground cells inside its view up to {reach} cells away."
    )


def _view_now(state: PromptState, compact: bool) -> str:
    """The view cone's current value (state-dependent: it goes with the state)."""
    if state.footprint == "paper":
        # The footprint kernel's own rule, on the camera's integer steps (zoom in tenths).
        h = paper_half_width(int(round(state.tilt)), int(round(state.zoom * 10)))
        side = 2 * h + 1
        return f"{side}x{side} cells"
    altitude = int(state.position[2]) + 1
    fov = math.degrees(2.0 * math.atan(math.tan(math.radians(state.fov_deg) / 2.0) / state.zoom))
    if compact:
        return f"pinhole {altitude} cells above ground, FOV {_num(fov, 0)} deg"
    return f"a pinhole camera {altitude} cells above the ground, field of view {_num(fov, 0)} deg"


def _ranges() -> str:
    return (
        f"pan [{PAN_RANGE[0]:g}, {PAN_RANGE[1]:g}] degrees, tilt [{TILT_RANGE[0]:g}, "
        f"{TILT_RANGE[1]:g}] degrees (90 = straight down), zoom [{ZOOM_RANGE[0]:.1f}, "
        f"{ZOOM_RANGE[1]:.1f}], X, Y, Z each -1, 0 or 1"
    )


def _camera(state: PromptState, compact: bool) -> str:
    items = (_num(state.fov_deg, 0), state.resolution, int(state.tilt), int(state.pan))
    return ("[{},{},{},{},{}]" if compact else "[{}, {}, {}, {}, {}]").format(
        *items, _zoom(state.zoom)
    )


def prompt_context(state: PromptState, decimals: int = 2) -> dict[str, Any]:
    """The variables a prompt template sees (docs/advice.md lists them), each already
    formatted as the built-in prompts format it."""
    if decimals < 0:
        raise ValueError(f"decimals must be >= 0, got {decimals}")
    x, y, z = (int(v) for v in state.position)
    sx, sy, sz = (int(v) for v in state.size)
    return {
        "x": x, "y": y, "z": z, "sx": sx, "sy": sy, "sz": sz,
        "tilt": int(state.tilt), "pan": int(state.pan), "zoom": _zoom(state.zoom),
        "fov": _num(state.fov_deg, 0), "resolution": state.resolution,
        "camera": _camera(state, False), "camera_compact": _camera(state, True),
        "battery": _num(min(max(state.battery, 0.0), 1.0), decimals),
        "coverage": _num(min(max(state.coverage, 0.0), 1.0), decimals),
        "footprint": state.footprint, "max_range": _num(state.max_range, 1),
        "view_rule": _view_rule(state, compact=False),
        "view_rule_compact": _view_rule(state, compact=True),
        "view_now": _view_now(state, compact=False),
        "view_now_compact": _view_now(state, compact=True),
        "obstacles": _obstacles(state, compact=False),
        "obstacles_compact": _obstacles(state, compact=True),
        "obstacle_list": [tuple(float(v) for v in o) for o in state.obstacles],
        "ranges": _ranges(), "format_example": FORMAT_EXAMPLE,
        "format_ranges": COMPACT_TEMPLATE, "state_marker": STATE_MARKER,
        "local_map": state.local_map, "coarse_map": state.coarse_map,
        "teammates": _teammates(state, False, decimals),
        "teammates_compact": _teammates(state, True, decimals),
    }  # fmt: skip


def build_prompt(state: PromptState, variant: str = "paper", decimals: int = 2) -> str:
    """The prompt for ``state``: task, environment summary and request template.

    Args:
        state: the situation to describe.
        variant: one of :data:`VARIANTS`, or ``file:<path>`` for a Jinja2 template rendered
            with :func:`prompt_context`.
        decimals: decimals of battery and coverage (obstacles always use 1).

    Raises:
        ValueError: unknown variant, or negative ``decimals``.
    """
    if variant.startswith(TEMPLATE_PREFIX):
        import jinja2

        path = variant[len(TEMPLATE_PREFIX) :]
        template, _ = load_template(path)
        try:
            return template.render(**prompt_context(state, decimals))
        except jinja2.TemplateError as exc:  # an unknown variable, a bad filter
            raise ConfigError(f"advisor.prompt_file {path}: {exc}") from None
    if variant not in VARIANTS:
        raise ValueError(f"unknown prompt variant {variant!r}; allowed: {', '.join(VARIANTS)}")
    if decimals < 0:
        raise ValueError(f"decimals must be >= 0, got {decimals}")
    compact = variant == "compact"
    x, y, z = (int(v) for v in state.position)
    sx, sy, sz = (int(v) for v in state.size)
    camera = _camera(state, compact)
    battery = _num(min(max(state.battery, 0.0), 1.0), decimals)
    coverage = _num(min(max(state.coverage, 0.0), 1.0), decimals)
    # Everything before the state is the same for every state of a world configuration: an
    # advisor that keeps the key/value cache of that prefix only reads the state (local.py).
    if compact:
        return (
            "Drone camera task: pick the next camera setting and one-cell move to see the most "
            "unseen ground, avoid obstacles and save battery.\n"
            f"Reply in this format: {COMPACT_TEMPLATE}\n"
            f"View rule: {_view_rule(state, compact=True)}\n"
            f"Grid {sx}x{sy}x{sz} (x 0-{sx - 1}, y 0-{sy - 1}, z 0-{sz - 1})\n"
            f"{STATE_MARKER}"
            f"Position [x,y,z]: [{x},{y},{z}]\n"
            f"Camera [fov,resolution,tilt,pan,zoom]: {camera}\n"
            f"Battery {battery}, coverage {coverage}\n"
            f"View now: {_view_now(state, compact=True)}\n"
            f"{'Buildings' if state.buildings else 'Obstacles [x,y,z,radius]'}: "
            f"{_obstacles(state, compact=True)}"
            f"{_fleet_line(state, True, decimals)}"
        )
    return (
        "[Task]\n"
        "You control a drone whose gimbal camera can pan, tilt and zoom. Suggest its next move "
        "and camera setting to see as many ground cells as possible while avoiding obstacles, "
        "saving battery and not viewing cells again.\n"
        "\n[Request]\n"
        "Give a target pan, tilt and zoom, and a move of -1, 0 or 1 cell along X, Y and Z. "
        f"Ranges: {_ranges()}.\n"
        f"Reply with one line in exactly this format: {FORMAT_EXAMPLE}\n"
        "\n[Environment]\n"
        f"View cone: {_view_rule(state, compact=False)}\n"
        f"Grid: {sx} x {sy} x {sz} cells (x 0-{sx - 1}, y 0-{sy - 1}, z 0-{sz - 1}; ground z=0)\n"
        f"{STATE_MARKER}"
        f"Drone position [x, y, z]: [{x}, {y}, {z}]\n"
        f"Camera [field of view, resolution, tilt, pan, zoom]: {camera}\n"
        f"Battery: {battery} (1 full, 0 empty)\n"
        f"Coverage: {coverage} (share of ground cells seen)\n"
        f"View cone now: {_view_now(state, compact=False)}\n"
        f"{'Buildings' if state.buildings else SPHERES_HEADER}: {_obstacles(state, compact=False)}"
        f"{_fleet_line(state, False, decimals)}"
    )
