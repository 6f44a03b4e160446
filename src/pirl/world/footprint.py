"""Camera footprint models: which ground cells a camera pose sees.

Both models are numba-compiled functions that write the seen cells into a caller's buffer,
so the single and batched environments, the renderer and the planners use the same geometry.

- ``paper``: a square centred on the UAV, half-width ``floor(m * zoom + 0.5)`` with ``m = 2``
  when tilt < 80 degrees and ``m = 1`` otherwise (altitude and pan do not matter).
- ``frustum``: a pinhole camera at the cell centre, ``z + 1`` cells above the ground, the four
  corner rays intersected with the ground (cut at ``max_range``), optional occlusion by spheres.

Coordinates: cell ``(x, y, z)`` has its centre at ``(x, y, z)``; the ground plane lies at
``z = -1`` so a UAV in level ``z`` flies ``z + 1`` cells above it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

PAPER = 0
FRUSTUM = 1
# A square of half-width 4 (zoom 2.0, tilt < 80) is the largest paper footprint.
PAPER_MAX_HALF = 4


class Lens(NamedTuple):
    """The footprint model and the ground it projects onto (fixed for a world's lifetime)."""

    model: int
    """:data:`PAPER` or :data:`FRUSTUM`."""
    size_x: int
    """Ground cells along x (footprints are clipped to the grid)."""
    size_y: int
    """Ground cells along y."""
    fov_deg: float
    """Horizontal field of view at zoom 1.0, degrees (frustum model)."""
    max_range: float
    """Ground points farther than this many cells are cut to it (frustum model)."""
    occlusion: bool
    """Whether obstacle spheres hide the ground cells behind them (frustum model)."""


class CameraPose(NamedTuple):
    """Where the camera is and how it points: integers on the grid, floats in flight."""

    x: float
    """Position along x in cell units (cell i is centred at i)."""
    y: float
    """Position along y in cell units."""
    z: float
    """Level: the camera flies ``z + 1`` cells above the ground."""
    tilt: float
    """Degrees below the horizon (90 looks straight down)."""
    pan: float
    """Degrees of yaw in the world frame (0 = +x)."""
    zoom10: int
    """Zoom in tenths (10 = 1.0)."""


def lens_of(
    model: int, size: tuple[int, ...], fov_deg: float, max_range: float, occlusion: bool
) -> Lens:
    """The :class:`Lens` of a world of ``size`` (typed as the kernels expect)."""
    return Lens(
        int(model), int(size[0]), int(size[1]), float(fov_deg), float(max_range), bool(occlusion)
    )


@numba.njit(cache=True, inline="always")
def paper_half_width(tilt: int, zoom10: int) -> int:
    """Half-width of the paper model's square: floor(m * zoom + 0.5) in integer arithmetic."""
    m = 2 if tilt < 80 else 1
    return (m * zoom10 + 5) // 10


@numba.njit(cache=True)
def frustum_corners(lens, pose, out):
    """Write the 4 ground corners (out[4, 2]) of the frustum of ``pose``, in cell coordinates."""
    t = math.radians(pose.tilt)
    p = math.radians(pose.pan)
    height = pose.z + 1.0
    max_range = lens.max_range
    th = math.tan(math.radians(lens.fov_deg) / 2.0) / (pose.zoom10 / 10.0)
    tv = th * 0.75
    fx, fy, fz = math.cos(t) * math.cos(p), math.cos(t) * math.sin(p), -math.sin(t)
    rx, ry = math.sin(p), -math.cos(p)
    ux, uy, uz = math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)
    # Corner order walks around the rectangle so the polygon is simple.
    sxs = (1.0, 1.0, -1.0, -1.0)
    sys_ = (1.0, -1.0, -1.0, 1.0)
    for k in range(4):
        dx = fx + th * sxs[k] * rx + tv * sys_[k] * ux
        dy = fy + th * sxs[k] * ry + tv * sys_[k] * uy
        dz = fz + tv * sys_[k] * uz
        horiz = math.sqrt(dx * dx + dy * dy)
        if dz < -1e-9:
            s = height / -dz
            gx, gy = dx * s, dy * s
            if gx * gx + gy * gy > max_range * max_range:
                gx, gy = dx / horiz * max_range, dy / horiz * max_range
        elif horiz > 1e-12:
            gx, gy = dx / horiz * max_range, dy / horiz * max_range
        else:
            gx, gy = 0.0, 0.0
        out[k, 0] = pose.x + gx
        out[k, 1] = pose.y + gy


