"""A batch of grid worlds: the named state arrays and the fixed parameters.

:class:`WorldBatch` owns the numpy arrays of N worlds of one size, grouped in one
:class:`WorldArrays`, and the settings the rules read, in one :class:`Params`; the compiled
rules of :mod:`pirl.world.dynamics` take both (stepped by :class:`pirl.env.core.EnvCore`, whose
one fused kernel also weighs rewards and builds observations). Per-world scalars are numpy
records (:data:`STATUS_DTYPE`, :data:`FLAGS_DTYPE`) so that both numba and numpy read them by
name: ``w.status[e]["covered"]`` in a kernel, ``world.status["covered"]`` for every world at once.
Scenario generation (obstacles, start cell, wind stream; :mod:`pirl.world.scenario`) draws from
a ``numpy.random.Generator`` per world, so a world reset with seed s is the same whether it lives
alone or in a batch.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.world import dynamics as D
from pirl.world.footprint import (
    CameraPose,
    buffer_rows,
    footprint_cells,
    footprint_model,
    lens_of,
    max_footprint_cells,
)
from pirl.world.memory import check_memory
from pirl.world.scenario import Scenario, blocked_grid, draw_scenario

STATUS_DTYPE = np.dtype(
    [
        (name, np.int64)
        for name in (
            "x", "y", "z", "tilt", "pan", "zoom10", "steps", "covered", "coverable",
            "redundant_cells", "multi_cells", "cell_views", "collisions", "redundant_steps",
            "camera_actions", "n_obstacles", "footprint_sum", "wind_pushes",
        )
    ],
    align=True,
)  # fmt: skip
"""One world's integer state: cell (x, y, z), camera (tilt and pan degrees, zoom in tenths)
and the episode's counters: steps, covered and coverable ground cells, cells seen by a
redundant step, cells seen twice or more, coverable-cell views, collisions, redundant steps,
camera actions, obstacles, summed footprint sizes and wind pushes."""

FLAGS_DTYPE = np.dtype(
    [
        (name, np.int64)
        for name in (
            "collision", "redundant", "idle", "terminated", "truncated", "wind", "new_cells"
        )
    ],
    align=True,
)  # fmt: skip
"""What one world's last step did (0/1 events, and the count of new cells)."""

STATE_ARRAYS = (
    "status", "energy", "rng", "blocked", "coverable", "views", "redmask", "visits", "blk_todo",
    "blk_total", "obstacles", "terms", "flags", "occluding", "coverable_all", "progress",
    "guarded", "left", "credit", "seen_now", "yields", "clock", "seen_by", "near", "ground",
)  # fmt: skip
"""The :class:`WorldArrays` fields that are state (what a checkpoint keeps); the others are
lookups and scratch space derived from the config."""


_NO_TEAMMATES = np.zeros((0, 4), dtype=np.float64)
_NO_TEAMMATES.flags.writeable = False  # shared by every single-UAV view


def copy_records(records: np.ndarray) -> np.ndarray:
    """A read-only copy of a 1-D record array, made as bytes: numpy copies records field by
    field, ten times slower, and every step's info snapshot copies them."""
    return np.frombuffer(records.tobytes(), dtype=records.dtype)


def _has_ground(cfg: VCPPConfig) -> bool:
    """Whether ``cfg``'s world is a site with a terrain model."""
    if not cfg.site:
        return False
    from pirl.world.site import load_site

    return load_site(cfg.site).has_terrain


