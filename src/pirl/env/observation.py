"""The observation: a fixed-size vector whatever the world size.

Layout (W = ``obs_window``, G = ``obs_global``; all values in [0, 1]):

====================  ===========  ==========================================================
slice                 shape        meaning
====================  ===========  ==========================================================
``[0, W*W)``          (W, W)       local window centred on the UAV, x rows / y columns:
                                   1 = coverable ground cell not yet covered
``[W*W, 2*W*W)``      (W, W)       local window: 1 = blocked at the UAV's altitude, or outside
                                   the grid
``[2*W*W, +G*G)``     (G, G)       global summary: share of each block's coverable cells that
                                   are still uncovered (0 for a block with none)
next 11               scalars      x/(X-1), y/(Y-1), z/(Z-1), tilt/90, (pan+90)/180,
                                   (zoom-0.5)/1.5, battery, coverage (VCR so far),
                                   steps left / step limit, blocked above, blocked below
next W*W (obs_visits) (W, W)       local window: visits of each cell at the UAV's altitude
                                   this episode, min(v, C) / C (C = obs_visits_cap, 3)
next 1 (obs_stall)    scalar       steps since coverage last grew, min(s, 32) / 32
next 3 (obs_target)   scalars      to the nearest coverable cell not yet covered (ground
                                   plane): (dx/d + 1)/2, (dy/d + 1)/2, min(d, 16)/16; 0.5,
                                   0.5, 0 when none is left or the UAV is above one. With
                                   obs_target_path: the nearest such cell by moves at the
                                   UAV's altitude around blocked cells, (dx + 1)/2 and
                                   (dy + 1)/2 of the path's first move and min(moves, 16)/16
                                   (the straight line when none is reachable at that altitude)
====================  ===========  ==========================================================

next 6*M (obs_teammates = M)   the M teammates nearest to the UAV (fleets), nearest first,
                                   6 values each: 1 (present), (dx/(X-1) + 1)/2,
                                   (dy/(Y-1) + 1)/2, (dz/(Z-1) + 1)/2, cells in its
                                   footprint now / largest footprint, battery; zeros where
                                   fewer teammates fly (or none: one UAV)

The optional blocks are off by default (the paper's observation: 317 values).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pirl.config.world import VCPPConfig
from pirl.world.dynamics import BATCH_KERNEL, fleet_size, path_to_work, world_of

N_SCALARS = 11
N_TARGET = 3
N_TEAMMATE = 6  # values per teammate in the obs_teammates block
STALL_RANGE = 32.0  # steps: the stall scalar saturates here
TARGET_RANGE = 16.0  # cells: the distance feature saturates here, whatever the world size
# Bits of ObsLayout.extras: which optional blocks the observation has.
EXTRA_VISITS, EXTRA_TARGET, EXTRA_PATH, EXTRA_STALL = 1, 2, 4, 8


class ObsLayout(NamedTuple):
    """What the observation holds, as the kernels take it."""

    window: int
    """Side W of the local windows (odd)."""
    extras: int
    """Bits ``EXTRA_*`` of the optional blocks present."""
    visits_cap: int
    """Visit count at which the visits window saturates."""
    teammates: int
    """Teammates in the observation (``obs_teammates``; 0: no block)."""


def obs_size(
    window: int,
    global_side: int,
    visits: bool = False,
    target: bool = False,
    stall: bool = False,
    teammates: int = 0,
) -> int:
    """Length of the observation vector."""
    n = 2 * window * window + global_side * global_side + N_SCALARS
    n += (window * window if visits else 0) + (1 if stall else 0)
    return n + (N_TARGET if target else 0) + N_TEAMMATE * teammates


def obs_size_for(cfg: VCPPConfig) -> int:
    """Length of the observation vector of an environment config."""
    return obs_size(
        cfg.obs_window,
        cfg.obs_global,
        cfg.obs_visits,
        cfg.obs_target,
        cfg.obs_stall,
        cfg.obs_teammates,
    )


def obs_layout(cfg: VCPPConfig) -> ObsLayout:
    """The :class:`ObsLayout` of an environment config, for the observation kernels."""
    extras = (
        (EXTRA_VISITS if cfg.obs_visits else 0)
        | (EXTRA_TARGET if cfg.obs_target else 0)
        | (EXTRA_PATH if cfg.obs_target_path else 0)
        | (EXTRA_STALL if cfg.obs_stall else 0)
    )
    return ObsLayout(int(cfg.obs_window), extras, int(cfg.obs_visits_cap), int(cfg.obs_teammates))


@numba.njit(cache=True)
def nearest_work(coverable, views, x, y):
    """(d2, i, j) of the coverable cell not yet covered nearest to (x, y) (squared distance;
    on a tie the smallest (i, j)), or d2 = -1 when none is left. Searched ring by ring
    outwards, stopping once no nearer cell can lie beyond: the cost grows with the distance
    to the work, not with the grid."""
    sx, sy = coverable.shape
    best, bi, bj = -1, 0, 0
    for r in range(max(x, sx - 1 - x, y, sy - 1 - y) + 1):
        if best >= 0 and r * r > best:
            break  # every cell of ring r lies at least r away
        for i in range(max(0, x - r), min(sx, x + r + 1)):
            edge = i == x - r or i == x + r
            j = max(0, y - r)
            while j < min(sy, y + r + 1):
                if coverable[i, j] and views[i, j] == 0:
                    d2 = (i - x) * (i - x) + (j - y) * (j - y)
                    if best < 0 or d2 < best or (d2 == best and (i < bi or (i == bi and j < bj))):
                        best, bi, bj = d2, i, j
                # Inside the ring's side columns only its two ends belong to the ring.
                if edge or j >= y + r:
                    j += 1
                else:
                    j = y + r if y + r > j else j + 1
    return best, bi, bj


@numba.njit(cache=True)
def observation(w, p, layout, e, out):
    """Write world e's observation (``w``: WorldArrays, ``p``: Params) into ``out[e]``."""
    blocked, coverable, views, blk_todo, blk_total = (
        w.blocked,
        w.coverable,
        w.views,
        w.blk_todo,
        w.blk_total,
    )
    st = w.status[e]
    m = world_of(w, e)  # the world: map and coverage rows
    sx, sy, sz = p.size_x, p.size_y, p.size_z
    g = blk_todo.shape[1]
    window, extras = layout.window, layout.extras
    half = window // 2
    ww = window * window
    o = out[e]
    x, y, z = st["x"], st["y"], st["z"]
    k = 0
    for i in range(x - half, x + half + 1):
        for j in range(y - half, y + half + 1):
            if 0 <= i < sx and 0 <= j < sy:
                o[k] = 1.0 if (coverable[m, i, j] and views[m, i, j] == 0) else 0.0
                o[ww + k] = 1.0 if blocked[m, i, j, z] else 0.0
            else:
                o[k] = 0.0
                o[ww + k] = 1.0
            k += 1
    k = 2 * ww
    for bi in range(g):
        for bj in range(g):
            t = blk_total[m, bi, bj]
            o[k] = blk_todo[m, bi, bj] / t if t > 0 else 0.0
            k += 1
    o[k] = x / (sx - 1)
    o[k + 1] = y / (sy - 1)
    o[k + 2] = z / (sz - 1)
    o[k + 3] = st["tilt"] / 90.0
    o[k + 4] = (st["pan"] + 90) / 180.0
    o[k + 5] = (st["zoom10"] - 5) / 15.0
    o[k + 6] = min(1.0, max(0.0, w.energy[e] / p.capacity))
    cov = st["coverable"]
    o[k + 7] = st["covered"] / cov if cov > 0 else 1.0
    o[k + 8] = max(0.0, (p.step_limit - st["steps"]) / p.step_limit)
    o[k + 9] = 1.0 if (z + 1 >= sz or blocked[m, x, y, z + 1]) else 0.0
    o[k + 10] = 1.0 if (z - 1 < 0 or blocked[m, x, y, z - 1]) else 0.0
    k += N_SCALARS
    if extras & EXTRA_VISITS:
        cap = layout.visits_cap
        for i in range(x - half, x + half + 1):
            for j in range(y - half, y + half + 1):
                v = w.visits[e, i, j, z] if (0 <= i < sx and 0 <= j < sy) else 0
                o[k] = min(v, cap) / cap
                k += 1
    if extras & EXTRA_STALL:
        o[k] = min(st["steps"] - w.progress[e], STALL_RANGE) / STALL_RANGE
        k += 1
    if extras & EXTRA_TARGET:
        _target(w, p, layout, e, o[k : k + N_TARGET])
        k += N_TARGET
    if layout.teammates > 0:
        _teammates(w, p, layout.teammates, e, o[k : k + N_TEAMMATE * layout.teammates])


