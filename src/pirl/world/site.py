"""Sites: a real place read from a folder with a ``site.yaml`` into the world's voxel grids.

A site gives the map (shared by every UAV flying it) as grids over cells (x, y, z), x east,
y north, z the flight level:

- ``blocked[x, y, z]``: where the UAV cannot be (buildings up to their height, no-fly zones
  at every level);
- ``occluding[x, y, z]``: what hides the ground from the camera (buildings only);
- ``coverable[x, y]``: the ground cells the task wants seen (the area's free ground, and roofs
  with ``site.roofs``);
- ``starts``: the cells episodes start from.

With a terrain or surface model (:mod:`pirl.world.terrain`) the levels follow the ground:
level z over a cell flies (z + 1) x ``level_height_m`` above that cell's terrain, and
``heights`` holds the obstacles above it; a flat site has ``terrain`` zero everywhere.

Raster rows run north to south (row 0 is the north edge), as images and GeoTIFFs store them.
Geodata: a GeoTIFF's CRS and transform (read with rasterio) or ``site.origin`` place the grid
on the Earth; GeoJSON polygons (read with shapely) are reprojected from longitude/latitude
with pyproj. Every mistake in a site is one line naming ``site.key``.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.site import SiteSettings, start_kind

SITE_FILE = "site.yaml"
DEFAULT_CELL_M = 10.0
"""Metres per cell of a raster that gives no size at all."""


@dataclass(frozen=True)
class GeoRef:
    """Where the grid lies on the Earth: a projected CRS in metres and the grid's south-west
    corner in it. ``crs`` empty: a site in cell units only."""

    crs: str
    """The CRS (WKT or PROJ string) whose metres the grid is laid in; "" = none."""
    west: float
    """x of the grid's west edge in ``crs``."""
    south: float
    """y of the grid's south edge in ``crs``."""
    cell_size_m: float
    """Metres per cell."""

    @property
    def real(self) -> bool:
        """Whether the site is a place on the Earth (it has a CRS)."""
        return bool(self.crs)

    def cells_from_lonlat(self, lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grid coordinates (cell units, cell (x, y) spans [x, x+1)) of WGS84 points."""
        to = _transformer("EPSG:4326", self.crs)
        # Lists, not arrays: pyproj reads a one-element array as a scalar point (and warns).
        e, n = to.transform(np.asarray(lon, float).tolist(), np.asarray(lat, float).tolist())
        return (np.asarray(e) - self.west) / self.cell_size_m, (
            np.asarray(n) - self.south
        ) / self.cell_size_m

    def lonlat_from_cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """WGS84 (lon, lat) of grid coordinates (cell centres are at x + 0.5, y + 0.5)."""
        to = _transformer(self.crs, "EPSG:4326")
        e = self.west + np.asarray(x, dtype=float) * self.cell_size_m
        n = self.south + np.asarray(y, dtype=float) * self.cell_size_m
        lon, lat = to.transform(np.atleast_1d(e).tolist(), np.atleast_1d(n).tolist())
        return np.asarray(lon), np.asarray(lat)


_CELLS = GeoRef("", 0.0, 0.0, 1.0)
"""A geo-reference of cell units only: extents of what was given in cells."""


@functools.lru_cache(maxsize=16)
def _transformer(src: str, dst: str) -> Any:
    """One pyproj transformer per pair of CRSs: building one takes milliseconds, and a
    mission converts every waypoint."""
    from pyproj import Transformer

    return Transformer.from_crs(src, dst, always_xy=True)


@dataclass(frozen=True, eq=False)
class Site:
    """A loaded site: its settings, grids and geo-reference (see the module docstring)."""

    name: str
    folder: Path
    settings: SiteSettings
    heights: np.ndarray
    """(X, Y) obstacle heights above the terrain, metres, per cell."""
    blocked: np.ndarray
    """(X, Y, Z) where the UAV cannot be."""
    occluding: np.ndarray
    """(X, Y, Z) what hides the ground."""
    coverable: np.ndarray
    """(X, Y) the cells the task wants seen."""
    area: np.ndarray
    """(X, Y) cells inside the area to cover."""
    no_fly: np.ndarray
    """(X, Y) cells inside a no-fly zone."""
    starts: np.ndarray
    """(k, 3) start cells (x, y, z)."""
    georef: GeoRef
    level_height_m: float
    terrain: np.ndarray
    """(X, Y) the ground's height above sea level, metres (zero on a flat site)."""
    ground: str
    """How the ground was made (a flat site, a DTM, a DSM's estimate), in words."""
    fingerprint: str = field(default="")
    """A digest of the site's files: a run records it, so a changed site is noticed."""

    @property
    def has_terrain(self) -> bool:
        """Whether the ground is not flat (a terrain or surface model was given)."""
        return bool(self.settings.terrain or self.settings.surface)

    def ground_profile(self) -> Any:
        """A :class:`~pirl.world.terrain.GroundProfile`: terrain and surface at any point,
        from the site's own rasters."""
        from pirl.world.terrain import GridFrame, GroundProfile

        g = self.georef
        frame = GridFrame(g.crs, g.west, g.south, g.cell_size_m, self.heights.shape[:2])
        return GroundProfile(self.folder, self.settings, frame, self.terrain, self.heights)

    @property
    def size(self) -> tuple[int, int, int]:
        """Grid size (X, Y, Z)."""
        x, y, z = self.blocked.shape
        return int(x), int(y), int(z)


# -- files --------------------------------------------------------------------------------
def site_folder(path: str | Path) -> Path:
    """The folder of a site given as the folder or its ``site.yaml``; refused in one line when
    there is none."""
    path = Path(path).expanduser()
    if path.is_file() and path.name == SITE_FILE:
        path = path.parent
    if not (path / SITE_FILE).is_file():
        raise ConfigError(f"site {path}: no {SITE_FILE} there (docs/sites.md: the format)")
    return path


def load_site(path: str | Path) -> Site:
    """Read and check the site at ``path`` (its folder or its ``site.yaml``); cached while
    its files are unchanged."""
    folder = site_folder(path).resolve()
    return _load_cached(folder, _fingerprint(folder))


def _fingerprint(folder: Path) -> str:
    import hashlib

    digest = hashlib.sha256()
    for file in sorted(folder.iterdir()):
        if file.is_file():
            stat = file.stat()
            digest.update(f"{file.name}:{stat.st_size}:{stat.st_mtime_ns}".encode())
    return digest.hexdigest()[:16]


@functools.lru_cache(maxsize=8)
def _load_cached(folder: Path, fingerprint: str) -> Site:
    from pirl.config.load import read_yaml
    from pirl.world.terrain import GridFrame, frame_of, read_ground

    settings = SiteSettings.from_dict(read_yaml(folder / SITE_FILE))
    if settings.heights:
        raster = _read_raster(folder, settings)
        georef, heights = _grid_heights(raster, settings)
        frame = GridFrame(
            georef.crs, georef.west, georef.south, georef.cell_size_m, heights.shape[:2]
        )
    else:
        frame = frame_of(folder, settings)
        georef = GeoRef(frame.crs, frame.west, frame.south, frame.cell)
        heights = np.zeros(frame.shape)
    if (settings.terrain or settings.surface) and not georef.real:
        raise ConfigError(
            "site.terrain: a ground model needs a georeferenced grid (a GeoTIFF with a CRS, or "
            "site.origin)"
        )
    ground = read_ground(folder, settings, frame)
    if ground.obstacles is not None:
        heights = ground.obstacles
    cells = heights.shape[0] * heights.shape[1] * settings.levels
    if cells > settings.max_cells:
        raise ConfigError(
            f"site.heights: the grid would hold {cells:,} cells ({heights.shape[0]} x "
            f"{heights.shape[1]} x {settings.levels}), more than site.max_cells="
            f"{settings.max_cells:,}: raise site.cell_size_m or lower site.levels"
        )
    level_m = settings.level_height_m or georef.cell_size_m
    levels = np.ceil(heights / level_m - 1e-9).astype(np.int64)
    z = np.arange(settings.levels)
    building = z[None, None, :] < levels[:, :, None]
    shape = heights.shape
    area = (
        _polygon_mask(folder, settings, "area", georef, shape)
        if settings.area
        else np.ones(shape, dtype=bool)
    )
    no_fly = (
        _polygon_mask(folder, settings, "no_fly", georef, shape)
        if settings.no_fly
        else np.zeros(shape, dtype=bool)
    )
    blocked = building | no_fly[:, :, None]
    ground_free = levels == 0
    coverable = area & (ground_free | settings.roofs)
    starts = _starts(folder, settings, georef, blocked, no_fly, area)
    return Site(
        name=settings.name or folder.name,
        folder=folder,
        settings=settings,
        heights=heights,
        blocked=blocked,
        occluding=building,
        coverable=coverable,
        area=area,
        no_fly=no_fly,
        starts=starts,
        georef=georef,
        level_height_m=float(level_m),
        terrain=ground.terrain,
        ground=ground.note,
        fingerprint=fingerprint,
    )


@dataclass(frozen=True)
class _Raster:
    values: np.ndarray  # (rows, cols), row 0 north
    pixel_m: float
    crs: str
    west: float  # in crs (or metres from the grid's west edge)
    south: float


def _read_raster(folder: Path, s: SiteSettings) -> _Raster:
    path = folder / s.heights
    if not path.is_file():
        raise ConfigError(f"site.heights: {path} does not exist")
    suffix = path.suffix.lower()
    pixel = s.pixel_size_m or s.cell_size_m or DEFAULT_CELL_M
    try:
        if suffix in (".tif", ".tiff"):
            return _read_geotiff(path, s)
        if suffix == ".png":
            from PIL import Image

            with Image.open(path) as img:
                _check_pixels(img.size[1], img.size[0], s)
                if img.mode not in ("L", "I", "I;16", "F"):
                    img = img.convert("L")
                values = np.asarray(img, dtype=np.float64) * s.height_scale_m
        elif suffix == ".csv":
            values = np.loadtxt(path, delimiter=",", ndmin=2, dtype=np.float64)
        else:
            values = np.load(path, allow_pickle=False)
    except ConfigError:
        raise
    except Exception as exc:  # noqa: BLE001 - any reader's failure is the same user mistake
        raise ConfigError(
            f"site.heights: {path.name} is not a readable {suffix[1:]} raster "
            f"({type(exc).__name__}: {str(exc).splitlines()[0][:120] if str(exc) else ''})"
        ) from None
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or min(values.shape) < 1:
        raise ConfigError(f"site.heights: {path.name} must be a 2-D raster, got {values.shape}")
    _check_pixels(values.shape[0], values.shape[1], s)
    crs = ""
    if s.origin:
        crs = local_crs(s.origin)
    return _Raster(values, pixel, crs, 0.0, 0.0)


def _check_pixels(rows: int, cols: int, s: SiteSettings) -> None:
    # Before anything large is read: a raster several times the grid limit is refused
    # (resampling to larger cells may still bring it under; give cell_size_m then).
    if rows * cols > 16 * s.max_cells:
        raise ConfigError(
            f"site.heights: {cols} x {rows} pixels is too large to read (limit "
            f"{16 * s.max_cells:,} pixels, 16 x site.max_cells)"
        )


def _read_geotiff(path: Path, s: SiteSettings) -> _Raster:
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    from pirl.world.terrain import check_north_up

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)  # said below, in one line
        src = rasterio.open(path)
    with src:
        _check_pixels(src.height, src.width, s)
        t = src.transform
        if src.crs is None and t.is_identity:  # a plain raster in a .tif: no geo-reference
            if not s.origin:
                raise ConfigError(
                    f"site.heights: {path.name} has no CRS; give site.origin [lat, lon] of its "
                    "south-west corner"
                )
            band = src.read(1, masked=True).astype(np.float64).filled(np.nan)
            pixel = s.pixel_size_m or s.cell_size_m or DEFAULT_CELL_M
            return _Raster(band, pixel, local_crs(s.origin), 0.0, 0.0)
        check_north_up(src, path.name, "heights")
        band = src.read(1, masked=True).astype(np.float64)
        crs = src.crs
        west, south = t.c, t.f + t.e * src.height
        pixel = abs(t.a)
    values = band.filled(np.nan)
    if crs is None:
        if not s.origin:
            raise ConfigError(
                f"site.heights: {path.name} has no CRS; give site.origin [lat, lon] of its "
                "south-west corner"
            )
        return _Raster(values, s.pixel_size_m or pixel, local_crs(s.origin), 0.0, 0.0)
    return _Raster(values, pixel, crs.to_wkt(), west, south)


