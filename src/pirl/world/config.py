"""Configuration of the grid world and the environment, with strict validation.

One flat dataclass, :class:`VCPPConfig`, holds every value a user may change. It loads from
YAML or a dict; an unknown key, a wrong type or an impossible value raises
:class:`ConfigError` naming the key and what is allowed.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from pirl.config.grid import (
    PAN_MAX,
    PAN_MIN,
    PAN_STEP,
    TILT_MAX,
    TILT_MIN,
    TILT_STEP,
    ZOOM_MAX10,
    ZOOM_MIN10,
)

# The training world the paper scales from.
BASE_SIZE = (15, 15, 3)

REWARD_TERMS = (
    "coverage",
    "redundant",
    "battery",
    "cam_usage",
    "curiosity",
    "collision",
    "idle",
    "llm",
)
STATIC_WEIGHTS = (1.0, -0.6, -0.3, 0.4, 0.35, -1.15, -0.55, 0.4)
EWRI_RANGES = (
    (0.5, 1.5),
    (-1.0, -0.2),
    (-0.5, -0.1),
    (0.2, 0.6),
    (0.2, 0.5),
    (-1.5, -0.8),
    (-0.8, -0.3),
    (0.2, 0.6),
)


class ConfigError(ValueError):
    """A configuration value is unknown, of the wrong type, or impossible."""


class UserError(ConfigError):
    """A mistake the user can fix that is not a config value: a missing API key, a damaged or
    missing run file, an expert run that cannot serve. The command line prints it as one line
    (like every ConfigError) and exits with code 2."""


def zoom_to_tenths(zoom: float, key: str = "zoom") -> int:
    """Convert a zoom factor to integer tenths, refusing values off the 0.1 grid."""
    tenths = round(zoom * 10)
    if abs(zoom * 10 - tenths) > 1e-6 or not ZOOM_MIN10 <= tenths <= ZOOM_MAX10:
        raise ConfigError(
            f"{key}={zoom!r} is off the zoom grid: allowed values are 0.5, 0.6, ..., 2.0"
        )
    return tenths


@dataclass(frozen=True)
class VCPPConfig:
    """Every setting of the VCPP world and environment (DESIGN.md sections 3, 4 and 8)."""

    size: tuple[int, int, int] = BASE_SIZE
    """Grid size (X, Y, Z) in cells; each at least 3."""
    footprint: str = "paper"
    """Camera footprint model: 'paper' (square, the paper's simulator) or 'frustum' (pinhole)."""
    occlusion: bool = False
    """Frustum only: hide ground cells whose line of sight crosses an obstacle sphere."""
    fov_deg: float = 90.0
    """Frustum only: horizontal field of view at zoom 1.0, degrees."""
    max_range: float = 8.0
    """Frustum only: ground points farther than this (cells) are cut at this range."""
    obstacles_min: int = 2
    """Fewest obstacle spheres per episode."""
    obstacles_max: int = 5
    """Most obstacle spheres per episode."""
    radius_min: float = 1.0
    """Smallest sphere radius, cells."""
    radius_max: float = 2.0
    """Largest sphere radius, cells."""
    obstacles_scale_with_area: bool = False
    """Multiply the obstacle count by the ground area relative to 15x15 (off in the paper)."""
    wind_prob: float = 0.1
    """Probability per step that a gust pushes the UAV one cell along +-x or +-y."""
    battery_capacity: float = 100.0
    """Energy units at the training size; multiplied by alpha when scale_by_alpha."""
    max_steps: int = 200
    """Step limit at the training size; multiplied by alpha when scale_by_alpha."""
    scale_by_alpha: bool = True
    """Scale battery and step limit by alpha = (X*Y*Z) / (15*15*3), as the paper does."""
    energy_move: float = 1.0
    """Energy of an x/y move."""
    energy_climb: float = 1.5
    """Energy of a z+ move."""
    energy_descend: float = 0.7
    """Energy of a z- move."""
    energy_camera: float = 0.2
    """Energy of a camera action."""
    energy_hover: float = 0.1
    """Energy spent every step, whatever the action."""
    start_tilt: int = 90
    """Camera tilt at reset, degrees (0 forward, 90 straight down), multiple of 5."""
    start_pan: int = 0
    """Camera pan at reset, degrees (0 = +x), multiple of 15 in [-90, 90]."""
    start_zoom: float = 1.0
    """Camera zoom at reset, on the grid 0.5, 0.6, ..., 2.0."""
    start_camera: str = "fixed"
    """'fixed': every episode starts with the camera at start_tilt/pan/zoom (the paper). 'random':
    each scenario also draws its starting camera pose uniformly on the grid (exploring starts;
    training only: ``train.camera_start``)."""
    reward: str = "static"
    """Reward weights: 'static' (PPO-SR) or 'ewri' (re-drawn at every reset)."""
    static_weights: tuple[float, ...] = STATIC_WEIGHTS
    """Static weights in the order of REWARD_TERMS."""
    ewri_ranges: tuple[tuple[float, float], ...] = EWRI_RANGES
    """EWRI (low, high) uniform ranges in the order of REWARD_TERMS."""
    llm_weight: bool = False
    """Keep the LLM weight (set by PARE); False leaves it 0, as for PPO-SR and PPO-EWRI."""
    obs_window: int = 11
    """Side of the egocentric local window in the observation (odd)."""
    obs_global: int = 8
    """Side of the coarse global coverage summary in the observation."""
    obs_visits: bool = False
    """Add a local window of this episode's visit counts at the UAV's altitude (min(v, 3)/3):
    the curiosity term rewards unvisited cells, and without it a policy cannot see which ones
    it has visited, so a greedy policy can loop (uavSim keeps a position history for this).
    False is the paper's observation."""
    obs_target: bool = False
    """Add the direction to the nearest coverable cell not yet covered and its distance in
    cells (saturating at 16), so a policy trained on a small world can find the work left on a
    large one where its local window shows none. False is the paper's observation."""
    render_cell_px: int = 0
    """Pixels per cell in rgb_array renders; 0 picks a size near 480 pixels."""

    def __post_init__(self) -> None:
        _validate(self)

    # -- derived values -------------------------------------------------------------------
    @property
    def alpha(self) -> float:
        """Size scale factor relative to the 15x15x3 training world."""
        x, y, z = self.size
        return (x * y * z) / (BASE_SIZE[0] * BASE_SIZE[1] * BASE_SIZE[2])

    @property
    def capacity(self) -> float:
        """Battery capacity (energy units) of this world."""
        return self.battery_capacity * (self.alpha if self.scale_by_alpha else 1.0)

    @property
    def step_limit(self) -> int:
        """Step limit of this world."""
        return int(round(self.max_steps * (self.alpha if self.scale_by_alpha else 1.0)))

    @property
    def start_zoom10(self) -> int:
        return zoom_to_tenths(self.start_zoom, "start_zoom")

    @property
    def obstacle_count_range(self) -> tuple[int, int]:
        """Inclusive (min, max) obstacle count, scaled with area when asked."""
        if not self.obstacles_scale_with_area:
            return self.obstacles_min, self.obstacles_max
        area = self.size[0] * self.size[1] / (BASE_SIZE[0] * BASE_SIZE[1])
        return max(0, round(self.obstacles_min * area)), max(0, round(self.obstacles_max * area))

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> VCPPConfig:
        """Build from a mapping, refusing unknown keys and coercing lists to tuples."""
        if not isinstance(values, Mapping):
            raise ConfigError(f"expected a mapping of settings, got {type(values).__name__}")
        check_keys(values, [f.name for f in fields(cls)])
        return cls(**{key: _coerce(key, value) for key, value in values.items()})

    @classmethod
    def from_yaml(cls, path: str | Path) -> VCPPConfig:
        """Load from a YAML file whose top level is a mapping of settings."""
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"config file not found: {path}")
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
        if data is None:
            # An empty file would silently train on built-in defaults that match no preset.
            raise ConfigError(
                f"{path} is empty; give settings (or {{}} for the built-in defaults), or a "
                "preset such as quick or test"
            )
        return cls.from_dict(data)

    def replace(self, **changes: Any) -> VCPPConfig:
        """A copy with some settings changed (validated like from_dict)."""
        merged = {f.name: getattr(self, f.name) for f in fields(self)}
        merged.update(changes)
        return VCPPConfig.from_dict(merged)

    def to_dict(self) -> dict[str, Any]:
        """Plain, YAML-safe dict of every setting."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, tuple):
                value = [list(v) if isinstance(v, tuple) else v for v in value]
            out[f.name] = value
        return out


def check_keys(values: Mapping[str, Any], known: list[str], section: str = "") -> None:
    """Refuse keys not in ``known``, naming the key, a close match and the allowed keys."""
    for key in values:
        if key not in known:
            close = difflib.get_close_matches(str(key), known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            where = f" in section {section!r}" if section else ""
            raise ConfigError(
                f"unknown setting {key!r}{where}{hint}; allowed keys: {', '.join(sorted(known))}"
            )


def _coerce(key: str, value: Any) -> Any:
    if isinstance(value, list):
        return tuple(tuple(v) if isinstance(v, list) else v for v in value)
    return value


def _check_type(cfg: VCPPConfig, name: str, expected: type | tuple[type, ...]) -> None:
    value = getattr(cfg, name)
    names = (
        expected.__name__ if isinstance(expected, type) else "/".join(t.__name__ for t in expected)
    )
    ok = isinstance(value, expected) and not (
        isinstance(value, bool)
        and bool not in (expected if isinstance(expected, tuple) else (expected,))
    )
    if not ok:
        raise ConfigError(f"{name}={value!r} has type {type(value).__name__}; expected {names}")


def _validate(cfg: VCPPConfig) -> None:
    num = (int, float)
    for f in fields(cfg):
        if f.name in ("size", "static_weights", "ewri_ranges"):
            continue
        default = f.default
        if isinstance(default, bool):
            _check_type(cfg, f.name, bool)
        elif isinstance(default, int):
            _check_type(cfg, f.name, int)
        elif isinstance(default, float):
            _check_type(cfg, f.name, num)
        elif isinstance(default, str):
            _check_type(cfg, f.name, str)

    size = cfg.size
    if (
        not isinstance(size, tuple | list)
        or len(size) != 3
        or not all(isinstance(s, int) and not isinstance(s, bool) for s in size)
    ):
        raise ConfigError(f"size={size!r}: expected three integers (X, Y, Z), each >= 3")
    if min(size) < 3:
        raise ConfigError(f"size={tuple(size)!r} is impossible: every side must be >= 3 cells")
    if max(size) > 2048:
        raise ConfigError(f"size={tuple(size)!r}: sides above 2048 cells are not supported")
    object.__setattr__(cfg, "size", tuple(int(s) for s in size))

    _choice(cfg, "footprint", ("paper", "frustum"))
    _choice(cfg, "reward", ("static", "ewri"))
    if not 0.0 <= cfg.wind_prob <= 1.0:
        raise ConfigError(f"wind_prob={cfg.wind_prob!r}: allowed range is [0, 1]")
    if not 0.0 < cfg.fov_deg < 180.0:
        raise ConfigError(f"fov_deg={cfg.fov_deg!r}: allowed range is (0, 180)")
    if not cfg.max_range > 0:
        raise ConfigError(f"max_range={cfg.max_range!r}: must be > 0")
    if not 0 <= cfg.obstacles_min <= cfg.obstacles_max:
        raise ConfigError(
            f"obstacles_min={cfg.obstacles_min}, obstacles_max={cfg.obstacles_max}: "
            "need 0 <= obstacles_min <= obstacles_max"
        )
    if not 0 < cfg.radius_min <= cfg.radius_max:
        raise ConfigError(
            f"radius_min={cfg.radius_min}, radius_max={cfg.radius_max}: "
            "need 0 < radius_min <= radius_max"
        )
    if not (math.isfinite(cfg.battery_capacity) and cfg.battery_capacity > 0):
        raise ConfigError(f"battery_capacity={cfg.battery_capacity!r}: must be a positive number")
    if cfg.max_steps < 1:
        raise ConfigError(f"max_steps={cfg.max_steps!r}: must be >= 1")
    for name in ("energy_move", "energy_climb", "energy_descend", "energy_camera", "energy_hover"):
        if getattr(cfg, name) < 0:
            raise ConfigError(f"{name}={getattr(cfg, name)!r}: energy must be >= 0")
    if cfg.energy_move <= 0:
        raise ConfigError("energy_move must be > 0: it normalizes the battery reward term")
    if cfg.start_tilt % TILT_STEP or not TILT_MIN <= cfg.start_tilt <= TILT_MAX:
        raise ConfigError(f"start_tilt={cfg.start_tilt!r}: allowed values are 0, 5, ..., 90")
    if cfg.start_pan % PAN_STEP or not PAN_MIN <= cfg.start_pan <= PAN_MAX:
        raise ConfigError(f"start_pan={cfg.start_pan!r}: allowed values are -90, -75, ..., 90")
    zoom_to_tenths(cfg.start_zoom, "start_zoom")
    _choice(cfg, "start_camera", ("fixed", "random"))
    if len(cfg.static_weights) != len(REWARD_TERMS) or not all(
        isinstance(w, int | float) for w in cfg.static_weights
    ):
        raise ConfigError(
            f"static_weights: expected {len(REWARD_TERMS)} numbers for {', '.join(REWARD_TERMS)}"
        )
    if len(cfg.ewri_ranges) != len(REWARD_TERMS) or not all(
        len(r) == 2 and r[0] <= r[1] for r in cfg.ewri_ranges
    ):
        raise ConfigError(
            f"ewri_ranges: expected {len(REWARD_TERMS)} [low, high] pairs with low <= high "
            f"for {', '.join(REWARD_TERMS)}"
        )
    if cfg.obs_window < 3 or cfg.obs_window % 2 == 0:
        raise ConfigError(f"obs_window={cfg.obs_window!r}: must be an odd integer >= 3")
    if cfg.obs_global < 1:
        raise ConfigError(f"obs_global={cfg.obs_global!r}: must be >= 1")
    if cfg.render_cell_px < 0:
        raise ConfigError(f"render_cell_px={cfg.render_cell_px!r}: must be >= 0")


def _choice(cfg: VCPPConfig, name: str, allowed: tuple[str, ...]) -> None:
    value = getattr(cfg, name)
    if value not in allowed:
        raise ConfigError(f"{name}={value!r}: allowed values are {', '.join(allowed)}")


__all__ = [
    "BASE_SIZE",
    "EWRI_RANGES",
    "REWARD_TERMS",
    "STATIC_WEIGHTS",
    "ConfigError",
    "VCPPConfig",
    "check_keys",
    "zoom_to_tenths",
]