@numba.njit(cache=True)
def _target(w, p, layout, e, o):
    """The obs_target block of slot e into ``o`` (3 values)."""
    coverable, views = w.coverable, w.views
    m = world_of(w, e)
    st = w.status[e]
    x, y, z = st["x"], st["y"], st["z"]
    sx, sy = p.size_x, p.size_y
    moves = -1
    if layout.extras & EXTRA_PATH and not (coverable[m, x, y] and views[m, x, y] == 0):
        dx, dy, moves = path_to_work(w, e, x, y, z, sx, sy, 0)
    if moves > 0:
        o[0] = (dx + 1.0) / 2.0
        o[1] = (dy + 1.0) / 2.0
        o[2] = min(moves, TARGET_RANGE) / TARGET_RANGE
        return
    # The straight line: without obs_target_path, or when no way is open at this altitude
    # (when a way is open the search alone runs: the hot path does one pass, not two).
    best, bi, bj = nearest_work(coverable[m], views[m], x, y)
    if best <= 0:  # none left, or the UAV is above one
        o[0], o[1], o[2] = 0.5, 0.5, 0.0
    else:
        d = np.sqrt(best)
        o[0] = ((bi - x) / d + 1.0) / 2.0
        o[1] = ((bj - y) / d + 1.0) / 2.0
        o[2] = min(d, TARGET_RANGE) / TARGET_RANGE


