"""Ground models of a site: a terrain (DTM) and a surface (DSM) in metres above sea level,
read onto the site's grid with rasterio.

The grid's levels follow the terrain: level z over cell (x, y) flies (z + 1) x
``level_height_m`` above ``terrain[x, y]``, so a hill is ground to fly over, not a wall, and
what blocks a level is the obstacle height above the terrain, as on a flat site:

- ``terrain`` and ``surface``: obstacles are ``surface - terrain`` (less than
  ``site.min_obstacle_m`` is ground);
- ``surface`` alone: the terrain is estimated by a grey-scale opening of the surface over
  ``site.ground_window_m`` (the lowest surface within the window, then the highest of those),
  which removes anything narrower than the window and keeps wider hills;
- ``terrain`` alone: obstacles come from ``heights`` (above the ground) or there are none.

Resampling onto the grid is stated per input: the terrain bilinear (a smooth ground between
the DTM's posts), the surface by the highest pixel in a cell (an obstacle never shrinks away,
the rule ``heights`` follows). A raster in another CRS than the grid is reprojected. Axes:
arrays here are (x east, y north), like every grid of :mod:`pirl.world.site`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.site import SiteSettings

METRE_UNITS = ("", "m", "metre", "meter", "metres", "meters")
"""Vertical units a ground model may state (none stated is read as metres)."""


@dataclass(frozen=True)
class GridFrame:
    """Where a site's grid lies in a projected CRS (metres): what rasters are warped onto."""

    crs: str
    west: float
    south: float
    cell: float
    shape: tuple[int, int]
    """(X, Y) cells."""


@dataclass(frozen=True)
class Ground:
    """A site's ground: terrain above sea level and obstacles above it, per cell (X, Y)."""

    terrain: np.ndarray
    obstacles: np.ndarray | None
    """Obstacle heights above the terrain; None = take them from ``site.heights``."""
    note: str
    """How the ground was made, for ``pirl site check``."""


def open_geotiff(path: Path, key: str, s: SiteSettings) -> Any:
    """The open rasterio dataset of a north-up, square-pixel raster in metres; everything
    else is refused in one line naming ``site.key``."""
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    if not path.is_file():
        raise ConfigError(f"site.{key}: {path} does not exist")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)  # said below, in one line
            src = rasterio.open(path)
    except Exception as exc:  # noqa: BLE001 - any reader's failure is the same user mistake
        raise ConfigError(
            f"site.{key}: {path.name} is not a readable GeoTIFF ({type(exc).__name__})"
        ) from None
    if src.height * src.width > 16 * s.max_cells:
        src.close()
        raise ConfigError(
            f"site.{key}: {src.width} x {src.height} pixels is too large to read (limit "
            f"{16 * s.max_cells:,} pixels, 16 x site.max_cells)"
        )
    return src


def check_north_up(src: Any, name: str, key: str) -> None:
    """Refuse (one line) a rotated, south-up or non-square-pixel raster, or one in degrees."""
    t = src.transform
    if abs(t.b) > 1e-12 or abs(t.d) > 1e-12 or t.e >= 0:
        raise ConfigError(
            f"site.{key}: {name} is rotated or not north-up; warp it to a north-up grid first "
            "(gdalwarp)"
        )
    if abs(abs(t.a) - abs(t.e)) > 1e-6 * abs(t.a):
        raise ConfigError(
            f"site.{key}: {name} has non-square pixels ({t.a} x {-t.e}); warp it to square "
            "pixels first"
        )
    if src.crs is not None and src.crs.is_geographic:
        raise ConfigError(
            f"site.{key}: {name} is in degrees ({src.crs.to_string()}); reproject it to a "
            "metric CRS (e.g. its UTM zone) first"
        )


def frame_of(folder: Path, s: SiteSettings) -> GridFrame:
    """The grid of a site without ``heights``: its surface's raster (else its terrain's) at
    ``site.cell_size_m`` (0 = the raster's pixel). The surface first: its buildings are the
    sharpest edges, best kept on their own pixels."""
    key = "surface" if s.surface else "terrain"
    path = folder / getattr(s, key)
    with open_geotiff(path, key, s) as src:
        check_north_up(src, path.name, key)
        if src.crs is None:
            raise ConfigError(f"site.{key}: {path.name} has no CRS; a ground model needs one")
        t = src.transform
        pixel = abs(t.a)
        cell = s.cell_size_m or pixel
        nx = max(1, math.ceil(src.width * pixel / cell - 1e-9))
        ny = max(1, math.ceil(src.height * pixel / cell - 1e-9))
        north = t.f
        return GridFrame(src.crs.to_wkt(), t.c, north - ny * cell, float(cell), (nx, ny))