@numba.njit(cache=True)
def _inside(px, py, poly):
    """Whether (px, py) lies in the convex polygon, its edges included.

    Edges count as inside on every side, so a view that is symmetric about the UAV sees a
    symmetric set of cells (a crossing-number test would keep one edge and drop the other).
    """
    n = poly.shape[0]
    area = 0.0
    for i in range(n):
        j = (i + 1) % n
        area += poly[i, 0] * poly[j, 1] - poly[j, 0] * poly[i, 1]
    sign = 1.0 if area >= 0.0 else -1.0
    for i in range(n):
        j = (i + 1) % n
        cross = (poly[j, 0] - poly[i, 0]) * (py - poly[i, 1]) - (poly[j, 1] - poly[i, 1]) * (
            px - poly[i, 0]
        )
        if cross * sign < -1e-9:
            return False
    return True


@numba.njit(cache=True)
def _occluded(cx, cy, cz, gx, gy, obstacles):
    """True when the segment camera -> ground cell centre crosses an obstacle sphere."""
    gz = -1.0
    dx, dy, dz = gx - cx, gy - cy, gz - cz
    seg2 = dx * dx + dy * dy + dz * dz
    for k in range(obstacles.shape[0]):
        ox, oy, oz, r = obstacles[k, 0], obstacles[k, 1], obstacles[k, 2], obstacles[k, 3]
        t = ((ox - cx) * dx + (oy - cy) * dy + (oz - cz) * dz) / seg2
        t = min(1.0, max(0.0, t))
        qx, qy, qz = cx + t * dx - ox, cy + t * dy - oy, cz + t * dz - oz
        if qx * qx + qy * qy + qz * qz <= r * r:
            return True
    return False


@numba.njit(cache=True)
def footprint_cells(lens, pose, obstacles, out):
    """Write the ground cells ``pose`` sees through ``lens`` as rows (i, j) of ``out``; return
    their count.

    ``lens`` is a :class:`Lens` or a tuple with its fields (a world's ``Params``); ``pose`` a
    grid :class:`CameraPose` (integers); ``obstacles`` the rows (cx, cy, cz, r) that may
    occlude. ``out`` must hold at least :func:`buffer_rows` rows.
    """
    if lens.model == PAPER:
        n = 0
        h = paper_half_width(pose.tilt, pose.zoom10)
        x, y = pose.x, pose.y
        for i in range(max(0, x - h), min(lens.size_x, x + h + 1)):
            for j in range(max(0, y - h), min(lens.size_y, y + h + 1)):
                out[n, 0] = i
                out[n, 1] = j
                n += 1
        return n
    poly = np.empty((4, 2))
    frustum_corners(lens, pose, poly)
    return frustum_scan(lens, pose, poly, obstacles, out)


@numba.njit(cache=True)
def frustum_scan(lens, pose, poly, obstacles, out):
    """Write the ground cells inside ground polygon ``poly`` (seen from ``pose``, occluded by
    ``obstacles`` when the lens says so) as rows of ``out``; return their count."""
    x0 = max(0, int(math.floor(poly[:, 0].min())))
    x1 = min(lens.size_x - 1, int(math.ceil(poly[:, 0].max())))
    y0 = max(0, int(math.floor(poly[:, 1].min())))
    y1 = min(lens.size_y - 1, int(math.ceil(poly[:, 1].max())))
    n = 0
    for i in range(x0, x1 + 1):
        for j in range(y0, y1 + 1):
            if _inside(i, j, poly):
                if lens.occlusion and _occluded(pose.x, pose.y, pose.z, i, j, obstacles):
                    continue
                out[n, 0] = i
                out[n, 1] = j
                n += 1
    return n


def max_footprint_cells(model: int, size_z: int, fov_deg: float, max_range: float) -> int:
    """Cells in the largest footprint any camera setting can produce on an unbounded ground.

    This normalizes the coverage reward term dC into [0, 1].
    """
    if model == PAPER:
        return (2 * PAPER_MAX_HALF + 1) ** 2
    span = int(math.ceil(max_range)) + 2
    side = 2 * span + 1
    out = np.empty((side * side, 2), dtype=np.int64)
    empty = np.zeros((0, 4))
    lens = lens_of(FRUSTUM, (side, side), fov_deg, max_range, False)
    best = 0
    for z in range(size_z):
        for tilt in range(0, 91, 5):
            for pan in (0, 45):
                for zoom10 in range(5, 21):
                    pose = CameraPose(span, span, z, tilt, pan, zoom10)
                    best = max(best, footprint_cells(lens, pose, empty, out))
    return best


def buffer_rows(model: int, max_range: float) -> int:
    """Rows a footprint buffer needs for this model."""
    if model == PAPER:
        return (2 * PAPER_MAX_HALF + 1) ** 2
    side = 2 * (int(math.ceil(max_range)) + 2) + 1
    return side * side
