"""Top-down pictures of a world: coverage, obstacles shaded by height, footprint, UAV, path."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw

from pirl.world.state import WorldBatch

_UNCOVERED = np.array([236, 236, 236], dtype=np.float64)
_COVERED = np.array([140, 210, 140], dtype=np.float64)
_OBSTACLE_LOW = np.array([196, 160, 120], dtype=np.float64)
_OBSTACLE_HIGH = np.array([70, 45, 25], dtype=np.float64)
_FOOTPRINT = np.array([70, 120, 235], dtype=np.float64)


def cell_pixels(size: tuple[int, int, int], cell_px: int = 0) -> int:
    """Pixels per cell: ``cell_px`` when given, else a size near 480 pixels (at least 4)."""
    return cell_px if cell_px > 0 else max(4, 480 // max(size[0], size[1]))


# A fleet's UAVs and their paths, UAV 1 first (UAV 1 keeps the one-UAV picture's colours).
_UAV_COLOURS = (
    ((220, 30, 30), (240, 140, 20)),
    ((30, 90, 220), (90, 160, 240)),
    ((150, 40, 190), (200, 120, 230)),
    ((20, 150, 140), (90, 210, 200)),
    ((120, 80, 20), (190, 150, 80)),
    ((200, 40, 130), (240, 130, 190)),
)


def render_world(
    world: WorldBatch,
    e: int,
    path: Sequence | None = None,
    cell_px: int = 0,
) -> np.ndarray:
    """RGB image (Y*c, X*c, 3) of slot ``e``'s world; +x to the right, +y up.

    ``path`` is the UAV's cells; for a fleet (``world.uavs`` > 1) one such list per UAV. Each
    UAV of the world is drawn with its footprint, a fleet's each in its own colour.
    """
    sx, sy, sz = world.cfg.size
    c = cell_pixels(world.cfg.size, cell_px)
    g = world.world_of(e)
    covered = world.covered(e)
    blocked = world.blocked[g]
    # Height of the tallest blocked cell in each column, 0 when the column is free.
    levels = np.where(blocked.any(axis=2), sz - np.argmax(blocked[:, :, ::-1], axis=2), 0)
    rgb = np.where(covered[..., None], _COVERED, _UNCOVERED)
    shade = (levels / sz)[..., None]
    obstacle = _OBSTACLE_LOW * (1 - shade) + _OBSTACLE_HIGH * shade
    rgb = np.where((levels > 0)[..., None], 0.45 * rgb + 0.55 * obstacle, rgb)
    rgb = np.where(~world.coverable[g][..., None], obstacle, rgb)
    k = world.uavs
    slots = range(g * k, g * k + k) if k > 1 else (e,)
    for s in slots:
        if k > 1 and world.left[s]:
            continue
        fp = world.footprint(s)
        if len(fp):
            rgb[fp[:, 0], fp[:, 1]] = 0.55 * rgb[fp[:, 0], fp[:, 1]] + 0.45 * _FOOTPRINT
    # (x, y) grid -> image rows top-down in y, columns in x.
    img = np.repeat(np.repeat(rgb.transpose(1, 0, 2)[::-1], c, axis=0), c, axis=1)
    image = Image.fromarray(img.astype(np.uint8))
    draw = ImageDraw.Draw(image)

    def centre(x: int, y: int) -> tuple[float, float]:
        return (x + 0.5) * c, (sy - 1 - y + 0.5) * c

    paths = (path or [None] * k) if k > 1 else [path]
    for u, s in enumerate(slots):
        body, trail = _UAV_COLOURS[u % len(_UAV_COLOURS)]
        cells = paths[u] if u < len(paths) else None
        if cells and len(cells) > 1:
            draw.line([centre(p[0], p[1]) for p in cells], fill=trail, width=max(1, c // 4))
        x, y, z = world.position(s)
        cx, cy = centre(x, y)
        radius = c * (0.3 + 0.3 * (z + 1) / sz)
        draw.ellipse(
            [cx - radius, cy - radius, cx + radius, cy + radius], fill=body, outline=(0, 0, 0)
        )
    return np.asarray(image)