class WorldArrays(NamedTuple):
    """The arrays of N worlds of one size holding K UAVs each, as the kernels take them.

    The map (``blocked``, ``occluding``, ``coverable``, ``obstacles``) and the coverage
    bookkeeping (``views``, ``redmask``, ``blk_*``) have one row per world; each UAV's own
    state (``status``, ``energy``, ``rng``, ``visits``, ...) has one row per slot, the
    (world, UAV) pair ``world * K + uav`` (:func:`pirl.world.dynamics.world_of`). With one UAV
    (the paper's task) slots and worlds coincide.
    """

    status: np.ndarray
    """(N*K,) records of :data:`STATUS_DTYPE`: pose, camera and counters. ``status[e]["x"]``
    reads and writes the same in numba and in plain Python (a record is a view)."""
    energy: np.ndarray
    """(N*K,) battery energy units left."""
    rng: np.ndarray
    """(N*K,) uint64 state of each UAV's wind stream (splitmix64)."""
    blocked: np.ndarray
    """(N, X, Y, Z) cells inside an obstacle."""
    coverable: np.ndarray
    """(N, X, Y) ground cells that count for coverage."""
    views: np.ndarray
    """(N, X, Y) how many steps saw each ground cell."""
    redmask: np.ndarray
    """(N, X, Y) cells seen by a redundant step (C_redundant of the RVC metric)."""
    visits: np.ndarray
    """(N*K, X, Y, Z) each UAV's visits of each cell this episode."""
    blk_todo: np.ndarray
    """(N, G, G) coverable cells of each coarse block not yet covered."""
    blk_total: np.ndarray
    """(N, G, G) coverable cells of each coarse block."""
    obstacles: np.ndarray
    """(N, max_obstacles, 4) spheres (cx, cy, cz, radius); ``status["n_obstacles"]`` are used."""
    occluding: np.ndarray
    """(N, X, Y, Z) cells that hide the ground behind them where a world has no spheres (a
    site's buildings); equal to ``blocked`` in a sphere world, whose spheres occlude exactly."""
    ground: np.ndarray
    """(N, X, Y) a site's terrain in levels (``MapGrids.ground``): a move over it costs its
    climb or descent, and a ridge hides what lies behind it; (N, 0, 0) on flat ground, where
    no rule reads it."""
    coverable_all: np.ndarray
    """(N,) coverable cells of the world's site, seeable or not (= the coverable count of a
    sphere world)."""
    progress: np.ndarray
    """(N*K,) the UAV's step at which its view last added coverage (0 at reset): the
    observation's stall scalar is ``steps - progress``."""
    guarded: np.ndarray
    """(N*K,) steps of this episode whose action the stall guard chose (``env.stall_guard``)."""
    left: np.ndarray
    """(N*K,) whether the UAV has left the episode (a fleet's: its battery spent, or the
    fleet's coverage complete) while teammates fly on."""
    credit: np.ndarray
    """(N*K,) ground cells credited to the UAV: first seen by it (the start's view included)."""
    seen_now: np.ndarray
    """(N*K,) ground cells in the UAV's footprint now (its last view)."""
    yields: np.ndarray
    """(N*K,) moves that held because a teammate took the cell earlier in the same step."""
    clock: np.ndarray
    """(N,) steps of the world's episode (whose UAV moves first: ``clock mod K``)."""
    seen_by: np.ndarray
    """(N, X, Y) a fleet's: bit u set when UAV u has seen the ground cell (overlap between
    UAVs); untouched with one UAV."""
    near: np.ndarray
    """(N,) a fleet's near misses: pairs of UAVs in face-adjacent cells, summed over steps."""
    terms: np.ndarray
    """(N*K, 8) raw reward terms of the last step, in the order of ``REWARD_TERMS``."""
    flags: np.ndarray
    """(N*K,) records of :data:`FLAGS_DTYPE`: the last step's events."""
    block_x: np.ndarray
    """(X,) coarse block of each x (a lookup, the same for every world)."""
    block_y: np.ndarray
    """(Y,) coarse block of each y."""
    buf: np.ndarray
    """(N*K, rows, 2) scratch rows for each UAV's footprint."""
    path: np.ndarray
    """(N*K, 2, X*Y) scratch of the observation's path search: its queue, and each cell's
    moves * 4 + first move (-1 not reached)."""


