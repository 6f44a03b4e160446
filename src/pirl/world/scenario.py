"""Scenarios: what a seed fixes about an episode, and how it is drawn.

:func:`draw_scenario` draws a world's obstacle spheres (or takes a site's grids), a free start
cell, the wind stream's seed and, when asked, a starting camera pose and a box of ground left
to cover, all from one ``numpy.random.Generator``; a fleet's teammates start at the free cells
nearest to UAV 1's. :class:`pirl.world.state.WorldBatch` loads a drawn :class:`Scenario` into
one of its worlds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numba
import numpy as np

from pirl.config import grid
from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.world import dynamics as D
from pirl.world.grids import MapGrids

_MAX_SCENARIO_TRIES = 200


@dataclass(frozen=True)
class Scenario:
    """What a seed fixes about an episode: the map (obstacle spheres, or a site's grids), the
    start cell and the wind stream."""

    obstacles: np.ndarray  # (n, 4): cx, cy, cz, radius in cell units
    start: tuple[int, int, int]
    wind_seed: int
    camera: tuple[int, int, int] | None = None
    """Starting (tilt, pan, zoom tenths) if drawn (``start_camera``); else the config's."""
    grids: MapGrids | None = None
    """The site's map when the world is a site (then ``obstacles`` is empty)."""
    work: tuple[int, int, int, int] | None = None
    """Cells (x0, y0, x1, y1), inclusive, of the only ground left to cover at the start if
    drawn (``start_surveyed``); every other ground cell starts covered. None: all of it."""
    fleet: tuple[tuple[int, int, int], ...] = ()
    """A fleet's teammates (UAVs 2..K): their start cells, distinct and free."""
    fleet_winds: tuple[int, ...] = ()
    """A fleet's teammates: the seeds of their wind streams."""

    def starts(self) -> tuple[tuple[int, int, int], ...]:
        """Every UAV's start cell, UAV 1's first."""
        return (tuple(int(v) for v in self.start), *self.fleet)  # type: ignore[return-value]

    def winds(self) -> tuple[int, ...]:
        """Every UAV's wind seed, UAV 1's first."""
        return (int(self.wind_seed), *self.fleet_winds)


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


def fleet_starts(blocked: np.ndarray, start: tuple[int, int, int], uavs: int) -> list:
    """The start cells of a fleet's teammates: the ``uavs - 1`` free cells nearest to UAV 1's
    ``start`` by moves (breadth-first over free cells, in the order of the move table), as a
    fleet takes off from one launch site. One line when fewer free cells can be reached."""
    need = uavs - 1
    found: list[tuple[int, int, int]] = []
    seen = {start}
    queue = [start]
    head = 0
    size = blocked.shape
    while head < len(queue) and len(found) < need:
        x, y, z = queue[head]
        head += 1
        for dx, dy, dz in D.MOVE_DELTAS:
            c = (x + dx, y + dy, z + dz)
            if c in seen or not all(0 <= v < n for v, n in zip(c, size, strict=True)):
                continue
            seen.add(c)
            if not blocked[c]:
                queue.append(c)
                found.append(c)
                if len(found) == need:
                    break
    if len(found) < need:
        raise ConfigError(
            f"env.uavs={uavs}: only {len(found) + 1} free cells can be reached from the start "
            f"{start}; use fewer UAVs"
        )
    return found


def draw_scenario(cfg: VCPPConfig, rng: np.random.Generator) -> Scenario:
    """Draw obstacles, a free start cell and the wind seed from ``rng``.

    Obstacle layouts that leave no free cell or no coverable ground are drawn again. On a site
    (``cfg.site``) the map is the site's and only the start (from its start cells), the wind
    and the camera are drawn. A fleet's teammates (``cfg.uavs`` > 1) start at the free cells
    nearest to the start (:func:`fleet_starts`), each with a wind seed drawn after everything
    else, so a fleet's scenario holds the one-UAV scenario of the same seed.
    """
    scenario = _draw_one(cfg, rng)
    if cfg.uavs == 1:
        return scenario
    if scenario.grids is not None:
        blocked = scenario.grids.blocked
    else:
        blocked = blocked_grid(cfg.size, scenario.obstacles)
    fleet = fleet_starts(blocked, scenario.starts()[0], cfg.uavs)
    winds = tuple(int(rng.integers(0, 2**63 - 1)) for _ in fleet)
    return dataclasses.replace(scenario, fleet=tuple(fleet), fleet_winds=winds)


def _draw_one(cfg: VCPPConfig, rng: np.random.Generator) -> Scenario:
    if cfg.site:
        from pirl.world.seeable import site_grids

        grids = site_grids(cfg)
        start = grids.starts[int(rng.integers(len(grids.starts)))]
        wind_seed = int(rng.integers(0, 2**63 - 1))
        start_cell = (int(start[0]), int(start[1]), int(start[2]))
        camera = _draw_camera(cfg, rng)
        return Scenario(
            np.zeros((0, 4)), start_cell, wind_seed, camera, grids, _draw_work(cfg, rng)
        )
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
            camera = _draw_camera(cfg, rng)
            start_cell = (int(start[0]), int(start[1]), int(start[2]))
            return Scenario(obstacles, start_cell, wind_seed, camera, None, _draw_work(cfg, rng))
    raise ConfigError(
        f"size={cfg.size}: could not place {lo}-{hi} obstacles of radius "
        f"{cfg.radius_min}-{cfg.radius_max} and keep a free cell and coverable ground; "
        "use a larger world or smaller/fewer obstacles"
    )


def _draw_work(cfg: VCPPConfig, rng: np.random.Generator) -> tuple[int, int, int, int] | None:
    """With probability ``start_surveyed``, a box of ground left to cover (each side 2 cells to
    half the world's); drawn after everything else and only when asked, so other scenarios
    stay the same."""
    if cfg.start_surveyed <= 0 or rng.random() >= cfg.start_surveyed:
        return None
    sx, sy, _ = cfg.size
    wx = int(rng.integers(2, max(2, sx // 2) + 1))
    wy = int(rng.integers(2, max(2, sy // 2) + 1))
    x0 = int(rng.integers(0, sx - wx + 1))
    y0 = int(rng.integers(0, sy - wy + 1))
    return (x0, y0, x0 + wx - 1, y0 + wy - 1)


def _draw_camera(cfg: VCPPConfig, rng: np.random.Generator) -> tuple[int, int, int] | None:
    # Drawn last, and only when asked: fixed-start scenarios stay the same.
    if cfg.start_camera == "random" or (cfg.start_camera == "mixed" and rng.random() < 0.5):
        return (
            int(rng.choice(grid.tilt_steps())),
            int(rng.choice(grid.pan_steps())),
            int(rng.integers(grid.ZOOM_MIN10, grid.ZOOM_MAX10 + 1)),
        )
    return None


__all__ = ["MapGrids", "Scenario", "blocked_grid", "draw_scenario", "fleet_starts"]
