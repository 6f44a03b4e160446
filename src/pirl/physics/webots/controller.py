"""Webots controller: a trained PIRL policy flies the Mavic 2 Pro of a ``pirl webots-world``.

For users who have Webots; not exercised in CI (Webots cannot be installed there). The glue is
thin on purpose: waypoints from the policy's actions, coverage from the pose, battery and
metrics are :class:`~pirl.physics.flight.Mission`, the code the PyFlyt backend runs and the
tests check; the flight law is :class:`~pirl.physics.webots.pilot.MavicPilot` (tested without
Webots). What is Webots-only is reading the devices and writing the motors:

- propellers ``front left/front right/rear left/rear right propeller`` (velocity control),
- ``inertial unit`` (roll, pitch, yaw), ``gps`` (position, speed), ``gyro`` (rates),
- gimbal motors ``camera pitch`` (the policy's tilt) and ``camera yaw`` (pan minus the body's
  heading), ``camera roll`` (levels the image when the gimbal is stabilized),
- zoom through the camera's field of view (``Camera.setFov``, within its ``CameraZoom``).

Collisions are geometric: the drone's body sphere (``body_radius_m``) touching an obstacle
sphere. At the end of the episode one JSON line of metrics is appended to ``--out`` (the same
fields as ``pirl evaluate``) and the simulation quits (the robot is a supervisor).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.physics.flight import Mission, Pose, normalized_power, touching
from pirl.physics.webots.pilot import MavicPilot

PROPELLERS = (
    "front left propeller",
    "front right propeller",
    "rear left propeller",
    "rear right propeller",
)
SETTLE_S = 3.0
"""Seconds the drone holds its start cell before the episode starts (not counted)."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The controller's arguments (the world's ``controllerArgs``)."""
    ap = argparse.ArgumentParser(prog="pirl_mavic", description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="boustrophedon", help="Run folder or built-in method.")
    ap.add_argument("--size", type=int, nargs=3, default=(30, 30, 3), metavar=("X", "Y", "Z"))
    ap.add_argument("--seed", type=int, default=0, help="Scenario seed of the world.")
    ap.add_argument("--cell-size", type=float, default=2.0, help="Cell size, metres.")
    ap.add_argument("--level-height", type=float, default=None, help="Level spacing, metres.")
    ap.add_argument("--footprint", default=None, help="paper or frustum.")
    ap.add_argument("--config", default=None, help="YAML of environment settings.")
    ap.add_argument("--out", default="pirl_webots_episodes.jsonl", help="Metrics JSON lines.")
    ap.add_argument("--stay", action="store_true", help="Do not quit at the end.")
    return ap.parse_args(argv)


def mission_from_args(args: argparse.Namespace) -> Mission:
    """The Mission the world was generated for (same size, seed, metric layout)."""
    cfg = VCPPConfig.from_yaml(args.config) if args.config else VCPPConfig()
    changes: dict[str, Any] = {"size": tuple(args.size)}
    if args.footprint:
        changes["footprint"] = args.footprint
    cfg = cfg.replace(**changes)
    level = args.level_height if args.level_height is not None else args.cell_size
    physics = PhysicsConfig(cell_size_m=args.cell_size, level_height_m=level, body_radius_m=0.25)
    return Mission(cfg, physics)


