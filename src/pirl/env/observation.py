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
====================  ===========  ==========================================================
"""

from __future__ import annotations

import numba

from pirl.world import dynamics as D

N_SCALARS = 11


def obs_size(window: int, global_side: int) -> int:
    """Length of the observation vector."""
    return 2 * window * window + global_side * global_side + N_SCALARS


@numba.njit(cache=True, inline="always")
def _observation(
    e, ints, energy, capacity, step_limit, blocked, coverable, views, blk_todo, blk_total,
    window, out,
):  # fmt: skip
    sx, sy, sz = blocked.shape[1], blocked.shape[2], blocked.shape[3]
    g = blk_todo.shape[1]
    half = window // 2
    ww = window * window
    o = out[e]
    x, y, z = ints[e, D.PX], ints[e, D.PY], ints[e, D.PZ]
    k = 0
    for i in range(x - half, x + half + 1):
        for j in range(y - half, y + half + 1):
            if 0 <= i < sx and 0 <= j < sy:
                o[k] = 1.0 if (coverable[e, i, j] and views[e, i, j] == 0) else 0.0
                o[ww + k] = 1.0 if blocked[e, i, j, z] else 0.0
            else:
                o[k] = 0.0
                o[ww + k] = 1.0
            k += 1
    k = 2 * ww
    for bi in range(g):
        for bj in range(g):
            t = blk_total[e, bi, bj]
            o[k] = blk_todo[e, bi, bj] / t if t > 0 else 0.0
            k += 1
    o[k] = x / (sx - 1)
    o[k + 1] = y / (sy - 1)
    o[k + 2] = z / (sz - 1)
    o[k + 3] = ints[e, D.TILT] / 90.0
    o[k + 4] = (ints[e, D.PAN] + 90) / 180.0
    o[k + 5] = (ints[e, D.ZOOM] - 5) / 15.0
    o[k + 6] = min(1.0, max(0.0, energy[e] / capacity))
    cov = ints[e, D.COVERABLE]
    o[k + 7] = ints[e, D.COVERED] / cov if cov > 0 else 1.0
    o[k + 8] = max(0.0, (step_limit - ints[e, D.STEPS]) / step_limit)
    o[k + 9] = 1.0 if (z + 1 >= sz or blocked[e, x, y, z + 1]) else 0.0
    o[k + 10] = 1.0 if (z - 1 < 0 or blocked[e, x, y, z - 1]) else 0.0


@numba.njit(cache=True)
def build_observations(
    worlds, ints, energy, capacity, step_limit, blocked, coverable, views, blk_todo, blk_total,
    window, out,
):  # fmt: skip
    """Write the observation of each world index in ``worlds`` into the matching row of out."""
    for k in range(worlds.shape[0]):
        _observation(
            worlds[k], ints, energy, capacity, step_limit, blocked, coverable, views, blk_todo,
            blk_total, window, out,
        )  # fmt: skip


__all__ = ["N_SCALARS", "build_observations", "obs_size"]