def local_crs(origin: tuple[float, ...]) -> str:
    """A metric CRS of metres east and north of ``origin`` (lat, lon)."""
    lat, lon = origin
    # Azimuthal equidistant centred on the south-west corner: metres east and north of it.
    return f"+proj=aeqd +lat_0={lat} +lon_0={lon} +x_0=0 +y_0=0 +datum=WGS84 +units=m +no_defs"


def _grid_heights(raster: _Raster, s: SiteSettings) -> tuple[GeoRef, np.ndarray]:
    values = raster.values
    bad = ~np.isfinite(values)
    if bad.any():
        raise ConfigError(
            f"site.heights: {int(bad.sum()):,} cells are NaN or nodata; fill them (0 for open "
            "ground)"
        )
    if (values < 0).any():
        raise ConfigError(
            f"site.heights: {int((values < 0).sum()):,} cells are negative (lowest "
            f"{values.min():.2f} m): heights are metres above ground (subtract the terrain "
            "from a DSM)"
        )
    grid = values[::-1, :].T  # (x east, y north)
    cell = s.cell_size_m or raster.pixel_m
    if abs(cell - raster.pixel_m) > 1e-9 * cell:
        grid = _resample(grid, raster.pixel_m, cell)
    return GeoRef(raster.crs, raster.west, raster.south, float(cell)), np.ascontiguousarray(grid)


