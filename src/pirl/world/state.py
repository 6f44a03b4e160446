"""A batch of grid worlds: the state arrays and scenario generation (reset).

:class:`WorldBatch` owns the numpy arrays of N worlds of one size; the compiled rules of
:mod:`pirl.world.dynamics` read and write them (stepped by :class:`pirl.env.core.EnvCore`,
whose one fused kernel also weighs rewards and builds observations). Scenario generation (obstacles,
start cell, wind stream) draws from a ``numpy.random.Generator`` per world, so a world reset
with seed s is the same whether it lives alone or in a batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from pirl.config import grid
from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.world import dynamics as D
from pirl.world.footprint import FRUSTUM, PAPER, buffer_rows, footprint_cells, max_footprint_cells

_MAX_SCENARIO_TRIES = 200


@dataclass(frozen=True)
class Scenario:
    """What a seed fixes about an episode: obstacles, start cell and the wind stream."""

    obstacles: np.ndarray  # (n, 4): cx, cy, cz, radius in cell units
    start: tuple[int, int, int]
    wind_seed: int
    camera: tuple[int, int, int] | None = None
    """Starting (tilt, pan, zoom tenths) if drawn (``start_camera: random``); else the config's."""


@numba.njit(cache=True)
def _fill_blocked(obstacles, out):
    sx, sy, sz = out.shape
    for k in range(obstacles.shape[0]):
        cx, cy, cz, r = obstacles[k, 0], obstacles[k, 1], obstacles[k, 2], obstacles[k, 3]
        # Only the sphere's bounding box can be blocked by it.
        for i in range(max(0, int(np.floor(cx - r))), min(sx, int(np.ceil(cx + r)) + 1)):
            for j in range(max(0, int(np.floor(cy - r))), min(sy, int(np.ceil(cy + r)) + 1)):
                for m in range(max(0, int(np.floor(cz - r))), min(sz, int(np.ceil(cz + r)) + 1)):
                    if (i - cx) ** 2 + (j - cy) ** 2 + (m - cz) ** 2 <= r * r:
                        out[i, j, m] = True


def blocked_grid(size: tuple[int, int, int], obstacles: np.ndarray) -> np.ndarray:
    """Cells whose centre lies within an obstacle sphere (distance <= radius)."""
    blocked = np.zeros(size, dtype=np.bool_)
    _fill_blocked(np.asarray(obstacles, dtype=np.float64).reshape(-1, 4), blocked)
    return blocked


def draw_scenario(cfg: VCPPConfig, rng: np.random.Generator) -> Scenario:
    """Draw obstacles, a free start cell and the wind seed from ``rng`` (DESIGN.md section 3).

    Obstacle layouts that leave no free cell or no coverable ground are drawn again.
    """
    sx, sy, sz = cfg.size
    lo, hi = cfg.obstacle_count_range
    span = np.array([sx - 1, sy - 1, sz - 1], dtype=np.float64)
    for _ in range(_MAX_SCENARIO_TRIES):
        n = int(rng.integers(lo, hi + 1))
        centers = rng.uniform(0.0, 1.0, size=(n, 3)) * span
        radii = rng.uniform(cfg.radius_min, cfg.radius_max, size=n)
        obstacles = np.concatenate([centers, radii[:, None]], axis=1)
        blocked = blocked_grid(cfg.size, obstacles)
        free = np.flatnonzero(~blocked)
        if free.size and not blocked[:, :, 0].all():
            start = np.unravel_index(free[int(rng.integers(free.size))], cfg.size)
            wind_seed = int(rng.integers(0, 2**63 - 1))
            camera = None
            if cfg.start_camera == "random":  # drawn last: fixed-start scenarios stay the same
                camera = (
                    int(rng.choice(grid.tilt_steps())),
                    int(rng.choice(grid.pan_steps())),
                    int(rng.integers(grid.ZOOM_MIN10, grid.ZOOM_MAX10 + 1)),
                )
            start_cell = (int(start[0]), int(start[1]), int(start[2]))
            return Scenario(obstacles, start_cell, wind_seed, camera)
    raise ConfigError(
        f"size={cfg.size}: could not place {lo}-{hi} obstacles of radius "
        f"{cfg.radius_min}-{cfg.radius_max} and keep a free cell and coverable ground; "
        "use a larger world or smaller/fewer obstacles"
    )


