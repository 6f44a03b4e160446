"""Camera footprint models: which ground cells a camera pose sees.

Both models are numba-compiled functions that write the seen cells into a caller's buffer,
so the single and batched environments, the renderer and the planners use the same geometry.

- ``paper``: a square centred on the UAV, half-width ``floor(m * zoom + 0.5)`` with ``m = 2``
  when tilt < 80 degrees and ``m = 1`` otherwise (altitude and pan do not matter).
- ``frustum``: a pinhole camera at the cell centre, ``z + 1`` cells above the ground, the four
  corner rays intersected with the ground (cut at ``max_range``), optional occlusion: by the
  obstacle spheres of a generated world (the paper's geometry, exactly), or, in a world of
  voxels (a site), by a ray march through its occluding cells.

Coordinates: cell ``(x, y, z)`` has its centre at ``(x, y, z)``; the ground plane lies at
``z = -1`` so a UAV in level ``z`` flies ``z + 1`` cells above it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from pirl.config import grid

PAPER = 0
FRUSTUM = 1
# A square of half-width 4 (zoom 2.0, tilt < 80) is the largest paper footprint.
PAPER_MAX_HALF = 4


MODELS = {"paper": PAPER, "frustum": FRUSTUM}
"""Each footprint model's name (``env.footprint``) and number."""


def footprint_model(name: str) -> int:
    """The number of the footprint model called ``name`` (one of :data:`MODELS`)."""
    return MODELS[name]


NO_VOXELS = np.zeros((0, 0, 0), dtype=np.bool_)
NO_GROUND = np.zeros((0, 0), dtype=np.float64)
"""The ground of a flat world (no terrain): nothing of it hides anything."""
"""The occluding grid of a footprint without voxels (:func:`footprint_cells`)."""


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


paper_half_width = numba.njit(cache=True)(grid.paper_half_width)
"""The rule of :func:`pirl.config.grid.paper_half_width`, compiled for the kernels."""


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
def _occluded_voxels(cx, cy, cz, gx, gy, occluding):
    """True when the segment camera -> ground cell centre passes through an occluding voxel
    (other than those of the target cell's own column: a roof is seen, not hidden by itself).

    A 3-D DDA (Amanatides and Woo) over voxels centred at integer coordinates; the ground
    plane is at z = -1, and level 0's voxels reach down to it.
    """
    sx, sy, sz = occluding.shape
    if sx == 0:
        return False
    dx, dy, dz = gx - cx, gy - cy, -1.0 - cz
    px, py, pz = cx + 0.5, cy + 0.5, cz + 0.5
    i, j, k = int(math.floor(px)), int(math.floor(py)), int(math.floor(pz))
    ti, tj = int(gx), int(gy)
    inf = 1e30
    si = 1 if dx > 0 else -1
    sj = 1 if dy > 0 else -1
    tdx = abs(1.0 / dx) if dx != 0.0 else inf
    tdy = abs(1.0 / dy) if dy != 0.0 else inf
    tdz = abs(1.0 / dz) if dz != 0.0 else inf
    tx = ((i + 1 - px) if dx > 0 else (px - i)) * tdx if dx != 0.0 else inf
    ty = ((j + 1 - py) if dy > 0 else (py - j)) * tdy if dy != 0.0 else inf
    tz = (pz - k) * tdz if dz != 0.0 else inf
    while True:
        if tx <= ty and tx <= tz:
            t, i, tx = tx, i + si, tx + tdx
        elif ty <= tz:
            t, j, ty = ty, j + sj, ty + tdy
        else:
            t, k, tz = tz, k - 1, tz + tdz
        if t >= 1.0:
            return False
        if i < 0 or j < 0 or i >= sx or j >= sy or k >= sz:
            continue
        # Below level 0 (z in [-1, -0.5]) a building still stands on the ground.
        if (i != ti or j != tj) and occluding[i, j, max(k, 0)]:
            return True


@numba.njit(cache=True)
def _occluded_ground(cx, cy, cz, gx, gy, ground):
    """True when the terrain rises above the segment camera -> ground cell centre: a ridge
    between them. ``ground`` is the terrain in levels at cell centres (integer coordinates,
    the voxels' convention); the camera is ``cz + 1`` levels above the ground under it, the
    target on its own ground. Between cell centres the terrain is bilinear, so a uniform
    slope never hides its own cells; the segment is sampled every half cell."""
    top = ground_at(ground, cx, cy) + cz + 1.0  # heights from the ground plane at level -1
    bottom = ground[gx, gy]
    dx, dy = gx - cx, gy - cy
    n = int(math.ceil(2.0 * math.sqrt(dx * dx + dy * dy)))
    for s in range(1, n):
        t = s / n
        if top + t * (bottom - top) < ground_at(ground, cx + t * dx, cy + t * dy) - 1e-9:
            return True
    return False


@numba.njit(cache=True)
def ground_at(ground, px, py):
    """The terrain at point (px, py), bilinear between cell centres (exact at a centre)."""
    sx, sy = ground.shape
    i0 = min(max(int(math.floor(px)), 0), sx - 1)
    j0 = min(max(int(math.floor(py)), 0), sy - 1)
    i1, j1 = min(i0 + 1, sx - 1), min(j0 + 1, sy - 1)
    fx, fy = min(max(px - i0, 0.0), 1.0), min(max(py - j0, 0.0), 1.0)
    return (ground[i0, j0] * (1 - fx) + ground[i1, j0] * fx) * (1 - fy) + (
        ground[i0, j1] * (1 - fx) + ground[i1, j1] * fx
    ) * fy


