"""Which coverable cells of a site can be seen at all, and why the others cannot.

A coverable cell is *seeable* when some camera pose of some cell the UAV can reach from a
start sees it through the world's footprint model (occlusion included). Every other one has a
reason, checked in this order:

- ``hidden``: no free cell at all (reachable or not, no-fly zones ignored) sees it with any
  pose: a courtyard narrower than the footprint, ground hidden by buildings from every cell;
- ``no_fly``: only cells inside no-fly zones see it;
- ``unreachable``: cells outside no-fly zones see it, but none the UAV can reach from a start
  (enclosed by buildings or no-fly zones).

Poses tried: the paper model's largest square (zoom 2.0, tilt below 80: it contains every
other square, and the model has no occlusion), or for the frustum model every tilt and pan
step at zooms 0.5, 1.0 and 2.0. A camera cell is skipped once no unseen coverable cell is
left within its reach, so an open site costs little.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np

from pirl.config import grid
from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.world.footprint import (
    NO_GROUND,
    NO_VOXELS,
    PAPER,
    PAPER_MAX_HALF,
    CameraPose,
    Lens,
    footprint_cells,
    footprint_model,
    lens_of,
)
from pirl.world.grids import MapGrids
from pirl.world.site import Site, load_site

REASONS = ("hidden", "no_fly", "unreachable")
"""The reasons a coverable cell cannot be seen, in the order they are checked."""


@dataclass(frozen=True)
class Seeability:
    """What a site's check found (see the module docstring)."""

    coverable: int
    """Coverable cells of the site."""
    seeable: np.ndarray
    """(X, Y) coverable cells a reachable cell sees."""
    reason: np.ndarray
    """(X, Y) int8: -1 seeable or not coverable, else the index in :data:`REASONS`."""
    reachable: np.ndarray
    """(X, Y, Z) cells the UAV can reach from a start."""

    @property
    def counts(self) -> dict[str, int]:
        """Unseeable coverable cells per reason (every reason listed, zeros included)."""
        return {name: int((self.reason == k).sum()) for k, name in enumerate(REASONS)}


@numba.njit(cache=True)
def _reach(blocked, starts):
    sx, sy, sz = blocked.shape
    seen = np.zeros(blocked.shape, dtype=np.bool_)
    queue = np.empty((sx * sy * sz, 3), dtype=np.int64)
    head = tail = 0
    for k in range(starts.shape[0]):
        x, y, z = starts[k, 0], starts[k, 1], starts[k, 2]
        if not blocked[x, y, z] and not seen[x, y, z]:
            seen[x, y, z] = True
            queue[tail, 0], queue[tail, 1], queue[tail, 2] = x, y, z
            tail += 1
    moves = np.array(((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)))
    while head < tail:
        x, y, z = queue[head, 0], queue[head, 1], queue[head, 2]
        head += 1
        for m in range(6):
            i, j, k = x + moves[m, 0], y + moves[m, 1], z + moves[m, 2]
            inside = 0 <= i < sx and 0 <= j < sy and 0 <= k < sz
            if inside and not blocked[i, j, k] and not seen[i, j, k]:
                seen[i, j, k] = True
                queue[tail, 0], queue[tail, 1], queue[tail, 2] = i, j, k
                tail += 1
    return seen


@numba.njit(cache=True)
def _union_views(lens, sources, occluding, ground, target, poses, reach, out):
    """Mark in ``out`` the ``target`` cells some pose of some ``sources`` cell sees."""
    sx, sy, sz = sources.shape
    buf = np.empty((out.shape[0] * out.shape[1] + 1, 2), dtype=np.int64)
    empty = np.zeros((0, 4))
    left = np.zeros((sx, sy), dtype=np.int64)
    for i in range(sx):
        for j in range(sy):
            left[i, j] = 1 if target[i, j] and not out[i, j] else 0
    tried = np.zeros(sources.shape, dtype=np.bool_)
    # A sparse pass first: it sees most cells, so the full pass skips most camera cells.
    for stride in (5, 1):
        for x in range(0, sx, stride):
            for y in range(0, sy, stride):
                for z in range(sz):
                    if not sources[x, y, z] or tried[x, y, z]:
                        continue
                    tried[x, y, z] = True
                    if not _any_left(left, x, y, reach):
                        continue
                    for p in range(poses.shape[0]):
                        pose = CameraPose(x, y, z, poses[p, 0], poses[p, 1], poses[p, 2])
                        n = footprint_cells(lens, pose, empty, occluding, ground, buf)
                        for r in range(n):
                            i, j = buf[r, 0], buf[r, 1]
                            if left[i, j]:
                                left[i, j] = 0
                                out[i, j] = True


