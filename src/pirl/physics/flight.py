"""The mission logic every physics backend shares: waypoints, coverage, battery, metrics.

A :class:`Mission` turns the policy's grid actions into waypoints for a flying drone and turns
the drone's flight back into the grid's bookkeeping, so that PyFlyt and Webots run the same
rules and only differ in how they fly. It keeps a :class:`~pirl.world.state.WorldBatch` of one
world as its grid-level state and applies the grid's own rules to it: the camera
(:func:`pirl.world.dynamics.camera_action`), the booking of a view
(:func:`~pirl.world.dynamics.book_view`), the visit count and the close of a step (battery,
counters, reward terms, termination: :func:`~pirl.world.dynamics.close_step`), the
observation (:func:`pirl.env.observation.build_observations`) and the metrics
(:func:`pirl.world.metrics.episode_metrics`). Only the flight and the mapping from a
continuous pose to cells and footprints are its own.

One step, as a backend drives it::

    plan = mission.begin_step(action)           # camera change or a new waypoint
    while not mission.update(dt, pose, power, contact):
        fly towards mission.target_position()   # the backend's physics, dt at a time
    obs, terminated, truncated, info = mission.end_step(pose)

Rules (docs/physics.md):

- **Waypoints.** A move targets the centre of the neighbouring cell of the cell the drone is
  in now (its position rounded to the grid), so wind drift is part of what the policy sees. A
  move out of the grid is refused by the geofence: no flight, one collision (as in the grid).
  A move into an obstacle is flown; the contact is the collision, and the drone is sent back
  to the cell it came from. A move ends when the drone is within ``tolerance_m`` of its
  waypoint, or after ``step_timeout_s`` (a timeout). A camera action changes tilt, pan or zoom
  exactly as in the grid and holds the drone at its cell for ``camera_hold_s``.
- **Coverage.** The footprint is evaluated from the continuous pose (:mod:`.coverage`) at
  ``sample_hz`` during the step and once at its end; the step's view is the union of its
  samples and is booked like one grid view (new cells, views, redundant cells).
- **Battery.** ``energy_per_hover_s`` units per second of hover-equivalent power, where the
  power relative to hover is the mean cube of the rotors' speed relative to hover speed
  (:func:`normalized_power`), plus ``camera_energy`` per camera action. Same capacity, step
  limit and BE formula as the grid. Every unit is booked to one cause
  (:data:`ENERGY_CAUSES`, the ``energy_<cause>`` metrics, which add up to ``energy_used``),
  and the episode's ``end`` says why it ended (``coverage``, ``battery`` or ``step_limit``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from pirl.config.errors import ConfigError
from pirl.config.physics import PhysicsConfig
from pirl.config.world import REWARD_TERMS, VCPPConfig
from pirl.env.info import InfoSnapshot
from pirl.env.observation import build_observations, obs_layout, obs_size_for
from pirl.physics.coverage import footprint_cells_pose, view_angles
from pirl.world import dynamics as D
from pirl.world.footprint import (
    NO_GROUND,
    PAPER,
    CameraPose,
    buffer_rows,
    footprint_model,
    ground_at,
)
from pirl.world.metrics import episode_metrics
from pirl.world.scenario import Scenario, draw_scenario
from pirl.world.state import WorldBatch

Cell = tuple[int, int, int]

MOVE, CAMERA, REFUSED = "move", "camera", "refused"

ENERGY_CAUSES = ("move", "climb", "descend", "hover", "camera", "geofence", "timeout", "contact")
"""Where a physics episode's battery went, one ``energy_<cause>`` metric each (they add up to
``energy_used``): ``move``, ``climb``, ``descend``: flight of x/y, z+ and z- moves that reached
their waypoint, up to a contact; ``hover``: holding the cell during camera actions;
``camera``: the gimbal and zoom motors; ``geofence``: holding the cell after a move refused by
the geofence; ``timeout``: flight of moves that ran out ``step_timeout_s``, up to a contact;
``contact``: flight after a contact that counted as a collision, to the end of its step."""


@dataclass(frozen=True)
class Pose:
    """A drone's pose: position in metres (world frame, z up) and attitude in radians.

    ``rpy`` is (roll, pitch, yaw) with body -> world rotation Rz(yaw) Ry(pitch) Rx(roll).
    """

    position: np.ndarray
    rpy: np.ndarray

    @classmethod
    def level(cls, position: np.ndarray | tuple[float, float, float]) -> Pose:
        """A level pose (zero roll, pitch and yaw) at ``position``."""
        return cls(np.asarray(position, dtype=np.float64), np.zeros(3))


@dataclass(frozen=True)
class StepPlan:
    """What one policy action asks of the drone."""

    action: int
    kind: str
    """``move`` (fly to ``target``), ``camera`` (hold ``origin``) or ``refused`` (geofence)."""
    origin: Cell
    target: Cell
    camera: tuple[int, int, int]
    """(tilt degrees, pan degrees, zoom tenths) for this step."""


def normalized_power(speed_ratios: np.ndarray, max_ratio: float = np.inf) -> float:
    """Electrical power relative to hover, from each rotor's speed relative to hover speed.

    Momentum theory: a rotor's induced power grows as thrust^1.5 and its thrust as speed^2,
    so its power grows as speed^3. The mean over rotors is 1.0 in a steady hover. Speed
    ratios above ``max_ratio`` (the real drone's top rotor speed) are charged at it.
    """
    r = np.minimum(np.abs(np.asarray(speed_ratios, dtype=np.float64)), max_ratio)
    return float(np.dot(r * r, r)) / r.size


def touching(position: np.ndarray, spheres_m: np.ndarray, body_radius_m: float) -> bool:
    """Whether a body of ``body_radius_m`` at ``position`` touches a sphere (rows cx, cy, cz, r).

    The geometric contact test for backends that do not report contacts themselves.
    """
    if not len(spheres_m):
        return False
    d = np.linalg.norm(spheres_m[:, :3] - np.asarray(position)[None, :], axis=1)
    return bool((d <= spheres_m[:, 3] + body_radius_m).any())


class Mission:
    """One episode's grid-level state, advanced by a physics backend (see the module doc)."""

    def __init__(self, env_cfg: VCPPConfig, physics: PhysicsConfig | None = None) -> None:
        self.cfg = env_cfg
        self.physics = physics or PhysicsConfig()
        # A site's terrain in metres of this flight, its lowest point at z = 0 (levels scale
        # from the site's level height to the physics one, as the grid's levels do).
        self.ground_m: np.ndarray | None = None
        if env_cfg.site:
            from pirl.world.site import load_site

            site = load_site(env_cfg.site)
            if site.has_terrain:
                lifted = (site.terrain - site.terrain.min()) / site.level_height_m
                self.ground_m = np.ascontiguousarray(lifted * self.physics.level_height_m)
        self.world = WorldBatch(env_cfg, 1)
        if self.world.step_limit < 1:
            raise ConfigError(
                f"size={env_cfg.size}, max_steps={env_cfg.max_steps}: the step limit scaled by "
                f"alpha={env_cfg.alpha:.3g} rounds to 0; raise max_steps or set scale_by_alpha"
            )
        self.model = footprint_model(env_cfg.footprint)
        self.obs = np.zeros((1, obs_size_for(env_cfg)), np.float32)
        self._layout = obs_layout(env_cfg)
        self._buf = np.empty((buffer_rows(self.model, env_cfg.max_range), 2), dtype=np.int64)
        self._weights = np.zeros((1, len(REWARD_TERMS)))
        self._seen = np.zeros(env_cfg.size[:2], dtype=np.bool_)
        self._index = np.array([0], dtype=np.int64)
        self._masks = np.ones((1, D.N_ACTIONS), dtype=np.bool_)  # written at every info
        p = self.physics
        self._camera_energy = env_cfg.energy_camera if p.camera_energy is None else p.camera_energy
        self._sample_period = 1.0 / p.sample_hz
        # The footprint's ground: the terrain in horizontal cell sizes (its vertical unit).
        self._ground = NO_GROUND if self.ground_m is None else self.ground_m / p.cell_size_m
        self.scenario: Scenario | None = None
        self.plan: StepPlan | None = None

    # -- geometry -------------------------------------------------------------------------
    def ground_at(self, x: float, y: float) -> float:
        """The ground's height in metres at grid point (x, y) (the footprint's bilinear rule,
        :func:`pirl.world.footprint.ground_at`; 0 on flat ground)."""
        if self.ground_m is None:
            return 0.0
        return float(ground_at(self.ground_m, float(x), float(y)))

    def cell_position(self, cell: Cell | np.ndarray) -> np.ndarray:
        """Centre of ``cell`` in metres: (i, j) * cell size, (k + 1) * level height above the
        ground there."""
        p = self.physics
        i, j, k = (float(c) for c in cell)
        z = (k + 1.0) * p.level_height_m + self.ground_at(i, j)
        return np.array([i * p.cell_size_m, j * p.cell_size_m, z])

    def cell_coords(self, position: np.ndarray) -> np.ndarray:
        """Continuous grid coordinates (x, y, level) of a position in metres (the level from
        the height above the ground under it)."""
        p = self.physics
        x, y, z = (float(v) for v in position)
        x, y = x / p.cell_size_m, y / p.cell_size_m
        return np.array([x, y, (z - self.ground_at(x, y)) / p.level_height_m - 1.0])

    def nearest_cell(self, position: np.ndarray) -> Cell:
        """The grid cell the drone is in: its position rounded (halves up), kept in the grid."""
        c = np.floor(self.cell_coords(position) + 0.5).astype(np.int64)
        size = self.cfg.size
        return tuple(int(min(max(c[a], 0), size[a] - 1)) for a in range(3))  # type: ignore[return-value]

    def in_obstacle(self, pose: Pose) -> bool:
        """Whether ``pose`` rounds to an obstacle cell (the drone is pressed into a sphere)."""
        return bool(self.world.blocked[0][self.nearest_cell(pose.position)])

    def obstacle_spheres_m(self) -> np.ndarray:
        """The scenario's obstacles as spheres in metres: rows (cx, cy, cz, radius)."""
        if self.scenario is None:
            raise RuntimeError("call reset() first")
        out = np.zeros((len(self.scenario.obstacles), 4))
        for k, (cx, cy, cz, r) in enumerate(self.scenario.obstacles):
            out[k, :3] = self.cell_position((cx, cy, cz))
            out[k, 3] = r * self.physics.cell_size_m
        return out

    def obstacle_boxes_m(self) -> np.ndarray:
        """A site's buildings as a few boxes in metres: rows (cx, cy, cz, half x, half y,
        half z); none in a generated world. Level 0's boxes stand on the ground (z = 0)."""
        if self.scenario is None:
            raise RuntimeError("call reset() first")
        if self.scenario.grids is None:
            return np.zeros((0, 6))
        from pirl.world.boxes import merge_boxes

        c, lh = self.physics.cell_size_m, self.physics.level_height_m
        if self.ground_m is not None:
            return self._columns_m()
        boxes = merge_boxes(self.scenario.grids.occluding)
        out = np.zeros((len(boxes), 6))
        for n, (x0, y0, z0, x1, y1, z1) in enumerate(boxes):
            lo = np.array([(x0 - 0.5) * c, (y0 - 0.5) * c, 0.0 if z0 == 0 else (z0 + 0.5) * lh])
            hi = np.array([(x1 + 0.5) * c, (y1 + 0.5) * c, (z1 + 1.5) * lh])
            out[n, :3], out[n, 3:] = (lo + hi) / 2, (hi - lo) / 2
        return out

    def _columns_m(self) -> np.ndarray:
        """Over terrain, each building cell as its own box, from below the lowest ground of
        its cell (the terrain, a heightfield, covers the rest) to its top above the ground at
        its centre: boxes merged across cells would float over a slope or sink into it."""
        c, lh = self.physics.cell_size_m, self.physics.level_height_m
        g = self.ground_m
        assert g is not None and self.scenario is not None and self.scenario.grids is not None
        occ = self.scenario.grids.occluding
        rows = []
        for x, y in zip(*np.nonzero(occ.any(axis=2)), strict=True):
            top = g[x, y] + (int(np.flatnonzero(occ[x, y])[-1]) + 1.5) * lh
            low = float(g[max(x - 1, 0) : x + 2, max(y - 1, 0) : y + 2].min()) - lh
            rows.append([x * c, y * c, (top + low) / 2, c / 2, c / 2, (top - low) / 2])
        return np.array(rows).reshape(-1, 6)

    def camera(self) -> tuple[int, int, int]:
        """The gimbal's setting now: (tilt degrees, pan degrees, zoom tenths)."""
        return self.world.camera_setting(0)

    def target_position(self) -> np.ndarray:
        """The waypoint the drone should fly to now, metres."""
        return self._target_m

    # -- episode --------------------------------------------------------------------------
    def reset(
        self, seed: int | None = None, scenario: Scenario | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """New episode: the scenario of ``seed`` exactly as ``VCPPEnv.reset(seed=seed)`` draws
        it (or a given one); returns the first observation and info."""
        if scenario is None:
            scenario = scenario_for_seed(self.cfg, seed)
        self.scenario = scenario
        # The drone starts level at the start cell's centre, so the grid's first view (taken
        # by load_scenario) is exactly the view from the drone's pose.
        self.world.load_scenario(0, scenario)
        p = self.physics
        # Obstacles in the footprint's units (heights in cell sizes, ground at -1) for occlusion.
        obs = np.asarray(scenario.obstacles, dtype=np.float64).reshape(-1, 4).copy()
        obs[:, 2] = (obs[:, 2] + 1.0) * p.level_height_m / p.cell_size_m - 1.0
        self._geo_obstacles = obs
        self.start = tuple(int(v) for v in scenario.start)
        self._target_m = self.cell_position(self.start)
        self.sim_seconds = 0.0
        self.timeouts = 0
        self.recoveries = 0
        self.contacts = 0
        self.geofence = 0
        self.energy_used = 0.0
        self.energy_by_cause = dict.fromkeys(ENERGY_CAUSES, 0.0)
        self.end: str | None = None
        self._track_sum = 0.0
        self._steps_done = 0
        self.plan = None
        self.done = False
        self._in_contact = False
        return self._observation(), self._info()

    # -- one step -------------------------------------------------------------------------
    def begin_step(self, action: int) -> StepPlan:
        """Apply ``action`` to the grid-level state; the plan says what to fly."""
        if self.scenario is None:
            raise RuntimeError("call reset() first")
        if self.done:
            raise RuntimeError("the episode is over; call reset()")
        action = int(action)
        if not 0 <= action < D.N_ACTIONS:
            raise ValueError(f"action must be an integer in [0, {D.N_ACTIONS}); got {action}")
        w = self.world
        action = int(D.steer(w.arrays, w.params, 0, action))  # the grid's stall guard
        origin: Cell = w.position(0)
        tilt, pan, zoom = w.camera_setting(0)
        self._camera_before = (tilt, pan, zoom)
        kind, target = CAMERA, origin
        if action < D.N_MOVES:
            d = D.MOVE_DELTAS[action]
            cand = (origin[0] + d[0], origin[1] + d[1], origin[2] + d[2])
            inside = all(0 <= c < s for c, s in zip(cand, self.cfg.size, strict=True))
            kind, target = (MOVE, cand) if inside else (REFUSED, origin)
        else:
            D.camera_action(w.arrays, 0, action)  # the grid's camera rule, limits included
            tilt, pan, zoom = w.camera_setting(0)
        self.plan = StepPlan(action, kind, origin, target, (tilt, pan, zoom))
        self._target_blocked = bool(self.world.blocked[0][target])
        self._bounced = False
        self._target_m = self.cell_position(target)
        self._t = 0.0
        self._next_sample = self._sample_period
        # Hover-equivalent seconds of flight before and after this step's first collision
        # contact, booked to causes at the step's end (a timeout is known only then).
        self._power_s = 0.0
        self._power_after_contact_s = 0.0
        self._contact_hit = False
        if kind == MOVE:
            self._cause = {D.Z_PLUS: "climb", D.Z_MINUS: "descend"}.get(action, "move")
        else:
            self._cause = "hover" if kind == CAMERA else "geofence"
        self._collided = kind == REFUSED
        self._timed_out = False
        self._seen[:] = False
        self._last_fp = 0
        if kind == REFUSED:
            self.geofence += 1
        return self.plan

    def update(self, dt: float, pose: Pose, power: float = 1.0, contact: bool = False) -> bool:
        """Advance the step by ``dt`` seconds of flight ending at ``pose``; True when it is over.

        ``power`` is the flight power relative to hover over ``dt`` (see
        :func:`normalized_power`); ``contact`` whether the drone touched an obstacle.
        """
        plan = self.plan
        if plan is None:
            raise RuntimeError("call begin_step() first")
        p = self.physics
        self._t += dt
        if self._contact_hit:
            self._power_after_contact_s += power * dt
        else:
            self._power_s += power * dt
        if contact:
            # A collision is a contact that begins, or one made pushing into an obstacle cell:
            # a drone merely resting against a sphere (a free cell can lie closer to a sphere
            # than the drone's own radius) does not collide again at every step.
            pushing = plan.kind == MOVE and self._target_blocked
            if not self._collided and (pushing or not self._in_contact):
                self._collided = True
                self._contact_hit = True
                self.contacts += 1
            if plan.kind == MOVE and self._target_blocked and not self._bounced:
                # Bounce back from an obstacle cell to the cell it came from. A move between
                # free cells that grazes a sphere goes on: the drone slides around it.
                self._bounced = True
                self._target_m = self.cell_position(plan.origin)
        self._in_contact = contact
        while self._t >= self._next_sample - 1e-9:
            self.sample(pose)
            self._next_sample += self._sample_period
        if plan.kind == MOVE:
            dist = float(np.linalg.norm(np.asarray(pose.position) - self._target_m))
            # An obstacle cell's centre lies inside its sphere: that waypoint is never
            # "reached", the flight ends with the bounce back (or the timeout).
            reachable = not self._target_blocked or self._bounced
            if reachable and dist <= p.tolerance_m:
                return True
            if self._t >= p.step_timeout_s - 1e-9:
                self._timed_out = True
                return True
            return False
        return self._t >= p.camera_hold_s - 1e-9

    def footprint(self, pose: Pose, camera: tuple[int, int, int] | None = None) -> np.ndarray:
        """Ground cells (k, 2) seen from ``pose`` with ``camera`` (default: the current one).

        ``camera`` is (tilt degrees, pan degrees, zoom tenths). The rows live in a buffer
        that the next call overwrites.
        """
        tilt, pan, zoom10 = self.camera() if camera is None else camera
        x, y, level = self.cell_coords(pose.position)
        if self.model == PAPER:
            t_eff, p_eff, z = float(tilt), float(pan), float(level)
        else:
            t_eff, p_eff = view_angles(tilt, pan, pose.rpy, self.physics.stabilized_gimbal)
            # Height above the ground under it in horizontal cell sizes, minus one (the grid's
            # levels).
            above = float(pose.position[2]) - self.ground_at(float(x), float(y))
            z = above / self.physics.cell_size_m - 1.0
        at = CameraPose(float(x), float(y), z, t_eff, p_eff, int(zoom10))
        n = footprint_cells_pose(
            self.world.lens, at, self._geo_obstacles, self.world.occluding[0], self._ground,
            self._buf,
        )  # fmt: skip
        return self._buf[:n]

    def sample(self, pose: Pose) -> int:
        """Add the view from ``pose`` to this step's view; returns the footprint's size."""
        cells = self.footprint(pose)
        self._seen[cells[:, 0], cells[:, 1]] = True
        self._last_fp = len(cells)
        return self._last_fp

    def note_recovery(self) -> None:
        """Count a recovery (the backend put a tumbled drone back at its cell)."""
        self.recoveries += 1

    def end_step(self, pose: Pose) -> tuple[np.ndarray, bool, bool, dict[str, Any]]:
        """Book the step: pose, coverage, battery, counters; (obs, terminated, truncated, info)."""
        plan = self.plan
        if plan is None:
            raise RuntimeError("call begin_step() first")
        w = self.world
        self.sample(pose)  # the arrival view (a repeat of the last sample costs nothing)
        cell = self.nearest_cell(pose.position)
        if w.blocked[0][cell]:
            # The drone pressed into an obstacle's sphere deeper than half a cell: the grid has
            # no such position (observations, planners and visits assume free cells), so the
            # step is booked at the free cell it came from, like a bounce.
            cell = plan.origin
        st = w.status[0:1]  # a view: numpy writes a record's fields through it
        st["x"], st["y"], st["z"] = cell
        moved = cell != plan.origin
        cam_changed = plan.camera != self._camera_before

        new = self._book_view()
        used = self._book_energy(plan)
        curiosity = D.visit(w.arrays, 0) if moved else 0.0
        intended = self.nearest_cell(self._target_m)
        off_target = cell != intended and not self._collided
        self._track_sum += float(np.linalg.norm(np.asarray(pose.position) - self._target_m))
        self._steps_done += 1
        self.timeouts += int(self._timed_out)
        self.sim_seconds += self._t

        # The grid's own close of a step: battery, counters, reward terms, episode end. An
        # arrival off the intended cell counts where the grid counts a wind push.
        outcome = D.StepOutcome(
            float(used), int(new), moved, cam_changed, self._collided, off_target, float(curiosity)
        )
        D.close_step(w.arrays, w.params, 0, outcome)
        flags = w.flags[0]
        terminated, truncated = bool(flags["terminated"]), bool(flags["truncated"])
        self.done = terminated or truncated
        if self.done:
            self.end = self._end_reason(truncated)
        self.plan = None
        return self._observation(), terminated, truncated, self._info()

    @property
    def timed_out(self) -> bool:
        """Whether the step being flown has run out ``step_timeout_s``."""
        return self._timed_out

    # -- results --------------------------------------------------------------------------
    def metrics(self) -> dict[str, Any]:
        """The grid's episode metrics plus the physics extras (docs/physics.md): counters,
        ``energy_<cause>`` for each of :data:`ENERGY_CAUSES` and ``end`` (None while the
        episode runs)."""
        out: dict[str, Any] = episode_metrics(self.world, 0)
        steps = max(1, self._steps_done)
        out.update(
            {
                "timeouts": self.timeouts,
                "tracking_error_m": self._track_sum / steps,
                "sim_seconds": self.sim_seconds,
                "contacts": self.contacts,
                "geofence": self.geofence,
                "recoveries": self.recoveries,
                "energy_used": self.energy_used,
                **{f"energy_{c}": v for c, v in self.energy_by_cause.items()},
                "end": self.end,
            }
        )
        return out

    # -- internals ------------------------------------------------------------------------
    def _book_energy(self, plan: StepPlan) -> float:
        """Book this step's battery use to its causes; returns the step's total."""
        per_s = self.physics.energy_per_hover_s
        # A move that ran out its time is booked as a timeout up to its first contact, so that
        # what was lost to unreachable waypoints shows apart from ordinary flight.
        cause = "timeout" if self._timed_out and plan.kind == MOVE else self._cause
        parts = {cause: per_s * self._power_s, "contact": per_s * self._power_after_contact_s}
        if plan.kind == CAMERA:
            parts["camera"] = self._camera_energy
        used = 0.0
        for key, value in parts.items():
            self.energy_by_cause[key] += value
            used += value
        self.energy_used += used
        return used

    def _end_reason(self, truncated: bool) -> str:
        row = self.world.status[0]
        if row["covered"] >= row["coverable"]:
            return "coverage"
        if not truncated and self.world.energy[0] <= 0.0:
            return "battery"
        return "step_limit"

    def _book_view(self) -> int:
        """Book this step's view (the union of its samples) with the grid's own booking rule
        (:func:`pirl.world.dynamics.book_view`); the footprint sum takes the arrival view's
        size, the analogue of the grid's one view per step."""
        w = self.world
        cells = np.ascontiguousarray(np.argwhere(self._seen))
        w.status[0:1]["footprint_sum"] += self._last_fp
        return int(D.book_view(w.arrays, 0, cells, True))

    def _observation(self) -> np.ndarray:
        w = self.world
        build_observations(w.arrays, w.params, self._layout, self._index, self.obs)
        return self.obs[0].copy()

    def _info(self) -> dict[str, Any]:
        w = self.world
        metrics = {0: self.metrics()} if self.done else {}
        # The grid's valid-action rule, so a policy trained with masks flies with them too.
        D.action_masks(w.arrays, w.params, self._index, self._masks)
        snap = InfoSnapshot(w, self._weights, metrics, self._masks)
        return snap.info(0)


def scenario_for_seed(env_cfg: VCPPConfig, seed: int | None) -> Scenario:
    """The scenario ``VCPPEnv(env_cfg).reset(seed=seed)`` plays (obstacles, start, wind seed).

    The same generator (Gymnasium's seeding) and the same draws, in the same order.
    """
    rng, _ = seeding.np_random(seed)
    return draw_scenario(env_cfg, rng)


__all__ = [
    "CAMERA",
    "MOVE",
    "REFUSED",
    "Mission",
    "Pose",
    "StepPlan",
    "normalized_power",
    "scenario_for_seed",
    "touching",
]