@numba.njit(cache=True)
def _reset_bookkeeping(e, ints, views, redmask, visits, blk_todo, blk_total, coverable, bx, by):
    views[e] = 0
    redmask[e] = False
    visits[e] = 0
    blk_todo[e] = 0
    blk_total[e] = 0
    n = 0
    for i in range(coverable.shape[1]):
        for j in range(coverable.shape[2]):
            if coverable[e, i, j]:
                n += 1
                blk_todo[e, bx[i], by[j]] += 1
                blk_total[e, bx[i], by[j]] += 1
    ints[e, D.COVERABLE] = n
    visits[e, ints[e, D.PX], ints[e, D.PY], ints[e, D.PZ]] = 1


class WorldBatch:
    """N grid worlds of one configuration (their state; :class:`pirl.env.core.EnvCore` steps them).

    ``parallel`` spreads the worlds over numba threads; the results are the same either way.
    It is off by default: on a small shared machine (2 cores, with training and an LLM busy) a
    parallel step waits for its slowest thread and can be far slower than one thread.

    Public arrays (first axis = world): ``ints`` (see the column constants in
    :mod:`pirl.world.dynamics`), ``energy`` (units left), ``blocked`` (X, Y, Z), ``coverable``
    and ``views`` (X, Y; views = how many steps saw the cell), ``redmask`` (cells seen by a
    redundant step), ``visits`` (X, Y, Z), ``obstacles`` (max_obstacles, 4). After a step:
    ``terms`` (raw reward terms) and ``flags`` (per-step events).
    """

    def __init__(self, cfg: VCPPConfig, num: int, parallel: bool | None = None) -> None:
        if num < 1:
            raise ConfigError(f"num_envs={num}: need at least 1 world")
        self.cfg = cfg
        self.num = num
        sx, sy, sz = cfg.size
        g = cfg.obs_global
        self.model = PAPER if cfg.footprint == "paper" else FRUSTUM
        self.capacity = float(cfg.capacity)
        self.step_limit = int(cfg.step_limit)
        self.max_obstacles = max(1, cfg.obstacle_count_range[1])
        self.max_footprint = max_footprint_cells(self.model, sz, cfg.fov_deg, cfg.max_range)

        self.ints = np.zeros((num, D.N_INT_COLS), dtype=np.int64)
        self.energy = np.zeros(num, dtype=np.float64)
        self.rng = np.zeros(num, dtype=np.uint64)
        self.blocked = np.zeros((num, sx, sy, sz), dtype=np.bool_)
        self.coverable = np.zeros((num, sx, sy), dtype=np.bool_)
        self.views = np.zeros((num, sx, sy), dtype=np.int32)
        self.redmask = np.zeros((num, sx, sy), dtype=np.bool_)
        self.visits = np.zeros((num, sx, sy, sz), dtype=np.int32)
        self.blk_todo = np.zeros((num, g, g), dtype=np.int32)
        self.blk_total = np.zeros((num, g, g), dtype=np.int32)
        self.bx = (np.arange(sx) * g // sx).astype(np.int64)
        self.by = (np.arange(sy) * g // sy).astype(np.int64)
        self.obstacles = np.zeros((num, self.max_obstacles, 4), dtype=np.float64)
        self.terms = np.zeros((num, D.N_TERMS), dtype=np.float64)
        self.flags = np.zeros((num, D.N_FLAG_COLS), dtype=np.int64)
        self.buf = np.zeros((num, buffer_rows(self.model, cfg.max_range), 2), dtype=np.int64)
        self.parallel = bool(parallel) and num > 1

        self.pf = np.zeros(D.N_PF, dtype=np.float64)
        self.pf[D.PF_FOV] = cfg.fov_deg
        self.pf[D.PF_RANGE] = cfg.max_range
        self.pf[D.PF_WIND] = cfg.wind_prob
        self.pf[D.PF_E_MOVE] = cfg.energy_move
        self.pf[D.PF_E_CLIMB] = cfg.energy_climb
        self.pf[D.PF_E_DESCEND] = cfg.energy_descend
        self.pf[D.PF_E_CAM] = cfg.energy_camera
        self.pf[D.PF_E_HOVER] = cfg.energy_hover
        self.pf[D.PF_MAX_FP] = self.max_footprint
        self.pi = np.array(
            [self.model, int(cfg.occlusion), sx, sy, sz, self.step_limit], dtype=np.int64
        )

    # -- reset ----------------------------------------------------------------------------
    def reset_world(self, e: int, rng: np.random.Generator) -> Scenario:
        """Start a new episode in world ``e`` from a scenario drawn with ``rng``."""
        scenario = draw_scenario(self.cfg, rng)
        self.load_scenario(e, scenario)
        return scenario

    def load_scenario(self, e: int, scenario: Scenario) -> None:
        """Start a new episode in world ``e`` on a given scenario."""
        cfg = self.cfg
        n = len(scenario.obstacles)
        if n > self.max_obstacles:
            raise ConfigError(f"scenario has {n} obstacles; this world holds {self.max_obstacles}")
        blocked = blocked_grid(cfg.size, scenario.obstacles)
        start = tuple(int(v) for v in scenario.start)
        if len(start) != 3 or not all(0 <= v < s for v, s in zip(start, cfg.size, strict=True)):
            raise ConfigError(f"scenario start {scenario.start} lies outside the grid {cfg.size}")
        if blocked[start]:
            raise ConfigError(f"scenario start {start} lies inside an obstacle")
        self.obstacles[e] = 0.0
        self.obstacles[e, :n] = scenario.obstacles
        self.blocked[e] = blocked
        self.coverable[e] = ~self.blocked[e, :, :, 0]
        row = self.ints[e]
        row[:] = 0
        row[D.PX], row[D.PY], row[D.PZ] = start
        camera = scenario.camera or (cfg.start_tilt, cfg.start_pan, cfg.start_zoom10)
        row[D.TILT], row[D.PAN], row[D.ZOOM] = camera
        row[D.N_OBS] = n
        self.energy[e] = self.capacity
        self.rng[e] = np.uint64(scenario.wind_seed)
        _reset_bookkeeping(
            e, self.ints, self.views, self.redmask, self.visits, self.blk_todo, self.blk_total,
            self.coverable, self.bx, self.by,
        )  # fmt: skip
        # The camera sees before the first action; that first view earns no reward.
        D.observe(
            e, self.ints, self.coverable, self.views, self.redmask, self.blk_todo, self.bx,
            self.by, self.obstacles, self.pf, self.pi, self.buf[e], False,
        )  # fmt: skip
        self.terms[e] = 0.0
        self.flags[e] = 0

    # -- queries --------------------------------------------------------------------------
    def footprint(
        self,
        e: int,
        pose: tuple[int, int, int] | None = None,
        camera: tuple[int, int, int] | None = None,
    ) -> np.ndarray:
        """Ground cells (k, 2) seen by world ``e`` now, or from another pose/camera.

        ``camera`` is (tilt degrees, pan degrees, zoom tenths).
        """
        row = self.ints[e]
        x, y, z = pose if pose is not None else (row[D.PX], row[D.PY], row[D.PZ])
        tilt, pan, zoom10 = camera if camera is not None else (row[D.TILT], row[D.PAN], row[D.ZOOM])
        buf = np.empty_like(self.buf[e])
        n = footprint_cells(
            self.model, int(x), int(y), int(z), int(tilt), int(pan), int(zoom10),
            self.cfg.size[0], self.cfg.size[1], self.cfg.fov_deg, self.cfg.max_range,
            self.cfg.occlusion, self.obstacles[e], int(row[D.N_OBS]), buf,
        )  # fmt: skip
        return buf[:n].copy()

    def covered(self, e: int) -> np.ndarray:
        """Boolean (X, Y) map of covered cells of world ``e``."""
        return self.views[e] > 0

    def position(self, e: int) -> tuple[int, int, int]:
        r = self.ints[e]
        return int(r[D.PX]), int(r[D.PY]), int(r[D.PZ])

    def camera(self, e: int) -> tuple[int, int, float]:
        """(tilt degrees, pan degrees, zoom factor) of world ``e``."""
        r = self.ints[e]
        return int(r[D.TILT]), int(r[D.PAN]), r[D.ZOOM] / 10.0

    def battery(self, e: int) -> float:
        """Battery of world ``e`` normalized to [0, 1]."""
        return max(0.0, float(self.energy[e]) / self.capacity)

    def obstacle_list(self, e: int) -> np.ndarray:
        return self.obstacles[e, : int(self.ints[e, D.N_OBS])].copy()


__all__ = ["Scenario", "WorldBatch", "blocked_grid", "draw_scenario"]