@numba.njit(cache=True)
def _any_left(left, x, y, reach):
    """Whether an unseen cell lies within ``reach`` of (x, y)."""
    sx, sy = left.shape
    for i in range(max(0, x - reach), min(sx, x + reach + 1)):
        for j in range(max(0, y - reach), min(sy, y + reach + 1)):
            if left[i, j]:
                return True
    return False


def _poses(model: int) -> np.ndarray:
    if model == PAPER:
        return np.array([[0, 0, 20]], dtype=np.int64)
    return np.array(
        [[t, p, z] for t in grid.tilt_steps() for p in grid.pan_steps() for z in (5, 10, 20)],
        dtype=np.int64,
    )


def analyse(site: Site, lens: Lens) -> Seeability:
    """Seeable cells and the reason for each unseeable one (module docstring)."""
    target = site.coverable
    reach = PAPER_MAX_HALF if lens.model == PAPER else int(np.ceil(lens.max_range)) + 2
    poses = _poses(lens.model)
    occluding = site.occluding if lens.occlusion else NO_VOXELS
    ground = site_ground(site) if lens.occlusion and site.has_terrain else NO_GROUND
    reachable = _reach(site.blocked, site.starts)
    buildings = site.occluding
    sets = []
    for sources in (reachable, ~site.blocked, ~buildings):
        out = np.zeros(target.shape, dtype=np.bool_)
        _union_views(lens, sources, occluding, ground, target, poses, reach, out)
        sets.append(out & target)
    seen_reach, seen_allowed, seen_any = sets
    reason = np.full(target.shape, -1, dtype=np.int8)
    unseen = target & ~seen_reach
    reason[unseen & ~seen_any] = 0
    reason[unseen & seen_any & ~seen_allowed] = 1
    reason[unseen & seen_allowed] = 2
    return Seeability(int(target.sum()), seen_reach, reason, reachable)


def lens_for(cfg: VCPPConfig) -> Lens:
    """The footprint lens of a world config."""
    model = footprint_model(cfg.footprint)
    return lens_of(model, cfg.size, cfg.fov_deg, cfg.max_range, cfg.occlusion)


@functools.lru_cache(maxsize=16)
def _grids(site: Site, lens: Lens) -> MapGrids:
    seen = analyse(site, lens)
    if not seen.seeable.any():
        raise ConfigError(
            f"site {site.name}: no coverable cell can be seen ({_why(seen)}); run pirl site "
            "check for a picture"
        )
    # Starts the UAV cannot leave towards any view are kept: the episode still starts there.
    return MapGrids(
        site.name, site.blocked, site.occluding, seen.seeable, seen.coverable, site.starts,
        site_ground(site),
    )  # fmt: skip


def site_ground(site: Site) -> np.ndarray | None:
    """The site's terrain in levels (what the kernels take), None on flat ground."""
    if not site.has_terrain:
        return None
    return np.ascontiguousarray(site.terrain / site.level_height_m)


def _why(seen: Seeability) -> str:
    return ", ".join(f"{k} {v:,}" for k, v in seen.counts.items() if v) or "nothing coverable"


def site_grids(cfg: VCPPConfig) -> MapGrids:
    """The map grids of ``cfg.site`` under ``cfg``'s camera (cached while the site's files
    are unchanged)."""
    site = load_site(cfg.site)
    if site.size != tuple(cfg.size):
        raise ConfigError(
            f"env.size={list(cfg.size)} but site {site.name} is {list(site.size)}: "
            "give the site with --site (it sets the size)"
        )
    return _grids(site, lens_for(cfg))


def with_site(cfg: VCPPConfig, path: str) -> VCPPConfig:
    """``cfg`` on the site at ``path``: its size, and battery and steps scaled with its
    seeable cells. Refused in one line when the site cannot be used."""
    from pirl.world.site import site_folder

    folder = str(site_folder(path).resolve())
    site = load_site(folder)
    probe = cfg.replace(site=folder, size=site.size, ground_cells=0)
    grids = _grids(site, lens_for(probe))
    return probe.replace(ground_cells=int(grids.coverable.sum()))


__all__ = ["REASONS", "Seeability", "analyse", "lens_for", "site_grids", "with_site"]
