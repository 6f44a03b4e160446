"""Settings of the grid world and the environment, and the world constants they default to.

:class:`VCPPConfig` holds every value a user may change about the world (the ``env`` section of
a run config, or the keywords of ``gym.make("pirl/VCPP-v0", ...)``); it is loaded and checked by
:mod:`pirl.config.load` like every other section.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pirl.config.choices import Footprint
from pirl.config.errors import ConfigError
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
from pirl.config.load import Settings

BASE_SIZE = (15, 15, 3)
"""The training world the paper scales from."""

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
"""The reward terms, in the order of every weight vector and of the dynamics' term columns."""
STATIC_WEIGHTS = (1.0, -0.6, -0.3, 0.4, 0.35, -1.15, -0.55, 0.4)
"""The static (PPO-SR) weights, in the order of REWARD_TERMS."""
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
"""The EWRI (low, high) uniform ranges, in the order of REWARD_TERMS."""

MAX_UAVS = 62
"""Most UAVs per world (the fleet step keeps one bit per UAV in a 64-bit integer)."""
MAX_TEAMMATES_OBS = 8
"""Most teammates an observation can hold."""

OBS_BLOCKS = ("obs_visits", "obs_target", "obs_target_path", "obs_stall", "obs_teammates")
"""The settings of the observation's optional blocks: a trained policy acts only with the
blocks it was trained with."""


def zoom_to_tenths(zoom: float, key: str = "zoom") -> int:
    """Convert a zoom factor to integer tenths, refusing values off the 0.1 grid."""
    tenths = round(zoom * 10)
    if abs(zoom * 10 - tenths) > 1e-6 or not ZOOM_MIN10 <= tenths <= ZOOM_MAX10:
        raise ConfigError(
            f"{key}={zoom!r} is off the zoom grid: allowed values are 0.5, 0.6, ..., 2.0"
        )
    return tenths


