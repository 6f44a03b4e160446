"""Settings of the physics backends (PyFlyt here, Webots for users who have it).

:class:`PhysicsConfig` is the ``physics`` section of a run config; it is loaded and checked by
:mod:`pirl.config.load` like every other section.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pirl.config.load import Settings


@dataclass(frozen=True)
class PhysicsConfig(Settings, section="physics"):
    """How the grid world maps onto a flying quadrotor (docs/physics.md)."""

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

    def validate(self) -> None:
        """Positive rates and distances, the controller dividing the physics rate."""
        positive = (
            "cell_size_m", "level_height_m", "gust_period_s", "tolerance_m", "step_timeout_s",
            "sample_hz", "position_gain", "max_speed_m_s", "body_radius_m",
            "max_thrust_to_weight",
        )  # fmt: skip
        for key in positive:
            if not (math.isfinite(getattr(self, key)) and getattr(self, key) > 0):
                raise self.refuse(key, "must be a positive number")
        for key in ("wind_gust", "camera_hold_s", "energy_per_hover_s"):
            if not getattr(self, key) >= 0:
                raise self.refuse(key, "must be a number >= 0")
        if not self.max_thrust_to_weight >= 1:
            raise self.refuse("max_thrust_to_weight", "must be >= 1 (hover)")
        if not all(math.isfinite(w) for w in self.wind_mean):
            raise self.refuse("wind_mean", "expected three finite numbers (x, y, z) in m/s")
        # The flight code does float maths with it; YAML gives [1, 0, 0] as integers.
        object.__setattr__(self, "wind_mean", tuple(float(w) for w in self.wind_mean))
        self.require_positive("physics_hz", "control_hz")
        if self.physics_hz % self.control_hz:
            raise self.refuse("control_hz", f"must divide physics_hz={self.physics_hz}")
        if self.camera_energy is not None and not self.camera_energy >= 0:
            raise self.refuse("camera_energy", "must be >= 0 or None")
        if not 0 < self.recover_tilt_deg <= 180:
            raise self.refuse("recover_tilt_deg", "allowed (0, 180]")


__all__ = ["PhysicsConfig"]
