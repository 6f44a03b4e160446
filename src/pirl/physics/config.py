"""Settings of the physics backends (PyFlyt here, Webots for users who have it).

One frozen dataclass, :class:`PhysicsConfig`. Every field has a docstring; impossible values
raise :class:`~pirl.world.config.ConfigError` naming the field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from pirl.world.config import ConfigError, check_keys


@dataclass(frozen=True)
class PhysicsConfig:
    """How the grid world maps onto a flying quadrotor (DESIGN.md section 10)."""

    cell_size_m: float = 1.0
    """Horizontal side of a grid cell, metres. Cell (i, j) is centred at (i, j) * cell_size_m."""
    level_height_m: float = 1.0
    """Vertical spacing of the grid levels, metres: level z flies (z + 1) * level_height_m above
    the ground (the grid puts the ground one level below level 0). Keep it equal to
    cell_size_m for footprints and obstacle spheres that agree exactly with the grid."""
    wind_mean: tuple[float, float, float] = (1.5, 0.5, 0.0)
    """Mean wind velocity (x, y, z) in the world frame, m/s."""
    wind_gust: float = 1.0
    """Gust strength: standard deviation of each horizontal gust component, m/s (0 = steady)."""
    gust_period_s: float = 4.0
    """Typical period of the gusts, seconds (the gust spectrum is centred on 1 / this)."""
    tolerance_m: float = 0.25
    """A move's waypoint counts as reached within this distance of the cell centre, metres."""
    step_timeout_s: float = 5.0
    """A move that has not reached its waypoint after this much simulated time ends anyway and
    is recorded as a timeout; the policy then sees wherever the drone is."""
    camera_hold_s: float = 0.12
    """Simulated time a camera action takes (gimbal slew or zoom), the drone holding its cell."""
    sample_hz: float = 10.0
    """Coverage sampling rate during flight, per simulated second (plus one sample at the end
    of every step)."""
    physics_hz: int = 240
    """PyBullet physics rate (PyFlyt's default; lower rates make the small quadrotor sluggish)."""
    control_hz: int = 120
    """Flight controller rate of the PyFlyt QuadX (PyFlyt's default); must divide physics_hz.
    Slower control is cheaper but makes the cf2x thrust loop chatter (see docs/physics.md)."""
    position_gain: float = 2.0
    """Position-loop gain of the QuadX waypoint controller, 1/s (PyFlyt's cf2x default is 1)."""
    max_speed_m_s: float = 3.0
    """Horizontal speed limit of the waypoint controller, m/s (PyFlyt's cf2x default is 2)."""
    energy_per_hover_s: float = 0.8
    """Battery units per second of flight at hover power. Calibrated so that a one-cell x/y
    move costs about energy_move + energy_hover of the grid (1.1 units), so a typical episode
    uses about as much battery as in the grid (docs/physics.md)."""
    max_thrust_to_weight: float = 2.2
    """Thrust-to-weight ratio of the real drone the battery is charged for; rotor power is
    charged at most at the rotor speed of that thrust ((2.2)^1.5 = 3.3x hover power for a
    Crazyflie 2.x). PyFlyt's cf2x has 7.5x its weight in thrust and its motors saturate when a
    drone is pressed against an obstacle, which the cube law would charge at up to 39x hover
    power (docs/physics.md: what a timeout costs)."""
    camera_energy: float | None = None
    """Battery units per camera action for the gimbal and zoom motors; None uses the grid's
    energy_camera (0.2). With the hover during camera_hold_s a camera action then costs about
    the grid's 0.3."""
    stabilized_gimbal: bool = False
    """True: a 3-axis gimbal cancels body roll and pitch, so only position and yaw move the
    view. False (default): body roll and pitch tilt the camera (the harsher case)."""
    recover_tilt_deg: float = 60.0
    """A drone tilted beyond this (a tumble after a crash) is put back, level and still, at the
    centre of its last cell; each such recovery is counted."""
    body_radius_m: float = 0.1
    """Radius of the drone for the geometric obstacle check of the Webots controller, metres
    (PyFlyt detects contacts from the collision shapes instead)."""

    def __post_init__(self) -> None:
        _validate(self)

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> PhysicsConfig:
        """Build from a mapping, refusing unknown keys."""
        if not isinstance(values, Mapping):
            raise ConfigError(f"expected a mapping of physics settings, got {type(values)}")
        check_keys(values, [f.name for f in fields(cls)], "physics")
        clean = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
        return cls(**clean)

    def to_dict(self) -> dict[str, Any]:
        """Plain, YAML-safe dict of every setting."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = list(value) if isinstance(value, tuple) else value
        return out


def _validate(cfg: PhysicsConfig) -> None:
    positive = (
        "cell_size_m", "level_height_m", "gust_period_s", "tolerance_m", "step_timeout_s",
        "sample_hz", "position_gain", "max_speed_m_s", "body_radius_m", "max_thrust_to_weight",
    )  # fmt: skip
    for name in positive:
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"physics.{name}={value!r}: expected a number")
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"physics.{name}={value!r}: must be a positive number")
    for name in ("wind_gust", "camera_hold_s", "energy_per_hover_s"):
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
            raise ConfigError(f"physics.{name}={value!r}: must be a number >= 0")
    if not cfg.max_thrust_to_weight >= 1:
        raise ConfigError(
            f"physics.max_thrust_to_weight={cfg.max_thrust_to_weight!r}: must be >= 1 (hover)"
        )
    wind = cfg.wind_mean
    if not (
        isinstance(wind, tuple | list)
        and len(wind) == 3
        and all(isinstance(w, int | float) and math.isfinite(w) for w in wind)
    ):
        raise ConfigError(f"physics.wind_mean={wind!r}: expected three numbers (x, y, z) in m/s")
    object.__setattr__(cfg, "wind_mean", tuple(float(w) for w in wind))
    for name in ("physics_hz", "control_hz"):
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(f"physics.{name}={value!r}: must be a positive integer")
    if cfg.physics_hz % cfg.control_hz:
        raise ConfigError(
            f"physics.control_hz={cfg.control_hz} must divide physics_hz={cfg.physics_hz}"
        )
    if not isinstance(cfg.stabilized_gimbal, bool):
        raise ConfigError(f"physics.stabilized_gimbal={cfg.stabilized_gimbal!r}: true or false")
    for name in ("recover_tilt_deg", "camera_energy"):
        value = getattr(cfg, name)
        if (value is not None or name != "camera_energy") and (
            isinstance(value, bool) or not isinstance(value, int | float)
        ):
            raise ConfigError(f"physics.{name}={value!r}: expected a number")
    if cfg.camera_energy is not None and not cfg.camera_energy >= 0:
        raise ConfigError(f"physics.camera_energy={cfg.camera_energy!r}: must be >= 0 or None")
    if not 0 < cfg.recover_tilt_deg <= 180:
        raise ConfigError(f"physics.recover_tilt_deg={cfg.recover_tilt_deg!r}: allowed (0, 180]")


__all__ = ["PhysicsConfig"]
