"""Import a uavSim map (theilem/uavSim, BSD-3) as a site.

uavSim draws a map as an RGB PNG, one pixel per cell, each channel a layer (any non-zero
value sets it): red = no-fly zone, green = obstacle, blue = start and landing zone. An obstacle
that is also a no-fly zone (yellow) is a tall building: the UAV flies over neither it nor the
no-fly zone. A green-only obstacle is low: it hides the ground and blocks the lowest level,
and the UAV flies over it.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from pirl.config.errors import ConfigError
from pirl.world.site import SITE_FILE

LEVELS = 3
CELL_M = 10.0
"""uavSim maps carry no scale: 10 m cells, levels of 10 m (say another in site.yaml)."""


def read_uavsim(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(no_fly, obstacle, start, shape) layers of a uavSim PNG, in raster orientation (row 0
    north, as the image stores it)."""
    from PIL import Image

    try:
        with Image.open(path) as img:
            rgb = np.asarray(img.convert("RGB"))
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: not a PNG map ({exc})") from None
    layers = rgb.astype(bool)
    return layers[..., 0], layers[..., 1], layers[..., 2], np.array(rgb.shape[:2])


def _squares(mask: np.ndarray) -> dict:
    """GeoJSON of a raster mask's cells as one MultiPolygon, in cell units (x east, y north)."""
    import shapely
    from shapely.geometry import box, mapping

    rows = mask.shape[0]
    cells = [box(c, rows - 1 - r, c + 1, rows - r) for r, c in zip(*np.nonzero(mask), strict=True)]
    geom = shapely.union_all(cells)
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": mapping(geom)}
    ]}  # fmt: skip


def import_uavsim(png: Path, out: Path) -> Path:
    """Write a site folder ``out`` (refused if it exists) from a uavSim map; returns it."""
    png, out = Path(png), Path(out)
    if not png.is_file():
        raise ConfigError(f"{png}: no such map")
    if out.exists():
        raise ConfigError(f"--out {out} already exists; choose a new folder")
    no_fly, obstacle, start, shape = read_uavsim(png)
    if min(shape) < 3:
        raise ConfigError(f"{png}: {shape[1]} x {shape[0]} pixels; a site needs at least 3 x 3")
    heights = np.zeros(no_fly.shape, dtype=np.float64)
    heights[obstacle & ~no_fly] = CELL_M  # low: blocks level 0
    heights[obstacle & no_fly] = CELL_M * LEVELS  # tall: blocks every level
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        np.save(tmp / "heights.npy", heights)
        shutil.copyfile(png, tmp / png.name)
        lines = [
            f"# Imported from the uavSim map {png.name} (pirl site import-uavsim)",
            f"name: {png.stem}",
            "heights: heights.npy      # low obstacles 1 level, tall ones (obstacle + no-fly) all",
            f"cell_size_m: {CELL_M}",
            f"level_height_m: {CELL_M}",
            f"levels: {LEVELS}",
        ]
        nfz_only = no_fly & ~obstacle
        if nfz_only.any():
            (tmp / "no_fly.geojson").write_text(json.dumps(_squares(nfz_only)) + "\n")
            lines.append("no_fly: no_fly.geojson    # red pixels, in cell units")
        if start.any():
            (tmp / "start.geojson").write_text(json.dumps(_squares(start)) + "\n")
            lines.append("start: {zone: start.geojson}  # blue pixels")
        (tmp / SITE_FILE).write_text("\n".join(lines) + "\n")
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


__all__ = ["import_uavsim", "read_uavsim"]