def warp_onto(folder: Path, s: SiteSettings, key: str, frame: GridFrame) -> tuple[np.ndarray, str]:
    """Raster ``site.key`` reprojected onto ``frame`` (X, Y), metres above sea level: bilinear
    for the terrain, the highest pixel for the surface; and what was done, in words. No-data,
    NaN, a cell outside the raster or a vertical unit other than metres is refused in one
    line."""
    from affine import Affine
    from rasterio.crs import CRS
    from rasterio.warp import Resampling, reproject

    path = folder / getattr(s, key)
    with open_geotiff(path, key, s) as src:
        check_north_up(src, path.name, key)
        if src.crs is None:
            raise ConfigError(f"site.{key}: {path.name} has no CRS; a ground model needs one")
        unit = (src.units[0] or "").strip().lower() if src.units else ""
        if unit not in METRE_UNITS:
            raise ConfigError(
                f"site.{key}: {path.name} states heights in {src.units[0]!r}; convert them to "
                "metres above sea level first"
            )
        band = src.read(1, masked=True).astype(np.float64).filled(np.nan)
        crs = src.crs
        nx, ny = frame.shape
        dst = np.full((ny, nx), np.nan)
        reproject(
            source=band, destination=dst, src_transform=src.transform, src_crs=src.crs,
            src_nodata=np.nan, dst_transform=Affine(
                frame.cell, 0.0, frame.west, 0.0, -frame.cell, frame.south + ny * frame.cell
            ), dst_crs=frame.crs, dst_nodata=np.nan,
            resampling=Resampling.bilinear if key == "terrain" else Resampling.max,
        )  # fmt: skip
    bad = ~np.isfinite(dst)
    if bad.any():
        raise ConfigError(
            f"site.{key}: {int(bad.sum()):,} of the grid's {nx * ny:,} cells are no-data, NaN "
            f"or outside {path.name}; fill them or make the grid smaller"
        )
    how = "bilinear" if key == "terrain" else "highest pixel"
    if crs != CRS.from_user_input(frame.crs):
        how += f", reprojected from {crs.to_string()}"
    return np.ascontiguousarray(dst[::-1, :].T), how


def estimate_terrain(surface: np.ndarray, cell: float, window_m: float) -> np.ndarray:
    """The bare ground under a surface model: a grey-scale opening over a square window of
    about ``window_m`` (odd, at least 3 cells) — anything narrower than it (a building, a
    copse) is removed, wider ground is kept. Convex hill tops narrower than the window are
    lowered: choose the window from the widest building."""
    from scipy.ndimage import grey_opening

    size = max(3, 2 * round(window_m / cell / 2) + 1)
    return grey_opening(surface, size=(size, size), mode="nearest")


def read_ground(folder: Path, s: SiteSettings, frame: GridFrame) -> Ground:
    """The site's terrain and, from a surface model, its obstacles (see the module doc)."""
    nx, ny = frame.shape
    if not (s.terrain or s.surface):
        return Ground(np.zeros((nx, ny)), None, "flat ground (no terrain or surface model)")
    terrain, t_how = warp_onto(folder, s, "terrain", frame) if s.terrain else (None, "")
    if not s.surface:
        return Ground(terrain, None, f"terrain {s.terrain} ({t_how})")
    surface, s_how = warp_onto(folder, s, "surface", frame)
    if terrain is None:
        terrain = estimate_terrain(surface, frame.cell, s.ground_window_m)
        how = (
            f"terrain estimated from the surface {s.surface} ({s_how}) by a grey-scale "
            f"opening over {s.ground_window_m:g} m (no DTM given)"
        )
    else:
        how = f"terrain {s.terrain} ({t_how}), surface {s.surface} ({s_how})"
    obstacles = surface - terrain
    obstacles[obstacles < s.min_obstacle_m] = 0.0
    rule = f"obstacles = surface - terrain >= {s.min_obstacle_m:g} m"
    return Ground(terrain, obstacles, f"{how}; {rule}")


