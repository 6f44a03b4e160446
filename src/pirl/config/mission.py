"""Settings of a written mission (``pirl plan``): speeds, battery, limits (docs/missions.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pirl.config.load import Settings

ALTITUDE_FRAMES = ("relative", "amsl", "terrain")
"""Frames of a mission's heights: above home (``MAV_FRAME_GLOBAL_RELATIVE_ALT``), above sea
level (``MAV_FRAME_GLOBAL``) or above the terrain (``MAV_FRAME_GLOBAL_TERRAIN_ALT``)."""

DEFAULT_ORIGIN = (47.397742, 8.545594)
"""Where a generated world (or a site without a geo-reference) is placed: PX4's simulated
home in Zurich. Not a real survey site; every file written there says so."""


@dataclass(frozen=True)
class MissionSettings(Settings, section="mission"):
    """Every setting of a mission ``pirl plan`` writes."""

    speed_m_s: float = 5.0
    """Cruise speed between waypoints (the flight time's estimate)."""
    climb_m_s: float = 2.0
    """Vertical speed of take-off, climbs and descents."""
    photo_s: float = 1.0
    """Time one photo, camera change or hover step takes."""
    battery_s: float = 1200.0
    """Flight time of one battery; a longer mission is split into sorties."""
    reserve: float = 0.2
    """Share of the battery kept in reserve (the return home is always planned in)."""
    max_items: int = 500
    """Most mission items one sortie may hold (autopilots hold a few hundred to a thousand)."""
    min_alt_m: float = 5.0
    """Refuse a plan with a waypoint lower than this above home."""
    max_alt_m: float = 120.0
    """Refuse a plan with a waypoint higher than this above home."""
    cell_size_m: float = 10.0
    """Metres per cell of a generated world (a site has its own)."""
    level_height_m: float = 10.0
    """Metres between flight levels of a generated world (a site has its own)."""
    autopilot: str = "px4"
    """The .plan's firmware type: px4 or ardupilot."""
    separation_m: float = 5.0
    """A fleet's missions (``pirl plan --uavs``): every pair of UAVs stays at least this far
    apart horizontally or in altitude at every sampled instant (docs/fleets.md)."""
    check_every_s: float = 0.25
    """How often the separation check samples every UAV's position."""
    max_delay_s: float = 120.0
    """The longest a UAV's take-off may be held back for its separation before the plan is
    refused."""

    altitude_frame: str = ""
    """The frame of the heights written: relative, amsl or terrain (``ALTITUDE_FRAMES``);
    empty = amsl on a site with a terrain model, relative elsewhere (docs/missions.md)."""
    terrain_tolerance_m: float = 1.0
    """Over terrain (amsl, relative): points are inserted along a leg wherever the ground
    under it departs from the leg's height above ground by more than this."""
    min_clearance_m: float = 2.0
    """Over terrain: refuse a plan passing closer than this above the surface model (DSM)
    at any point sampled every metre along its legs."""
    max_climb_m_s: float = 3.0
    """Over terrain: the fastest climb along a leg; a steeper leg is flown slower (the
    flight time's estimate)."""
    max_descent_m_s: float = 2.0
    """Over terrain: the fastest descent along a leg."""
    sensor_width_mm: float = 13.2
    """The camera's sensor width (default: a 1-inch 20 MP camera, 13.2 mm) for the ground
    sample distance ``pirl site check`` reports."""
    focal_length_mm: float = 8.8
    """The lens's focal length at zoom 1."""
    image_width_px: int = 5472
    """Pixels across the image."""

    def validate(self) -> None:
        """Positive speeds, times and sizes; a reserve in [0, 1); ordered altitude limits."""
        self.require_positive(
            "speed_m_s", "climb_m_s", "battery_s", "max_items", "cell_size_m", "level_height_m",
            "check_every_s", "sensor_width_mm", "focal_length_mm", "image_width_px",
            "terrain_tolerance_m", "max_climb_m_s", "max_descent_m_s",
        )  # fmt: skip
        if not (math.isfinite(self.min_clearance_m) and self.min_clearance_m >= 0):
            raise self.refuse("min_clearance_m", "must be >= 0")
        if self.altitude_frame:
            self.require_choice("altitude_frame", ALTITUDE_FRAMES)
        for key in ("separation_m", "max_delay_s"):
            if not (math.isfinite(getattr(self, key)) and getattr(self, key) >= 0):
                raise self.refuse(key, "must be >= 0")
        if not (math.isfinite(self.photo_s) and self.photo_s >= 0):
            raise self.refuse("photo_s", "must be >= 0")
        if not 0 <= self.reserve < 1:
            raise self.refuse("reserve", "allowed range is [0, 1)")
        if not 0 <= self.min_alt_m < self.max_alt_m:
            raise self.refuse("max_alt_m", "need 0 <= min_alt_m < max_alt_m")
        if self.max_items < 8:
            raise self.refuse("max_items", "must be >= 8 (take-off, a leg, return)")
        self.require_choice("autopilot", ("px4", "ardupilot"))


__all__ = ["ALTITUDE_FRAMES", "DEFAULT_ORIGIN", "MissionSettings"]
