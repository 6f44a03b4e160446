"""Waypoint pilot for Webots' Mavic 2 Pro: pose and target in, four propeller speeds out.

Pure arithmetic (no Webots import), so it is tested here. The attitude and altitude
stabilizer and its constants are those of Webots' own Mavic 2 Pro samples (R2023, ENU frame):
propeller speeds around a hover value, a cubic altitude term, proportional roll and pitch
terms plus the gyro rates, and "disturbances" that lean the drone to move. On top of it, a
proportional-derivative position loop in the body frame sets the disturbances, and a
proportional yaw loop holds the heading at 0 so that the gimbal's yaw can follow the
world-frame pan.

Signs follow the samples: a negative pitch disturbance moves forward (+x body), a positive
roll disturbance moves left (+y body), a positive yaw disturbance turns left. The position
gains are a starting point, not tuned in Webots here (no Webots in CI).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _clamp(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


@dataclass
class MavicPilot:
    """Stabilizer and waypoint loop of the Mavic 2 Pro (see the module doc)."""

    vertical_thrust: float = 68.5
    """Propeller speed (rad/s) around which the sample stabilizer works: about hover."""
    vertical_offset: float = 0.6
    """Altitude offset the sample's cubic altitude term targets, metres."""
    vertical_p: float = 3.0
    roll_p: float = 50.0
    pitch_p: float = 30.0
    position_p: float = 1.2
    """Disturbance per metre of position error."""
    position_d: float = 1.5
    """Disturbance per m/s of velocity (damping)."""
    max_pitch_disturbance: float = 2.0
    max_roll_disturbance: float = 1.5
    yaw_p: float = 1.0
    max_yaw_disturbance: float = 1.3

    def propeller_speeds(
        self,
        position: np.ndarray,
        velocity: np.ndarray,
        rpy: np.ndarray,
        rates: np.ndarray,
        target: np.ndarray,
        yaw_target: float = 0.0,
    ) -> np.ndarray:
        """Signed speeds (rad/s) for front left, front right, rear left, rear right propellers.

        ``position``, ``velocity`` and ``target`` in metres and m/s (world frame, z up);
        ``rpy`` the inertial unit's roll, pitch, yaw; ``rates`` the gyro's (x, y, z) rates.
        """
        roll, pitch, yaw = (float(a) for a in rpy)
        c, s = math.cos(yaw), math.sin(yaw)
        ex, ey = float(target[0] - position[0]), float(target[1] - position[1])
        vx, vy = float(velocity[0]), float(velocity[1])
        # World -> body frame (heading only: the stabilizer keeps roll and pitch small).
        ex_b, ey_b = c * ex + s * ey, -s * ex + c * ey
        vx_b, vy_b = c * vx + s * vy, -s * vx + c * vy
        forward = self.position_p * ex_b - self.position_d * vx_b
        left = self.position_p * ey_b - self.position_d * vy_b
        pitch_dist = -_clamp(forward, -self.max_pitch_disturbance, self.max_pitch_disturbance)
        roll_dist = _clamp(left, -self.max_roll_disturbance, self.max_roll_disturbance)
        yaw_err = math.atan2(math.sin(yaw_target - yaw), math.cos(yaw_target - yaw))
        yaw_dist = _clamp(self.yaw_p * yaw_err, -self.max_yaw_disturbance, self.max_yaw_disturbance)

        roll_in = self.roll_p * _clamp(roll, -1.0, 1.0) + float(rates[0]) + roll_dist
        pitch_in = self.pitch_p * _clamp(pitch, -1.0, 1.0) + float(rates[1]) + pitch_dist
        dz = _clamp(float(target[2] - position[2]) + self.vertical_offset, -1.0, 1.0)
        base = self.vertical_thrust + self.vertical_p * dz**3
        fl = base - yaw_dist + pitch_in - roll_in
        fr = base + yaw_dist + pitch_in + roll_in
        rl = base + yaw_dist - pitch_in - roll_in
        rr = base - yaw_dist - pitch_in + roll_in
        # Front right and rear left spin the other way.
        return np.array([fl, -fr, -rl, rr])

    def power_ratios(self, speeds: np.ndarray) -> np.ndarray:
        """Each propeller's speed relative to the hover speed (for the energy model)."""
        return np.abs(np.asarray(speeds, dtype=np.float64)) / self.vertical_thrust


__all__ = ["MavicPilot"]