@numba.njit(cache=True)
def _teammates(w, p, count, e, o):
    """The obs_teammates block of slot e into ``o``: its ``count`` nearest teammates still
    flying (squared distance in cells; on a tie the lower UAV number), zeros after them."""
    o[:] = 0.0
    k = fleet_size(w)
    first = (e // k) * k
    st = w.status[e]
    x, y, z = st["x"], st["y"], st["z"]
    taken = 0  # bit u: teammate u already written
    for slot in range(min(count, k - 1)):
        best, pick = -1, -1
        for t in range(first, first + k):
            if t == e or w.left[t] or taken & (1 << (t - first)):
                continue
            tt = w.status[t]
            d2 = (tt["x"] - x) ** 2 + (tt["y"] - y) ** 2 + (tt["z"] - z) ** 2
            if best < 0 or d2 < best:
                best, pick = d2, t
        if pick < 0:
            return
        taken |= 1 << (pick - first)
        tt = w.status[pick]
        b = N_TEAMMATE * slot
        o[b] = 1.0
        o[b + 1] = ((tt["x"] - x) / (p.size_x - 1) + 1.0) / 2.0
        o[b + 2] = ((tt["y"] - y) / (p.size_y - 1) + 1.0) / 2.0
        o[b + 3] = ((tt["z"] - z) / max(1, p.size_z - 1) + 1.0) / 2.0
        o[b + 4] = min(1.0, w.seen_now[pick] / p.max_footprint)
        o[b + 5] = min(1.0, max(0.0, w.energy[pick] / p.capacity))


@numba.njit(**BATCH_KERNEL)
def build_observations(w, p, layout, worlds, out):
    """Write the observation of each world index in ``worlds`` into the matching row of out."""
    for k in range(worlds.shape[0]):
        observation(w, p, layout, worlds[k], out)


__all__ = [
    "N_SCALARS",
    "ObsLayout",
    "build_observations",
    "obs_layout",
    "obs_size",
    "obs_size_for",
]
