"""Write the example sites of this folder (run from the repository root:
``python examples/sites/make_examples.py``). The sites are invented, not surveys of real
places; `campus` is placed on the Earth so that its files carry real coordinates.

- ``campus``: a 48 x 40 GeoTIFF DSM (5 m cells, UTM zone 32N near Munich) with a ring building
  round a closed courtyard, a GeoJSON area (longitude/latitude) and a no-fly zone.
- ``village``: a 128 x 128 grey PNG of heights (0.25 m per grey level, 4 m cells) with an
  origin, streets of houses and a start zone.
- ``town``: 256 x 256 cells and 8 levels, not georeferenced: the scale benchmark's site.
- ``hills``: a 48 x 40 DTM and DSM (5 m cells, UTM zone 33N in Styria), metres above sea level:
  a valley between a ridge and a slope, a copse and three buildings on the DSM, an area and a
  no-fly zone in longitude/latitude. Levels follow the terrain.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _write_tif(
    path: Path, values: np.ndarray, crs: str, west: float, north: float, cell: float
) -> None:
    import rasterio
    from rasterio.transform import from_origin

    rows, cols = values.shape
    with rasterio.open(
        path, "w", driver="GTiff", width=cols, height=rows, count=1, dtype="float32", crs=crs,
        transform=from_origin(west, north, cell, cell),
    ) as dst:  # fmt: skip
        dst.write(values.astype(np.float32), 1)
        dst.update_tags(1, units="m")
        dst.units = ("m",)


def _write_polygons(out: Path, to_ll, cells: dict[str, tuple[float, ...]], west: float,
                    south: float, cell: float) -> None:  # fmt: skip
    """Each named polygon, given as cells (x0, y0, x1, y1) from the south-west corner, as a
    GeoJSON file in longitude/latitude."""
    for name, (x0, y0, x1, y1) in cells.items():
        feat = _feature(to_ll, west + x0 * cell, south + y0 * cell, west + x1 * cell,
                        south + y1 * cell)  # fmt: skip
        (out / f"{name}.geojson").write_text(
            json.dumps({"type": "FeatureCollection", "features": [feat]}, indent=1) + "\n"
        )


def _feature(to_ll, e0: float, n0: float, e1: float, n1: float) -> dict:
    ring = [(e0, n0), (e1, n0), (e1, n1), (e0, n1), (e0, n0)]
    coords = [list(to_ll.transform(e, n)) for e, n in ring]
    geometry = {"type": "Polygon", "coordinates": [coords]}
    return {"type": "Feature", "properties": {}, "geometry": geometry}


def campus() -> None:
    import rasterio
    from pyproj import Transformer
    from rasterio.transform import from_origin

    out = HERE / "campus"
    out.mkdir(exist_ok=True)
    cols, rows, cell = 48, 40, 5.0
    h = np.zeros((rows, cols), dtype=np.float32)  # row 0 = north
    h[4:8, 4:16] = 9.0  # a low hall: flown over at level 2
    h[24:36, 28:44] = 24.0  # a ring building, taller than every level ...
    h[27:33, 31:41] = 0.0  # ... round a courtyard the UAV cannot enter
    h[14:18, 30:34] = 14.0
    h[30:34, 6:10] = 4.0  # a shed
    west, north = 690_000.0, 5_336_000.0
    transform = from_origin(west, north, cell, cell)
    with rasterio.open(
        out / "dsm.tif", "w", driver="GTiff", width=cols, height=rows, count=1,
        dtype="float32", crs="EPSG:32632", transform=transform,
    ) as dst:  # fmt: skip
        dst.write(h, 1)
    to_ll = Transformer.from_crs("EPSG:32632", "EPSG:4326", always_xy=True)

    south = north - rows * cell
    polygons = {"area": (1, 1, 47, 39), "no_fly": (36, 30, 47, 39)}
    _write_polygons(out, to_ll, polygons, west, south, cell)
    (out / "site.yaml").write_text(
        "# An invented campus on a GeoTIFF DSM (UTM 32N): docs/sites.md\n"
        "name: campus\n"
        "heights: dsm.tif          # metres above ground, 5 m pixels\n"
        "level_height_m: 5.0       # levels fly at 5, 10 and 15 m\n"
        "levels: 3\n"
        "area: area.geojson        # longitude/latitude\n"
        "no_fly: no_fly.geojson    # a helipad corner\n"
        "start: [3, 3]\n"
    )


def hills() -> None:
    from pyproj import Transformer

    out = HERE / "hills"
    out.mkdir(exist_ok=True)
    cols, rows, cell = 48, 40, 5.0
    x = (np.arange(cols) + 0.5) * cell  # metres east of the west edge
    y = (rows - np.arange(rows) - 0.5) * cell  # metres north of the south edge (row 0 north)
    ex, ny = np.meshgrid(x, y)
    # A valley floor at 300 m, a ridge up to 35 m high running north-south 170 m east (at most
    # about 34 degrees steep), the ground rising 20 m towards the west, a gentle fall south.
    dtm = (
        300.0
        + 35.0 * np.exp(-(((ex - 170.0) / 45.0) ** 2)) * (0.7 + 0.3 * ny / (rows * cell))
        + 20.0 * np.clip((60.0 - ex) / 60.0, 0.0, None) ** 1.5
        + 0.04 * ny
    )
    dsm = dtm.copy()
    dsm[6:14, 28:33] += 11.0  # a copse on the ridge's west flank
    for r0, c0, h in ((26, 8, 8.0), (30, 20, 12.0), (12, 40, 15.0)):  # three buildings
        dsm[r0 : r0 + 4, c0 : c0 + 5] = dtm[r0 : r0 + 4, c0 : c0 + 5].max() + h
    west, north = 530_000.0, 5_210_000.0
    crs = "EPSG:32633"
    _write_tif(out / "dtm.tif", dtm, crs, west, north, cell)
    _write_tif(out / "dsm.tif", dsm, crs, west, north, cell)
    to_ll = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    south = north - rows * cell
    polygons = {"area": (1, 1, 47, 39), "no_fly": (40, 1, 47, 8)}
    _write_polygons(out, to_ll, polygons, west, south, cell)
    (out / "site.yaml").write_text(
        "# An invented hillside: DTM and DSM, metres above sea level (UTM 33N): docs/sites.md\n"
        "name: hills\n"
        "terrain: dtm.tif          # bare ground, 300-345 m above sea level, 5 m pixels\n"
        "surface: dsm.tif          # ground plus a copse and three buildings\n"
        "level_height_m: 5.0       # levels fly 5, 10, 15 and 20 m above the terrain\n"
        "levels: 4\n"
        "area: area.geojson        # longitude/latitude\n"
        "no_fly: no_fly.geojson    # a mast's corner\n"
        "start: [10, 20]\n"
    )


def village() -> None:
    from PIL import Image

    out = HERE / "village"
    out.mkdir(exist_ok=True)
    n = 128
    rng = np.random.default_rng(5)
    grey = np.zeros((n, n), dtype=np.uint8)  # row 0 = north
    for by in range(6, n - 10, 16):
        for bx in range(6, n - 10, 14):
            if rng.random() < 0.2:
                continue  # a yard
            w, d = int(rng.integers(5, 10)), int(rng.integers(5, 11))
            grey[by : by + d, bx : bx + w] = int(rng.integers(12, 48))  # 3-12 m
    grey[60:68, 60:68] = 200  # a church tower, 50 m
    Image.fromarray(grey, mode="L").save(out / "heights.png")
    (out / "site.yaml").write_text(
        "# An invented village on a grey PNG of heights: docs/sites.md\n"
        "name: village\n"
        "heights: heights.png\n"
        "height_scale_m: 0.25      # metres per grey level\n"
        "cell_size_m: 4.0\n"
        "level_height_m: 4.0\n"
        "levels: 3\n"
        "origin: [47.3769, 8.5417] # lat, lon of the south-west corner\n"
        "start: {zone: [0, 0, 5, 5]}\n"
    )


def town() -> None:
    from PIL import Image

    out = HERE / "town"
    out.mkdir(exist_ok=True)
    n = 256
    rng = np.random.default_rng(11)
    grey = np.zeros((n, n), dtype=np.uint8)  # row 0 = north; 0.2 m per grey level
    for by in range(4, n - 12, 20):
        for bx in range(4, n - 12, 18):
            if rng.random() < 0.15:
                continue  # a square
            w, d = int(rng.integers(6, 14)), int(rng.integers(6, 16))
            grey[by : by + d, bx : bx + w] = int(rng.integers(25, 220))  # 5-44 m
    Image.fromarray(grey, mode="L").save(out / "heights.png")
    (out / "site.yaml").write_text(
        "# An invented town of 256 x 256 cells and 8 levels (the scale benchmark): docs/sites.md\n"
        "name: town\n"
        "heights: heights.png\n"
        "height_scale_m: 0.2       # metres per grey level\n"
        "cell_size_m: 5.0\n"
        "level_height_m: 5.0       # levels fly at 5, 10, ... 40 m\n"
        "levels: 8\n"
        "start: {zone: [0, 0, 3, 3]}\n"
    )


if __name__ == "__main__":
    campus()
    village()
    town()
    hills()