@numba.njit(cache=True)
def footprint_cells(lens, pose, obstacles, occluding, ground, out):
    """Write the ground cells ``pose`` sees through ``lens`` as rows (i, j) of ``out``; return
    their count.

    ``lens`` is a :class:`Lens` or a tuple with its fields (a world's ``Params``); ``pose`` a
    grid :class:`CameraPose` (integers); ``obstacles`` the rows (cx, cy, cz, r) that may
    occlude; ``occluding`` the (X, Y, Z) voxels that occlude when there are no spheres (a
    (0, 0, 0) array for none); ``ground`` a site's terrain in levels (:data:`NO_GROUND` for
    flat ground), which hides what lies behind a ridge. ``out`` must hold at least
    :func:`buffer_rows` rows.

    Over terrain the frustum is projected exactly on each cell's own ground
    (:func:`frustum_over_ground`); the voxels of buildings stand on their cells' ground.
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
    if ground.shape[0] > 0:
        return frustum_over_ground(lens, pose, occluding, ground, out)
    poly = np.empty((4, 2))
    frustum_corners(lens, pose, poly)
    return frustum_scan(lens, pose, poly, obstacles, occluding, out)


@numba.njit(cache=True)
def frustum_over_ground(lens, pose, occluding, ground, out):
    """The frustum's cells over terrain, projected exactly: every ground cell within
    ``max_range`` (horizontally) whose centre, on its own terrain, lies inside the camera's
    pyramid; with occlusion, hidden by a ridge (:func:`_occluded_ground`) or by the voxels of
    buildings, marched as over flat ground (the ray's height above the ground taken to fall
    evenly from the camera's to the target's). Writes rows of ``out``; returns their count."""
    t = math.radians(pose.tilt)
    p = math.radians(pose.pan)
    th = math.tan(math.radians(lens.fov_deg) / 2.0) / (pose.zoom10 / 10.0)
    tv = th * 0.75
    fx, fy, fz = math.cos(t) * math.cos(p), math.cos(t) * math.sin(p), -math.sin(t)
    rx, ry = math.sin(p), -math.cos(p)
    ux, uy, uz = math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)
    cz = pose.z + ground_at(ground, pose.x, pose.y)
    reach = int(math.floor(lens.max_range)) + 1
    x0, y0 = int(math.floor(pose.x + 0.5)), int(math.floor(pose.y + 0.5))  # the nearest cell
    n = 0
    for i in range(max(0, x0 - reach), min(lens.size_x, x0 + reach + 1)):
        for j in range(max(0, y0 - reach), min(lens.size_y, y0 + reach + 1)):
            dx, dy = float(i - pose.x), float(j - pose.y)
            if dx * dx + dy * dy > lens.max_range * lens.max_range:
                continue
            dz = ground[i, j] - 1.0 - cz
            a = dx * fx + dy * fy + dz * fz
            if a <= 1e-9:
                continue
            if abs(dx * rx + dy * ry) > th * a or abs(dx * ux + dy * uy + dz * uz) > tv * a:
                continue
            if lens.occlusion:
                if _occluded_voxels(pose.x, pose.y, pose.z, i, j, occluding):
                    continue
                if _occluded_ground(pose.x, pose.y, pose.z, i, j, ground):
                    continue
            out[n, 0] = i
            out[n, 1] = j
            n += 1
    return n


@numba.njit(cache=True)
def frustum_scan(lens, pose, poly, obstacles, occluding, out):
    """Write the ground cells inside ground polygon ``poly`` (seen from ``pose``, occluded by
    ``obstacles``, or by ``occluding`` voxels where there are no spheres, when the lens says
    so) as rows of ``out``; return their count."""
    spheres = obstacles.shape[0] > 0
    x0 = max(0, int(math.floor(poly[:, 0].min())))
    x1 = min(lens.size_x - 1, int(math.ceil(poly[:, 0].max())))
    y0 = max(0, int(math.floor(poly[:, 1].min())))
    y1 = min(lens.size_y - 1, int(math.ceil(poly[:, 1].max())))
    n = 0
    for i in range(x0, x1 + 1):
        for j in range(y0, y1 + 1):
            if _inside(i, j, poly):
                if lens.occlusion:
                    if spheres:
                        if _occluded(pose.x, pose.y, pose.z, i, j, obstacles):
                            continue
                    elif _occluded_voxels(pose.x, pose.y, pose.z, i, j, occluding):
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
    no_voxels = NO_VOXELS
    best = 0
    for z in range(size_z):
        for tilt in range(0, 91, 5):
            for pan in (0, 45):
                for zoom10 in range(5, 21):
                    pose = CameraPose(span, span, z, tilt, pan, zoom10)
                    best = max(best, footprint_cells(lens, pose, empty, no_voxels, NO_GROUND, out))
    return best


def buffer_rows(model: int, max_range: float) -> int:
    """Rows a footprint buffer needs for this model."""
    if model == PAPER:
        return (2 * PAPER_MAX_HALF + 1) ** 2
    side = 2 * (int(math.ceil(max_range)) + 2) + 1
    return side * side