class Params(NamedTuple):
    """The settings the rules read, fixed for a batch's lifetime (typed as the kernels expect).

    Its first six fields are those of :class:`~pirl.world.footprint.Lens`, so the footprint
    functions take a Params as their lens: numba's parallel loops cannot take a tuple nested
    in a tuple, so the lens is not a field of its own.
    """

    model: int
    """Footprint model, :data:`~pirl.world.footprint.PAPER` or ``FRUSTUM``."""
    size_x: int
    """Cells along x."""
    size_y: int
    """Cells along y."""
    fov_deg: float
    """Horizontal field of view at zoom 1.0, degrees (frustum model)."""
    max_range: float
    """Ground points farther than this many cells are cut to it (frustum model)."""
    occlusion: bool
    """Whether obstacle spheres hide the ground behind them (frustum model)."""
    size_z: int
    """Flight levels."""
    step_limit: int
    """Steps before an episode is truncated (scaled by alpha)."""
    capacity: float
    """Battery energy units when full (scaled by alpha)."""
    wind_prob: float
    """Probability of a gust after each action."""
    energy_move: float
    """Energy of an x/y move (also the unit of the battery reward term)."""
    energy_climb: float
    """Energy of a z+ move."""
    energy_descend: float
    """Energy of a z- move."""
    energy_camera: float
    """Energy of a camera action."""
    energy_hover: float
    """Energy spent every step on top of the action's."""
    max_footprint: float
    """Cells of the largest possible footprint (the unit of the coverage reward term)."""
    stall_guard: int
    """Steps without new coverage after which the mask leaves only the way to work (0: off)."""


@numba.njit(cache=True)
def _reset_bookkeeping(w, p, g, work):
    """Zero world g's bookkeeping and its UAVs', count its coverable cells and take each UAV's
    first view (UAV 1's first). With ``work`` = (x0, y0, x1, y1) (x0 >= 0) the ground outside
    that box starts covered."""
    w.views[g] = 0
    w.redmask[g] = False
    w.blk_todo[g] = 0
    w.blk_total[g] = 0
    w.clock[g] = 0
    w.near[g] = 0
    w.seen_by[g] = 0
    n = 0
    covered = 0
    x0, y0, x1, y1 = work
    for i in range(w.coverable.shape[1]):
        for j in range(w.coverable.shape[2]):
            if w.coverable[g, i, j]:
                n += 1
                w.blk_total[g, w.block_x[i], w.block_y[j]] += 1
                if x0 >= 0 and not (x0 <= i <= x1 and y0 <= j <= y1):
                    w.views[g, i, j] = 1
                    covered += 1
                else:
                    w.blk_todo[g, w.block_x[i], w.block_y[j]] += 1
    k = D.fleet_size(w)
    for e in range(g * k, g * k + k):
        w.visits[e] = 0
        w.progress[e] = 0
        w.guarded[e] = 0
        w.left[e] = False
        w.credit[e] = 0
        w.yields[e] = 0
        st = w.status[e]
        st["coverable"] = n
        st["covered"] = covered
        w.visits[e, st["x"], st["y"], st["z"]] = 1
    # The cameras see before the first action; these first views earn no reward.
    for e in range(g * k, g * k + k):
        D.observe(w, p, e, False)