class WebotsFlight:
    """The Webots devices of the Mavic 2 Pro, read and written once per basic time step."""

    def __init__(self, robot: Any, mission: Mission) -> None:
        self.robot = robot
        self.mission = mission
        self.ms = int(robot.getBasicTimeStep())
        self.dt = self.ms / 1000.0
        dev = robot.getDevice
        self.imu, self.gps, self.gyro = dev("inertial unit"), dev("gps"), dev("gyro")
        for sensor in (self.imu, self.gps, self.gyro):
            sensor.enable(self.ms)
        self.camera = dev("camera")
        self.camera.enable(self.ms)
        self.pitch_motor, self.yaw_motor = dev("camera pitch"), dev("camera yaw")
        self.roll_motor = dev("camera roll")
        self.props = [dev(name) for name in PROPELLERS]
        for motor in self.props:
            motor.setPosition(float("inf"))
            motor.setVelocity(1.0)
        self.pilot = MavicPilot()
        self.spheres = mission.obstacle_spheres_m()
        self._last_position: np.ndarray | None = None

    def pose(self) -> tuple[Pose, np.ndarray, np.ndarray]:
        """(pose, velocity, gyro rates) from the sensors."""
        position = np.array(self.gps.getValues(), dtype=np.float64)
        try:
            velocity = np.array(self.gps.getSpeedVector(), dtype=np.float64)
        except AttributeError:  # Webots before R2023a: differentiate the position
            last = self._last_position if self._last_position is not None else position
            velocity = (position - last) / self.dt
        self._last_position = position
        rpy = np.array(self.imu.getRollPitchYaw(), dtype=np.float64)
        return Pose(position, rpy), velocity, np.array(self.gyro.getValues(), dtype=np.float64)

    def actuate(self, pose: Pose, velocity: np.ndarray, rates: np.ndarray) -> float:
        """Drive propellers and gimbal towards the mission's waypoint; the power vs hover."""
        mission = self.mission
        speeds = self.pilot.propeller_speeds(
            pose.position, velocity, pose.rpy, rates, mission.target_position()
        )
        for motor, speed in zip(self.props, speeds, strict=True):
            motor.setVelocity(float(speed))
        tilt, pan, zoom10 = mission.camera()
        pitch = math.radians(tilt)
        roll = 0.0
        if mission.physics.stabilized_gimbal:
            pitch -= float(pose.rpy[1])
            roll = -float(pose.rpy[0])
        self.pitch_motor.setPosition(_clamp(pitch, -0.5, 1.7))
        self.yaw_motor.setPosition(_clamp(math.radians(pan) - float(pose.rpy[2]), -1.7, 1.7))
        self.roll_motor.setPosition(_clamp(roll, -0.5, 0.5))
        half = math.tan(math.radians(mission.cfg.fov_deg) / 2.0)
        fov = 2.0 * math.atan(half / (zoom10 / 10.0))
        self.camera.setFov(_clamp(fov, self.camera.getMinFov(), self.camera.getMaxFov()))
        return normalized_power(self.pilot.power_ratios(speeds))

    def tick(self) -> tuple[Pose, float, bool] | None:
        """One basic time step: (pose, power, contact), or None when Webots stops."""
        pose, velocity, rates = self.pose()
        power = self.actuate(pose, velocity, rates)
        if self.robot.step(self.ms) == -1:
            return None
        hit = touching(pose.position, self.spheres, self.mission.physics.body_radius_m)
        return pose, power, hit


def _clamp(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


def run(robot: Any, args: argparse.Namespace) -> dict[str, float] | None:
    """Fly one episode in Webots; its metrics (None if Webots stopped first)."""
    from pirl.agents.loading import load_policy

    mission = mission_from_args(args)
    obs, info = mission.reset(args.seed)
    policy = load_policy(args.policy, seed=args.seed)
    policy.reset(mission.world, 0, seed=args.seed)
    flight = WebotsFlight(robot, mission)
    # Take-off and settle at the start cell; the episode's clock starts afterwards.
    settle_until = robot.getTime() + SETTLE_S
    while robot.getTime() < settle_until:
        if flight.tick() is None:
            return None
    wall = time.perf_counter()
    done = False
    while not done:
        mission.begin_step(int(policy.act(obs, info)))
        while True:
            ticked = flight.tick()
            if ticked is None:
                return None
            pose, power, hit = ticked
            if mission.update(flight.dt, pose, power, hit):
                break
        obs, terminated, truncated, info = mission.end_step(pose)
        done = terminated or truncated
    metrics = mission.metrics()
    record = {
        "method": getattr(policy, "name", str(args.policy)),
        "label": getattr(policy, "label", str(args.policy)),
        "sim": "webots",
        "size": "x".join(str(s) for s in args.size),
        "seed": args.seed,
        "source": str(args.policy),
        **{k: (float(v) if isinstance(v, np.floating) else v) for k, v in metrics.items()},
        "wall_seconds": time.perf_counter() - wall,
    }
    with open(Path(args.out), "a") as fh:
        fh.write(json.dumps(record, sort_keys=True) + "\n")
    print(json.dumps(record, sort_keys=True))
    return metrics


def main(argv: list[str] | None = None) -> None:
    """Entry point of the Webots controller (``controllers/pirl_mavic/pirl_mavic.py``)."""
    from controller import Supervisor  # provided by Webots

    args = parse_args(argv)
    robot = Supervisor()
    run(robot, args)
    if not args.stay:
        robot.simulationQuit(0)


__all__ = ["WebotsFlight", "main", "mission_from_args", "parse_args", "run"]