def _resample(grid: np.ndarray, pixel: float, cell: float) -> np.ndarray:
    nx = max(1, math.ceil(grid.shape[0] * pixel / cell - 1e-9))
    ny = max(1, math.ceil(grid.shape[1] * pixel / cell - 1e-9))
    if cell >= pixel:  # larger cells: the highest pixel whose centre lies in each cell
        ix = np.minimum(((np.arange(grid.shape[0]) + 0.5) * pixel / cell).astype(int), nx - 1)
        iy = np.minimum(((np.arange(grid.shape[1]) + 0.5) * pixel / cell).astype(int), ny - 1)
        out = np.zeros((nx, ny))
        np.maximum.at(out, (ix[:, None], iy[None, :]), grid)
        return out
    # smaller cells: the pixel under each cell's centre
    px = np.minimum(((np.arange(nx) + 0.5) * cell / pixel).astype(int), grid.shape[0] - 1)
    py = np.minimum(((np.arange(ny) + 0.5) * cell / pixel).astype(int), grid.shape[1] - 1)
    return grid[px[:, None], py[None, :]]


# -- polygons -----------------------------------------------------------------------------
def read_polygons(path: Path, key: str) -> Any:
    """The union of the Polygon and MultiPolygon geometries of a GeoJSON file (shapely)."""
    import shapely
    from shapely.geometry import shape

    if not path.is_file():
        raise ConfigError(f"site.{key}: {path} does not exist")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ConfigError(f"site.{key}: {path.name} is not GeoJSON ({exc})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"site.{key}: {path.name} is not a GeoJSON object")
    items = data.get("features") if data.get("type") == "FeatureCollection" else [data]
    geoms = []
    for item in items or []:
        geom = item.get("geometry") if isinstance(item, dict) and "geometry" in item else item
        try:
            g = shape(geom)
        except Exception as exc:  # noqa: BLE001 - shapely raises several kinds for bad input
            raise ConfigError(f"site.{key}: {path.name} holds a bad geometry ({exc})") from None
        if g.geom_type not in ("Polygon", "MultiPolygon"):
            raise ConfigError(
                f"site.{key}: {path.name} holds a {g.geom_type}; only Polygon and "
                "MultiPolygon describe areas"
            )
        geoms.append(shapely.make_valid(g))
    if not geoms:
        raise ConfigError(f"site.{key}: {path.name} holds no polygon")
    return shapely.union_all(geoms)


def _polygon_mask(
    folder: Path, s: SiteSettings, key: str, georef: GeoRef, shape: tuple[int, ...]
) -> np.ndarray:
    import shapely

    value = getattr(s, key) if key != "start" else s.start["zone"]
    written = read_polygons(folder / value, key)
    geom = written
    if georef.real:
        geom = shapely.transform(geom, lambda xy: np.stack(georef.cells_from_lonlat(*xy.T), 1))
    xs, ys = np.meshgrid(np.arange(shape[0]) + 0.5, np.arange(shape[1]) + 0.5, indexing="ij")
    mask = shapely.contains_xy(geom, xs.ravel(), ys.ravel()).reshape(shape)
    if not mask.any():
        # Both extents in the file's own coordinates: GeoJSON's longitude/latitude on a
        # georeferenced site, cell units on one without a CRS.
        raise ConfigError(
            f"site.{key}: {value} covers no cell of the {shape[0]} x {shape[1]} grid: it spans "
            f"{_extent(written.bounds, georef)}, the grid {_grid_extent(georef, shape)}"
        )
    return mask


def _extent(bounds: tuple[float, ...], georef: GeoRef) -> str:
    """(min x, min y, max x, max y) in words: lon/lat on a georeferenced site, else cells."""
    x0, y0, x1, y1 = bounds
    if georef.real:
        return f"lon {x0:.6f} to {x1:.6f}, lat {y0:.6f} to {y1:.6f} (WGS84 degrees)"
    return f"x {x0:.6g} to {x1:.6g}, y {y0:.6g} to {y1:.6g} (cell units)"


def _grid_extent(georef: GeoRef, shape: tuple[int, ...]) -> str:
    """The grid's extent in the words of :func:`_extent` (its corners' lon/lat, or cells)."""
    if not georef.real:
        return _extent((0.0, 0.0, float(shape[0]), float(shape[1])), georef)
    xs = np.array([0.0, shape[0], 0.0, shape[0]])
    ys = np.array([0.0, 0.0, shape[1], shape[1]])
    lon, lat = georef.lonlat_from_cells(xs, ys)
    return _extent((lon.min(), lat.min(), lon.max(), lat.max()), georef)


# -- starts -------------------------------------------------------------------------------
def _starts(
    folder: Path,
    s: SiteSettings,
    georef: GeoRef,
    blocked: np.ndarray,
    no_fly: np.ndarray,
    area: np.ndarray,
) -> np.ndarray:
    kind = start_kind(s.start)
    sx, sy, _ = blocked.shape
    if kind in ("cell", "latlon"):
        if kind == "cell":
            x, y = (int(v) for v in s.start)
        else:
            if not georef.real:
                raise ConfigError(
                    "site.start {lat, lon} needs a georeferenced site (a GeoTIFF with a CRS, "
                    "or site.origin)"
                )
            cx, cy = georef.cells_from_lonlat(
                np.array([s.start["lon"]]), np.array([s.start["lat"]])
            )
            x, y = int(math.floor(cx[0])), int(math.floor(cy[0]))
        if not (0 <= x < sx and 0 <= y < sy):
            # In the coordinates it was given in: cells, or latitude/longitude.
            raise ConfigError(
                f"site.start={s.start!r} lies outside the {sx} x {sy} grid, which spans "
                f"{_grid_extent(georef if kind == 'latlon' else _CELLS, (sx, sy))}"
            )
        free = np.flatnonzero(~blocked[x, y])
        if not free.size:
            what = "a no-fly zone" if no_fly[x, y] else "a building (blocked at every level)"
            raise ConfigError(f"site.start={s.start!r}: cell ({x}, {y}) lies inside {what}")
        return np.array([[x, y, int(free[0])]], dtype=np.int64)
    if kind == "box":
        x0, y0, x1, y1 = s.start["zone"]
        zone = np.zeros((sx, sy), dtype=bool)
        zone[max(0, min(x0, x1)) : max(x0, x1) + 1, max(0, min(y0, y1)) : max(y0, y1) + 1] = True
    elif kind == "zone_file":
        zone = _polygon_mask(folder, s, "start", georef, (sx, sy))
    else:
        zone = area
    # Each zone cell at its lowest free level; cells blocked at every level are not starts.
    open_ = ~blocked
    has = open_.any(axis=2) & zone
    if kind == "none":
        has &= open_[:, :, 0]
    xs, ys = np.nonzero(has)
    if not len(xs):
        raise ConfigError(
            f"site.start={s.start!r}: no free cell to start from (every cell of the zone is "
            "inside a building or a no-fly zone)"
        )
    zs = open_[xs, ys].argmax(axis=1)
    return np.stack([xs, ys, zs], axis=1).astype(np.int64)


__all__ = [
    "DEFAULT_CELL_M",
    "SITE_FILE",
    "GeoRef",
    "Site",
    "load_site",
    "local_crs",
    "read_polygons",
    "site_folder",
]