@dataclass(frozen=True)
class VCPPConfig(Settings, section="env"):
    """Every setting of the VCPP world and environment (docs/design.md)."""

    size: tuple[int, int, int] = BASE_SIZE
    """Grid size (X, Y, Z) in cells; each at least 3 (a site's own size when ``site`` is set)."""
    site: str = ""
    """A site folder (docs/sites.md): the map is the site's instead of drawn spheres, and
    resets draw a start from its start cells. Set with ``--site``, which also sets ``size``
    and ``ground_cells`` from the site."""
    ground_cells: int = 0
    """Ground cells that battery capacity and the step limit scale with; 0 = X * Y. A site
    sets its seeable cells, so a site with much blocked ground gets the budget of the ground
    there is to see."""
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
    training only: ``train.camera_start``); 'mixed': half of the scenarios do."""
    start_surveyed: float = 0.0
    """Share of episodes that start with the ground already covered but for one box (each
    side 2 cells to half the world's), drawn anywhere (training only: ``train.surveyed_start``):
    the work left then often lies out of the UAV's local window, as on a large world or a site,
    so a policy learns to find it by the target and the global summary. 0: none (the paper)."""
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
    obs_visits_cap: int = 3
    """With obs_visits: the count at which a cell's visits saturate (the window holds
    min(v, cap)/cap). Until a cell reaches the cap, a greedy policy looping over it sees the
    loop in its window; after that only the battery and step scalars change."""
    obs_target: bool = False
    """Add the direction to the nearest coverable cell not yet covered and its distance in
    cells (saturating at 16), so a policy trained on a small world can find the work left on a
    large one where its local window shows none. False is the paper's observation."""
    obs_target_path: bool = False
    """With obs_target: find that cell by moves at the UAV's altitude around blocked cells
    (breadth-first) and give the direction of the path's first move and its length, instead of
    the straight line, which can point into a wall and trap a greedy policy in front of it."""
    obs_stall: bool = False
    """Add one scalar: the steps since coverage last grew, min(s, 32)/32. Inside a loop
    nothing else the policy sees changes once the visit counts saturate; this climbs by 1/32
    a step, so a policy that has learned what a long stall means can act on it. False is the
    paper's observation."""
    stall_guard: int = 0
    """Steps without new coverage after which the env takes over until coverage grows again:
    it carries out one action, whatever the policy chose (the action mask leaves only that
    one), the first move of the way to the nearest ground not yet covered (details:
    ``pirl.world.dynamics.action_mask``). A rule of the env that ends any loop, for every
    method and act mode alike; episode rows count the steps it chose (``guarded_steps``).
    0 (off) is the paper's environment."""
    uavs: int = 1
    """UAVs flying together in each world, a fleet (docs/fleets.md): they share the map and
    its coverage, each with its own pose, camera, battery, visits and wind; UAV 1 starts at
    the drawn start, its teammates at the free cells nearest to it. 1 is the paper's task."""
    obs_teammates: int = 0
    """Add the nearest this-many teammates to the observation, 6 values each (present, x, y
    and z relative to the UAV, cells in their footprint now, battery), zeros where fewer fly:
    the same size for any fleet, so a policy trained at one size acts at another. 0 is the
    paper's observation."""
    render_cell_px: int = 0
    """Pixels per cell in rgb_array renders; 0 picks a size near 480 pixels."""
    max_memory_gb: float = 0.0
    """Most memory, GB, that the worlds of one command may need (their grids and recording
    buffers, estimated before anything is allocated); a larger request is refused in one line.
    0: half of this machine's memory. Not part of a run's identity (a resume may change it)."""

    @classmethod
    def resolve(
        cls, config: VCPPConfig | Mapping[str, Any] | None, settings: Mapping[str, Any]
    ) -> VCPPConfig:
        """A config (object, mapping or None for the defaults) with keyword ``settings`` on
        top, both checked: what every env constructor and ``gym.make`` take."""
        if config is None:
            base = cls()
        elif isinstance(config, VCPPConfig):
            base = config
        elif isinstance(config, Mapping):
            base = cls.from_dict(config)
        else:
            raise ConfigError(
                f"config must be a VCPPConfig or a mapping, got {type(config).__name__}"
            )
        return base.replace(**settings) if settings else base

    def validate(self) -> None:
        """Sizes, choices, ranges and the camera's start pose on the action grid."""
        size = self.size
        if min(size) < 3:
            raise ConfigError(
                f"{self.where('size')}={size!r} is impossible: every side must be >= 3 cells"
            )
        if self.ground_cells < 0:
            raise self.refuse("ground_cells", "must be >= 0 (0: X * Y)")
        if max(size) > 2048:
            raise self.refuse("size", "sides above 2048 cells are not supported")
        if not (math.isfinite(self.max_memory_gb) and self.max_memory_gb >= 0):
            raise self.refuse("max_memory_gb", "must be >= 0 (0: half of this machine's memory)")
        self.require_choice("footprint", Footprint)
        self.require_choice("reward", ("static", "ewri"))
        if not 0.0 <= self.wind_prob <= 1.0:
            raise self.refuse("wind_prob", "allowed range is [0, 1]")
        if not 0.0 < self.fov_deg < 180.0:
            raise self.refuse("fov_deg", "allowed range is (0, 180)")
        self.require_positive("max_range")
        if not 0 <= self.obstacles_min <= self.obstacles_max:
            raise ConfigError(
                f"{self.where('obstacles_min')}={self.obstacles_min}, "
                f"{self.where('obstacles_max')}={self.obstacles_max}: "
                "need 0 <= obstacles_min <= obstacles_max"
            )
        if not 0 < self.radius_min <= self.radius_max:
            raise ConfigError(
                f"{self.where('radius_min')}={self.radius_min}, "
                f"{self.where('radius_max')}={self.radius_max}: need 0 < radius_min <= radius_max"
            )
        if not (math.isfinite(self.battery_capacity) and self.battery_capacity > 0):
            raise self.refuse("battery_capacity", "must be a positive number")
        if self.max_steps < 1:
            raise self.refuse("max_steps", "must be >= 1")
        for key in (
            "energy_move",
            "energy_climb",
            "energy_descend",
            "energy_camera",
            "energy_hover",
        ):
            if getattr(self, key) < 0:
                raise self.refuse(key, "energy must be >= 0")
        if self.energy_move <= 0:
            raise self.refuse("energy_move", "must be > 0: it normalizes the battery reward term")
        if self.start_tilt % TILT_STEP or not TILT_MIN <= self.start_tilt <= TILT_MAX:
            raise self.refuse("start_tilt", "allowed values are 0, 5, ..., 90")
        if self.start_pan % PAN_STEP or not PAN_MIN <= self.start_pan <= PAN_MAX:
            raise self.refuse("start_pan", "allowed values are -90, -75, ..., 90")
        zoom_to_tenths(self.start_zoom, self.where("start_zoom"))
        self.require_choice("start_camera", ("fixed", "random", "mixed"))
        if not 0.0 <= self.start_surveyed <= 1.0:
            raise self.refuse("start_surveyed", "must be a share in [0, 1]")
        if self.obs_visits_cap < 1:
            raise self.refuse("obs_visits_cap", "must be >= 1")
        if self.stall_guard < 0:
            raise self.refuse("stall_guard", "must be >= 0 (0: off)")
        if not 1 <= self.uavs <= MAX_UAVS:
            raise self.refuse("uavs", f"must be a whole number of UAVs in [1, {MAX_UAVS}]")
        if not 0 <= self.obs_teammates <= MAX_TEAMMATES_OBS:
            raise self.refuse("obs_teammates", f"allowed range is [0, {MAX_TEAMMATES_OBS}]")
        if self.obs_target_path and not self.obs_target:
            raise self.refuse("obs_target_path", "needs obs_target: true (it changes that block)")
        if len(self.static_weights) != len(REWARD_TERMS):
            raise self.refuse(
                "static_weights",
                f"expected {len(REWARD_TERMS)} numbers for {', '.join(REWARD_TERMS)}",
            )
        if len(self.ewri_ranges) != len(REWARD_TERMS) or not all(
            low <= high for low, high in self.ewri_ranges
        ):
            raise self.refuse(
                "ewri_ranges",
                f"expected {len(REWARD_TERMS)} [low, high] pairs with low <= high "
                f"for {', '.join(REWARD_TERMS)}",
            )
        if self.obs_window < 3 or self.obs_window % 2 == 0:
            raise self.refuse("obs_window", "must be an odd integer >= 3")
        if self.obs_global < 1:
            raise self.refuse("obs_global", "must be >= 1")
        if self.render_cell_px < 0:
            raise self.refuse("render_cell_px", "must be >= 0")

    # -- derived values -------------------------------------------------------------------
    @property
    def alpha(self) -> float:
        """Size scale factor relative to the 15x15x3 training world."""
        x, y, z = self.size
        ground = self.ground_cells or x * y
        return (ground * z) / (BASE_SIZE[0] * BASE_SIZE[1] * BASE_SIZE[2])

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
        """Camera zoom at reset in tenths (the dynamics' integer zoom)."""
        return zoom_to_tenths(self.start_zoom, "start_zoom")

    @property
    def obstacle_count_range(self) -> tuple[int, int]:
        """Inclusive (min, max) obstacle count, scaled with area when asked."""
        if not self.obstacles_scale_with_area:
            return self.obstacles_min, self.obstacles_max
        area = self.size[0] * self.size[1] / (BASE_SIZE[0] * BASE_SIZE[1])
        return max(0, round(self.obstacles_min * area)), max(0, round(self.obstacles_max * area))


__all__ = [
    "BASE_SIZE",
    "EWRI_RANGES",
    "REWARD_TERMS",
    "STATIC_WEIGHTS",
    "VCPPConfig",
    "zoom_to_tenths",
]
