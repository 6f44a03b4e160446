"""Merge a voxel grid into a few boxes: a physics engine gets one body per box, not per voxel."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _merge(grid):
    sx, sy, sz = grid.shape
    used = np.zeros(grid.shape, dtype=np.bool_)
    out = np.empty((grid.sum(), 6), dtype=np.int64)
    n = 0
    for k in range(sz):
        for j in range(sy):
            for i in range(sx):
                if not grid[i, j, k] or used[i, j, k]:
                    continue
                i1 = i
                while i1 + 1 < sx and grid[i1 + 1, j, k] and not used[i1 + 1, j, k]:
                    i1 += 1
                j1 = j
                while j1 + 1 < sy:  # grow along y while the whole x run is free to take
                    ok = True
                    for a in range(i, i1 + 1):
                        if not grid[a, j1 + 1, k] or used[a, j1 + 1, k]:
                            ok = False
                            break
                    if not ok:
                        break
                    j1 += 1
                k1 = k
                while k1 + 1 < sz:  # then along z while the whole rectangle is
                    ok = True
                    for a in range(i, i1 + 1):
                        for b in range(j, j1 + 1):
                            if not grid[a, b, k1 + 1] or used[a, b, k1 + 1]:
                                ok = False
                                break
                        if not ok:
                            break
                    if not ok:
                        break
                    k1 += 1
                used[i : i1 + 1, j : j1 + 1, k : k1 + 1] = True
                out[n, 0], out[n, 1], out[n, 2] = i, j, k
                out[n, 3], out[n, 4], out[n, 5] = i1, j1, k1
                n += 1
    return out[:n]


def merge_boxes(grid: np.ndarray) -> np.ndarray:
    """Disjoint boxes (n, 6) of voxel indices (x0, y0, z0, x1, y1, z1), inclusive, whose union
    is exactly the True cells of ``grid`` (X, Y, Z): greedy, along x, then y, then z."""
    return _merge(np.ascontiguousarray(grid, dtype=np.bool_))


__all__ = ["merge_boxes"]