class _Samples:
    """A raster (rows north to south) sampled at points given in another CRS's metres."""

    def __init__(self, values: np.ndarray, transform: Any, crs: str, grid_crs: str) -> None:
        self.values = values
        self.inverse = ~transform
        self.to = None
        if crs != grid_crs:
            from pyproj import CRS, Transformer

            if not CRS.from_user_input(crs).equals(CRS.from_user_input(grid_crs)):
                self.to = Transformer.from_crs(grid_crs, crs, always_xy=True)

    def pixels(self, e: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional (row, col) of points, pixel centres at whole numbers."""
        if self.to is not None:
            e, n = (np.asarray(v) for v in self.to.transform(e.tolist(), n.tolist()))
        col, row = self.inverse * (e, n)
        return np.asarray(row) - 0.5, np.asarray(col) - 0.5

    def bilinear(self, e: np.ndarray, n: np.ndarray) -> np.ndarray:
        from scipy.ndimage import map_coordinates

        return map_coordinates(self.values, self.pixels(e, n), order=1, mode="nearest")

    def containing(self, e: np.ndarray, n: np.ndarray) -> np.ndarray:
        """The value of the pixel each point lies in (a DSM pixel stands for its square)."""
        row, col = self.pixels(e, n)
        rows, cols = self.values.shape
        r = np.clip(np.floor(row + 0.5).astype(int), 0, rows - 1)
        c = np.clip(np.floor(col + 0.5).astype(int), 0, cols - 1)
        return self.values[r, c]


class GroundProfile:
    """The terrain and the surface (metres above sea level) at any point of a site's grid,
    read from the site's own rasters (not the grid): what a mission's heights above the
    ground and its clearance are computed from. Points are grid coordinates (cell units,
    cell (x, y) spans [x, x + 1) x [y, y + 1))."""

    def __init__(self, folder: Path, s: SiteSettings, frame: GridFrame, terrain: np.ndarray,
                 obstacles: np.ndarray) -> None:  # fmt: skip
        from affine import Affine

        self.frame = frame
        nx, ny = frame.shape
        grid = Affine(frame.cell, 0.0, frame.west, 0.0, -frame.cell, frame.south + ny * frame.cell)
        self._terrain = (
            self._read(folder / s.terrain, frame)
            if s.terrain
            else _Samples(terrain[:, ::-1].T.copy(), grid, frame.crs, frame.crs)
        )
        self._surface = self._read(folder / s.surface, frame) if s.surface else None
        self._obstacles = obstacles

    @staticmethod
    def _read(path: Path, frame: GridFrame) -> _Samples:
        import rasterio

        with rasterio.open(path) as src:
            values = src.read(1, masked=True).astype(np.float64).filled(np.nan)
            return _Samples(values, src.transform, src.crs.to_wkt(), frame.crs)

    def _metres(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = self.frame
        return f.west + np.asarray(x, float) * f.cell, f.south + np.asarray(y, float) * f.cell

    def terrain(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The bare ground's height above sea level (bilinear)."""
        return self._terrain.bilinear(*self._metres(x, y))

    def surface(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The surface's height above sea level: the DSM's pixel each point lies in, or,
        without a DSM, the terrain plus the obstacle of the cell the point lies in."""
        if self._surface is not None:
            return self._surface.containing(*self._metres(x, y))
        nx, ny = self.frame.shape
        i = np.clip(np.floor(x).astype(int), 0, nx - 1)
        j = np.clip(np.floor(y).astype(int), 0, ny - 1)
        return self.terrain(x, y) + self._obstacles[i, j]


def slope_deg(terrain: np.ndarray, cell: float) -> np.ndarray:
    """The terrain's slope per cell, degrees (central differences, one-sided at the edges)."""
    if min(terrain.shape) < 2:
        return np.zeros_like(terrain)
    gx, gy = np.gradient(terrain, cell)
    return np.degrees(np.arctan(np.hypot(gx, gy)))


__all__ = [
    "METRE_UNITS",
    "Ground",
    "GroundProfile",
    "GridFrame",
    "check_north_up",
    "estimate_terrain",
    "frame_of",
    "open_geotiff",
    "read_ground",
    "slope_deg",
    "warp_onto",
]
