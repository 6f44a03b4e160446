"""The PyFlyt backend: a QuadX quadrotor in PyBullet flies the policy's waypoints.

:func:`run_physics_episode` plays one scenario seed: a :class:`~pirl.physics.flight.Mission`
turns each action into a waypoint or a camera change, and :class:`PyFlytFlight` flies it in a
headless PyFlyt ``Aviary`` (PyBullet): QuadX in PyFlyt's position mode (mode 7: x, y, yaw,
z), sphere obstacles as static collision bodies, the seeded :class:`~pirl.physics.wind.GustWind`
acting on the body's drag. Coverage is geometric from the drone's pose (PyFlyt's camera
images are not used: its gimbal image is upside down in 0.29.0, and the paper's coverage is
position-based anyway).

Determinism: the motor noise and the wind are drawn from generators seeded by the scenario,
and PyBullet in DIRECT mode is deterministic for the same build on the same machine, so an
episode replays exactly; across machines or PyBullet builds, floating-point differences may
grow into different trajectories.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import io
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from pirl.agents.policy import Policy
from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.physics.flight import Mission, Pose, normalized_power
from pirl.world.metrics import Milestone, PathTail

# PyBullet calls made every physics step. BulletClient resolves them through __getattr__ with
# inspect and functools on every call, 10-20% of a step's time; binding them once
# on the instance skips that (same functions, same client).
_HOT_CALLS = (
    "applyExternalForce", "applyExternalTorque", "getContactPoints",
    "getBasePositionAndOrientation", "getBaseVelocity", "getMatrixFromQuaternion",
    "getEulerFromQuaternion", "getLinkStates", "stepSimulation",
)  # fmt: skip
_GRAVITY = 9.81


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Silence stdout and stderr, C level included (pybullet prints its build banner on
    stderr, PyFlyt banners and escapes on stdout). Exceptions still propagate."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = (os.dup(1), os.dup(2))
    except OSError:  # no real stdout: nothing to silence at the C level
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            yield
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        # C's stdio buffers a pipe's output: flush what the libraries printed into /dev/null
        # before the streams are given back, or it comes out later.
        with contextlib.suppress(Exception):
            ctypes.CDLL(None).fflush(None)
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])
        os.close(devnull)


class PyFlytFlight:
    """A PyFlyt Aviary with one QuadX per mission and the first mission's obstacles.

    Build it after every ``mission.reset()``; ``fly(mission)`` flies the first drone's current
    step to its end; :meth:`fly_fleet` flies several drones together, each its own mission
    (the missions of one fleet: the same world, their own starts).
    """

    def __init__(self, mission: Mission | Sequence[Mission]) -> None:
        missions = [mission] if isinstance(mission, Mission) else list(mission)
        if any(m.scenario is None for m in missions):
            raise RuntimeError("reset the mission before building its flight")
        with _quiet():
            import pybullet
            from PyFlyt.core import Aviary

            from pirl.physics.wind import GustWind

        first = missions[0]
        p = first.physics
        self.physics = p
        self.missions = missions
        wind_seq, noise_seq = np.random.SeedSequence(first.scenario.wind_seed).spawn(2)
        windy = any(p.wind_mean) or p.wind_gust > 0
        wind_options: dict[str, Any] = {}
        if windy:
            wind_options = {
                "mean": p.wind_mean,
                "gust": p.wind_gust,
                "gust_period_s": p.gust_period_s,
                "seed": int(wind_seq.generate_state(1)[0]),
            }
        starts = np.stack([m.cell_position(m.start) for m in missions])
        with _quiet():
            self.aviary = Aviary(
                start_pos=starts,
                start_orn=np.zeros((len(missions), 3)),
                drone_type="quadx",
                drone_options={"control_hz": p.control_hz},
                wind_type=GustWind if windy else None,
                wind_options=wind_options,
                render=False,
                physics_hz=p.physics_hz,
                np_random=np.random.default_rng(noise_seq),
            )
        av = self.aviary
        for name in _HOT_CALLS:
            bound = functools.partial(getattr(pybullet, name), physicsClientId=av._client)
            av.__dict__[name] = bound
        av.__dict__["LINK_FRAME"] = pybullet.LINK_FRAME
        self.drones = list(av.drones)
        self.drone = self.drones[0]
        for drone in self.drones:
            # A stiffer, faster position loop than the cf2x defaults (1/s, 2 m/s): one-cell
            # hops in about 1.3 s instead of 2, with leans still under 20 degrees.
            drone.Kp_lin_pos = np.array([p.position_gain, p.position_gain])
            drone.lim_lin_pos = np.array([p.max_speed_m_s, p.max_speed_m_s])
        self.dt = float(av.step_period)

        self.sphere_ids = []
        if first.ground_m is not None:  # a site's terrain: a heightfield over the flat plane
            self.sphere_ids.append(self._terrain(pybullet, first.ground_m, p.cell_size_m))
        for cx, cy, cz, r in first.obstacle_spheres_m():
            shape = av.createCollisionShape(pybullet.GEOM_SPHERE, radius=float(r))
            body = av.createMultiBody(
                baseMass=0.0, baseCollisionShapeIndex=shape, basePosition=[cx, cy, cz]
            )
            self.sphere_ids.append(body)
        for row in first.obstacle_boxes_m():  # a site: its buildings, merged into boxes
            shape = av.createCollisionShape(
                pybullet.GEOM_BOX, halfExtents=[float(v) for v in row[3:]]
            )
            body = av.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                basePosition=[float(v) for v in row[:3]],
            )
            self.sphere_ids.append(body)
        av.register_all_new_bodies()
        self._spheres = np.array(self.sphere_ids, dtype=np.int64)
        self._ids = np.array([d.Id for d in self.drones], dtype=np.int64)

        # Hover throttle: total thrust m g shared by 4 rotors of thrust coef * (throttle*rpm)^2.
        drone = self.drone
        uid = drone.Id
        mass = sum(av.getDynamicsInfo(uid, link)[0] for link in range(-1, av.getNumJoints(uid)))
        max_thrust = float(drone.motors.thrust_coef.ravel()[0] * drone.motors.max_rpm[0] ** 2)
        self.hover_throttle = float(np.sqrt(mass * _GRAVITY / (4 * max_thrust)))
        self._setpoints: list[np.ndarray | None] = [None] * len(self.drones)
        for i in range(len(self.drones)):
            self._hold(i)
            self._set_target(starts[i], i)

    def _terrain(self, pybullet: Any, ground: np.ndarray, cell_m: float) -> int:
        """The terrain as PyBullet's heightfield shape: a post at every cell centre, (i, j) at
        (i, j) x ``cell_m``, triangles between them (a straight move between two neighbouring
        centres runs along an edge, on the ground's linear profile). PyBullet centres the
        field on its base: half its extent and its middle height."""
        sx, sy = ground.shape
        shape = self.aviary.createCollisionShape(
            pybullet.GEOM_HEIGHTFIELD, meshScale=[cell_m, cell_m, 1.0],
            heightfieldData=ground.T.ravel().tolist(), numHeightfieldRows=sx,
            numHeightfieldColumns=sy,
        )  # fmt: skip
        middle = (float(ground.max()) + float(ground.min())) / 2
        return self.aviary.createMultiBody(
            baseMass=0.0, baseCollisionShapeIndex=shape,
            basePosition=[(sx - 1) / 2 * cell_m, (sy - 1) / 2 * cell_m, middle],
        )  # fmt: skip

    def _hold(self, i: int = 0) -> None:
        """Position mode, holding where drone ``i`` is, trimmed for hover.

        PyFlyt's altitude loop builds the hover thrust in its integrator from zero, so a drone
        switched to position mode sags by about 9 cm and needs some 10 s to climb back.
        Starting the integrator at the hover throttle (the steady-state thrust command) is
        the trim a real flight controller carries.
        """
        drone = self.drones[i]
        drone.set_mode(7)
        drone.z_PIDs[0]._integral = np.array([self.hover_throttle])
        self._setpoints[i] = None

    def _set_target(self, position: np.ndarray, i: int = 0) -> None:
        if self._setpoints[i] is None or not np.array_equal(self._setpoints[i], position):
            self._setpoints[i] = np.array(position, dtype=np.float64)
            x, y, z = self._setpoints[i]
            self.aviary.set_setpoint(i, np.array([x, y, 0.0, z]))

    def pose(self, i: int = 0) -> Pose:
        """Drone ``i``'s pose now (position metres, roll/pitch/yaw radians)."""
        state = self.drones[i].state
        return Pose(state[3].copy(), state[1].copy())

    def _flown(self, mission: Mission, i: int, contacts: np.ndarray) -> tuple[Pose, bool]:
        """After a physics step: drone ``i``'s pose (put back if it tumbled or touched the
        ground), and whether its mission's step is over."""
        drone = self.drones[i]
        limit = np.radians(self.physics.recover_tilt_deg)
        # Thrust grows as rotor speed squared: the real drone's top speed relative to hover.
        top_speed = float(np.sqrt(self.physics.max_thrust_to_weight))
        pose = self.pose(i)
        power = normalized_power(drone.motors.throttle / self.hover_throttle, top_speed)
        touched = bool(len(self._spheres) and contacts[drone.Id, self._spheres].any())
        if np.abs(pose.rpy[:2]).max() > limit or contacts[drone.Id, self.aviary.planeId]:
            self._recover(mission, i)
            pose = self.pose(i)
        if not mission.update(self.dt, pose, power, touched):
            return pose, False
        if mission.timed_out and (touched or mission.in_obstacle(pose)):
            # Wedged against a sphere at full thrust: it would stay there for every later
            # step (the 4 timeouts in a row). A crash: put it back.
            self._recover(mission, i)
            pose = self.pose(i)
        return pose, True

    def fly(self, mission: Mission) -> Pose:
        """Fly the mission's current step (the first drone's) until it is over; returns the
        final pose."""
        while True:
            self._set_target(mission.target_position())
            self.aviary.step()
            pose, over = self._flown(mission, 0, self.aviary.contact_array)
            if over:
                return pose

    def fly_fleet(
        self,
        actions: Sequence[Callable[[], int | None]],
        take_off_s: Sequence[float],
        log: Callable[[float], Any] | None = None,
    ) -> dict[str, Any]:
        """Fly every drone's mission together until each has run out of actions or ended.

        ``actions[i]()`` gives drone ``i``'s next grid action (None: it has finished). Drone
        ``i`` hovers at its start until ``take_off_s[i]`` simulated seconds have passed; a
        drone that has finished lands where it is (PyFlyt cannot take a body out of the
        world), so teammates pass over it as they would over a drone on the ground. Returns
        the contacts between drones (pairs that touched, counted when they start touching),
        the closest approach of two drones that have taken off and not finished, and apart
        from it the closest approach of such a drone to one still waiting at its start (held
        there in the air, where the fleet's separation check has it on the ground). ``log``
        gets the simulated time about every 60 s of it.
        """
        av, missions = self.aviary, self.missions
        k = len(missions)
        state = ["waiting"] * k
        t, logged = 0.0, 0.0
        touching = np.zeros((k, k), dtype=bool)
        between, closest, to_waiting = 0, np.inf, np.inf
        while any(s != "done" for s in state):
            for i in range(k):
                if state[i] == "waiting" and t >= take_off_s[i] - 1e-9:
                    state[i] = self._next(missions[i], actions[i], i)
                if state[i] == "flying":
                    self._set_target(missions[i].target_position(), i)
            av.step()
            t += self.dt
            contacts = av.contact_array
            pair = contacts[np.ix_(self._ids, self._ids)] & ~np.eye(k, dtype=bool)
            between += int((pair & ~touching).sum()) // 2
            touching = pair
            up = [i for i in range(k) if state[i] != "done"]
            if len(up) > 1:
                at = np.array([self.drones[i].state[3] for i in up])
                gaps = np.linalg.norm(at[:, None] - at[None, :], axis=-1)
                waits = np.array([state[i] == "waiting" for i in up])
                pairs = np.triu(np.ones_like(gaps, dtype=bool), 1)
                flown = pairs & ~waits[:, None] & ~waits[None, :]
                one_waits = pairs & (waits[:, None] != waits[None, :])
                if flown.any():
                    closest = min(closest, float(gaps[flown].min()))
                if one_waits.any():
                    to_waiting = min(to_waiting, float(gaps[one_waits].min()))
            for i in range(k):
                if state[i] == "flying":
                    pose, over = self._flown(missions[i], i, contacts)
                    if over:
                        missions[i].end_step(pose)
                        state[i] = self._next(missions[i], actions[i], i)
            if log is not None and t - logged >= 60.0:
                logged = t
                log(t)
        return {
            "contacts_between_drones": between,
            "closest_approach_m": None if not np.isfinite(closest) else round(closest, 3),
            "closest_to_waiting_m": None if not np.isfinite(to_waiting) else round(to_waiting, 3),
            "sim_seconds": round(t, 1),
        }

    def _next(self, mission: Mission, action: Callable[[], int | None], i: int) -> str:
        """Begin drone ``i``'s next step; "done" (and land it) when it has none left."""
        a = None if mission.done else action()
        if a is not None:
            mission.begin_step(a)
            return "flying"
        here = self.pose(i).position
        self._set_target(np.array([here[0], here[1], 0.0]), i)
        return "done"

    def _recover(self, mission: Mission, i: int = 0) -> None:
        """Put a tumbled, grounded or wedged drone back, level and still, at its last cell's
        centre."""
        av, drone = self.aviary, self.drones[i]
        plan = mission.plan
        cell = plan.origin if plan is not None else mission.start
        position = mission.cell_position(cell)
        av.resetBasePositionAndOrientation(drone.Id, position, [0.0, 0.0, 0.0, 1.0])
        av.resetBaseVelocity(drone.Id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        drone.motors.throttle[:] = self.hover_throttle
        drone.update_state()
        self._hold(i)  # fresh controller state
        mission.note_recovery()

    def close(self) -> None:
        """Disconnect from PyBullet."""
        if getattr(self, "aviary", None) is not None:
            with contextlib.suppress(Exception):
                self.aviary.disconnect()
            self.aviary = None  # type: ignore[assignment]

    def __enter__(self) -> PyFlytFlight:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_physics_episode(
    env_cfg: VCPPConfig, policy: Policy, seed: int, physics: PhysicsConfig | None = None
) -> dict[str, float]:
    """Play ``policy`` zero-shot on scenario ``seed`` with a PyFlyt quadrotor; its metrics.

    Same scenario (obstacles, start) as ``VCPPEnv(env_cfg).reset(seed=seed)``, same step
    limit and battery capacity (scaled by alpha like the grid), same metrics as
    :func:`pirl.world.metrics.episode_metrics` plus the physics extras of
    :meth:`Mission.metrics`.
    """
    mission = Mission(env_cfg, physics or PhysicsConfig())
    obs, info = mission.reset(seed)
    policy.reset(mission.world, 0, seed=seed)
    tail, near = PathTail(1), Milestone(1)
    with PyFlytFlight(mission) as flight:
        done = False
        while not done:
            mission.begin_step(int(policy.act(obs, info)))
            pose = flight.fly(mission)
            obs, terminated, truncated, info = mission.end_step(pose)
            tail.record(mission.world)
            near.record(mission.world)
            done = terminated or truncated
    return {**mission.metrics(), "tail_cells": tail.distinct(0), "steps_to_99": near.steps(0)}


__all__ = ["PyFlytFlight", "run_physics_episode"]