class WorldBatch:
    """N grid worlds of one configuration (their state; :class:`pirl.env.core.EnvCore` steps them).

    ``parallel`` spreads the worlds over numba threads; the results are the same either way.
    It is off by default: on a small shared machine (2 cores, with training and an LLM busy) a
    parallel step waits for its slowest thread and can be far slower than one thread.

    The arrays are :attr:`arrays` (a :class:`WorldArrays`; each field is also an attribute,
    e.g. ``world.status``) and the settings :attr:`params` (a :class:`Params`).
    """

    def __init__(self, cfg: VCPPConfig, num: int, parallel: bool | None = None) -> None:
        if num < 1:
            raise ConfigError(f"num_envs={num}: need at least 1 world")
        check_memory(cfg, num)
        self.cfg = cfg
        self.num = num
        self.uavs = k = int(cfg.uavs)
        self.slots = slots = num * k
        sx, sy, sz = cfg.size
        g = cfg.obs_global
        self.model = footprint_model(cfg.footprint)
        self.capacity = float(cfg.capacity)
        self.step_limit = int(cfg.step_limit)
        self.max_obstacles = max(1, cfg.obstacle_count_range[1])
        self.max_footprint = max_footprint_cells(self.model, sz, cfg.fov_deg, cfg.max_range)
        self.parallel = bool(parallel) and num > 1
        self.lens = lens_of(self.model, cfg.size, cfg.fov_deg, cfg.max_range, cfg.occlusion)
        self.arrays = WorldArrays(
            status=np.zeros(slots, dtype=STATUS_DTYPE),
            energy=np.zeros(slots, dtype=np.float64),
            rng=np.zeros(slots, dtype=np.uint64),
            blocked=np.zeros((num, sx, sy, sz), dtype=np.bool_),
            coverable=np.zeros((num, sx, sy), dtype=np.bool_),
            views=np.zeros((num, sx, sy), dtype=np.int32),
            redmask=np.zeros((num, sx, sy), dtype=np.bool_),
            visits=np.zeros((slots, sx, sy, sz), dtype=np.int32),
            blk_todo=np.zeros((num, g, g), dtype=np.int32),
            blk_total=np.zeros((num, g, g), dtype=np.int32),
            obstacles=np.zeros((num, self.max_obstacles, 4), dtype=np.float64),
            occluding=np.zeros((num, sx, sy, sz), dtype=np.bool_),
            ground=np.zeros((num, sx, sy) if _has_ground(cfg) else (num, 0, 0)),
            coverable_all=np.zeros(num, dtype=np.int64),
            progress=np.zeros(slots, dtype=np.int64),
            guarded=np.zeros(slots, dtype=np.int64),
            left=np.zeros(slots, dtype=np.bool_),
            credit=np.zeros(slots, dtype=np.int64),
            seen_now=np.zeros(slots, dtype=np.int64),
            yields=np.zeros(slots, dtype=np.int64),
            clock=np.zeros(num, dtype=np.int64),
            seen_by=np.zeros((num, sx, sy) if k > 1 else (num, 1, 1), dtype=np.int64),
            near=np.zeros(num, dtype=np.int64),
            terms=np.zeros((slots, D.N_TERMS), dtype=np.float64),
            flags=np.zeros(slots, dtype=FLAGS_DTYPE),
            block_x=(np.arange(sx) * g // sx).astype(np.int64),
            block_y=(np.arange(sy) * g // sy).astype(np.int64),
            buf=np.zeros((slots, buffer_rows(self.model, cfg.max_range), 2), dtype=np.int64),
            path=np.zeros((slots, 2, sx * sy), dtype=np.int32),
        )
        self.arrays.path[:, 1] = -1  # the path search's "not reached" (it keeps it so)
        self.params = Params(
            *self.lens,
            size_z=int(sz),
            step_limit=self.step_limit,
            capacity=self.capacity,
            wind_prob=float(cfg.wind_prob),
            energy_move=float(cfg.energy_move),
            energy_climb=float(cfg.energy_climb),
            energy_descend=float(cfg.energy_descend),
            energy_camera=float(cfg.energy_camera),
            energy_hover=float(cfg.energy_hover),
            max_footprint=float(self.max_footprint),
            stall_guard=int(cfg.stall_guard),
        )
        # Each array also by name (world.status, world.views, ...): the same objects, listed
        # once, in WorldArrays; plain attributes, as a step reads several of them.
        vars(self).update(self.arrays._asdict())

    def state_dict(self) -> dict[str, np.ndarray]:
        """Copies of every state array (:data:`STATE_ARRAYS`), enough to continue exactly."""
        return {name: getattr(self.arrays, name).copy() for name in STATE_ARRAYS}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Put a :meth:`state_dict` back (into this batch's own arrays, which stay in place)."""
        # Arrays added after a checkpoint's version start at their reset values.
        later = {"progress", "guarded", "left", "credit", "seen_now", "yields", "clock"}
        later |= {"seen_by", "near", "ground"}
        missing = set(STATE_ARRAYS) - set(state) - later
        if missing:
            raise ValueError(f"world state lacks {sorted(missing)}")
        for name in STATE_ARRAYS:
            if name in state:
                getattr(self.arrays, name)[...] = state[name]
        if "progress" not in state:
            # A checkpoint from before the stall scalar: only obs_stall reads it, and no such
            # run had it on.
            self.arrays.progress[...] = self.arrays.status["steps"]
        if "guarded" not in state:  # nor the stall guard
            self.arrays.guarded[...] = 0

    # -- reset ----------------------------------------------------------------------------
    def reset_world(self, e: int, rng: np.random.Generator) -> Scenario:
        """Start a new episode in world ``e`` from a scenario drawn with ``rng``."""
        scenario = draw_scenario(self.cfg, rng)
        self.load_scenario(e, scenario)
        return scenario

    def load_scenario(self, e: int, scenario: Scenario) -> None:
        """Start a new episode in world ``e`` (every UAV of it) on a given scenario."""
        cfg = self.cfg
        n = len(scenario.obstacles)
        if n > self.max_obstacles:
            raise ConfigError(f"scenario has {n} obstacles; this world holds {self.max_obstacles}")
        grids = scenario.grids
        if grids is not None:
            if grids.blocked.shape != tuple(cfg.size):
                raise ConfigError(
                    f"site {grids.name} is {grids.blocked.shape}, this world {tuple(cfg.size)}"
                )
            blocked = grids.blocked
        else:
            blocked = blocked_grid(cfg.size, scenario.obstacles)
        start = tuple(int(v) for v in scenario.start)
        if len(start) != 3 or not all(0 <= v < s for v, s in zip(start, cfg.size, strict=True)):
            raise ConfigError(f"scenario start {scenario.start} lies outside the grid {cfg.size}")
        if blocked[start]:
            raise ConfigError(f"scenario start {start} lies inside an obstacle")
        starts = scenario.starts()
        if len(starts) != self.uavs:
            raise ConfigError(
                f"scenario has {len(starts)} UAV start(s); this world flies {self.uavs}"
            )
        for cell in starts[1:]:
            if not all(0 <= v < n for v, n in zip(cell, cfg.size, strict=True)) or blocked[cell]:
                raise ConfigError(f"scenario start {cell} lies outside the grid or in an obstacle")
        if len(set(starts)) != len(starts):
            raise ConfigError(f"scenario starts {starts}: two UAVs in one cell")
        w = self.arrays
        w.obstacles[e] = 0.0
        w.obstacles[e, :n] = scenario.obstacles
        w.blocked[e] = blocked
        if w.ground.shape[1]:
            w.ground[e] = grids.ground if grids is not None and grids.ground is not None else 0.0
        if grids is not None:
            w.occluding[e] = grids.occluding
            w.coverable[e] = grids.coverable
            w.coverable_all[e] = grids.coverable_all
        else:
            w.occluding[e] = blocked
            w.coverable[e] = ~w.blocked[e, :, :, 0]
            w.coverable_all[e] = int(w.coverable[e].sum())
        camera = scenario.camera or (cfg.start_tilt, cfg.start_pan, cfg.start_zoom10)
        first = e * self.uavs
        for u, (cell, wind) in enumerate(zip(starts, scenario.winds(), strict=True)):
            s = first + u
            w.status[s] = 0
            st = w.status[s : s + 1]  # a view: numpy writes a record's fields through it
            st["x"], st["y"], st["z"] = cell
            st["tilt"], st["pan"], st["zoom10"] = camera
            st["n_obstacles"] = n
            w.energy[s] = self.capacity
            w.rng[s] = np.uint64(wind)
        work = scenario.work if scenario.work is not None else (-1, -1, -1, -1)
        _reset_bookkeeping(w, self.params, e, tuple(int(v) for v in work))
        w.terms[first : first + self.uavs] = 0.0
        w.flags[first : first + self.uavs] = 0

    # -- queries: ``e`` is a slot (with one UAV per world, the world) ---------------------
    def world_of(self, e: int) -> int:
        """The world of slot ``e`` (the row of the map and coverage arrays)."""
        return e // self.uavs

    def footprint(
        self,
        e: int,
        pose: tuple[int, int, int] | None = None,
        camera: tuple[int, int, int] | None = None,
    ) -> np.ndarray:
        """Ground cells (k, 2) seen by world ``e`` now, or from another pose/camera.

        ``camera`` is (tilt degrees, pan degrees, zoom tenths).
        """
        x, y, z = pose if pose is not None else self.position(e)
        tilt, pan, zoom10 = camera if camera is not None else self.camera_setting(e)
        buf = np.empty_like(self.buf[e])
        at = CameraPose(int(x), int(y), int(z), int(tilt), int(pan), int(zoom10))
        g = self.world_of(e)
        n = footprint_cells(
            self.lens, at, self.obstacle_list(e), self.occluding[g], self.ground[g], buf
        )
        return buf[:n].copy()

    def covered(self, e: int) -> np.ndarray:
        """Boolean (X, Y) map of covered cells of slot ``e``'s world (the fleet's coverage)."""
        return self.views[self.world_of(e)] > 0

    def position(self, e: int) -> tuple[int, int, int]:
        """Cell (x, y, z) of world ``e``."""
        r = self.status[e]
        return int(r["x"]), int(r["y"]), int(r["z"])

    def positions(self, worlds: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k, 3) int64 cells of ``worlds`` (all by default)."""
        st = self.status[worlds]
        return np.stack([st["x"], st["y"], st["z"]], axis=-1)

    def camera(self, e: int) -> tuple[int, int, float]:
        """(tilt degrees, pan degrees, zoom factor) of world ``e``."""
        tilt, pan, zoom10 = self.camera_setting(e)
        return tilt, pan, zoom10 / 10.0

    def camera_setting(self, e: int) -> tuple[int, int, int]:
        """(tilt degrees, pan degrees, zoom tenths) of world ``e``: the integers the rules use."""
        r = self.status[e]
        return int(r["tilt"]), int(r["pan"]), int(r["zoom10"])

    def battery(self, e: int) -> float:
        """Battery of world ``e`` normalized to [0, 1]."""
        return max(0.0, float(self.energy[e]) / self.capacity)

    def teammates(self, e: int) -> np.ndarray:
        """(k, 4) float64 rows (x, y, z, battery in [0, 1]) of the UAVs flying beside slot
        ``e`` in its world (those that have not left), in slot order; (0, 4) for one UAV."""
        k = self.uavs
        if k == 1:  # every single-UAV view asks, at every planner step: nothing to gather
            return _NO_TEAMMATES
        first = self.world_of(e) * k
        rows = [s for s in range(first, first + k) if s != e and not self.left[s]]
        out = np.zeros((len(rows), 4), dtype=np.float64)
        for i, s in enumerate(rows):
            out[i, :3] = self.position(s)
            out[i, 3] = self.battery(s)
        return out

    def rank(self, e: int) -> int:
        """How many of :meth:`teammates` of slot ``e`` come before it in slot order."""
        if self.uavs == 1:
            return 0
        first = self.world_of(e) * self.uavs
        return int(np.count_nonzero(~self.left[first:e]))

    def obstacle_list(self, e: int) -> np.ndarray:
        """Obstacle spheres (n, 4) of world ``e``: rows (cx, cy, cz, radius)."""
        return self.obstacles[self.world_of(e), : int(self.status[e]["n_obstacles"])].copy()


__all__ = [
    "FLAGS_DTYPE",
    "STATE_ARRAYS",
    "STATUS_DTYPE",
    "Params",
    "WorldArrays",
    "WorldBatch",
    "copy_records",
]
