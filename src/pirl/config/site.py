"""Settings of a site: the ``site.yaml`` of a site folder (docs/sites.md).

A site is a real place to cover: a raster of obstacle heights (or a terrain and a surface
model in metres above sea level), the area to cover, no-fly zones and where the UAV
starts. Files named here are relative to the site folder.
:mod:`pirl.world.site` turns these settings into the voxel grids of a world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pirl.config.errors import ConfigError
from pirl.config.load import Settings

RASTER_SUFFIXES = (".png", ".csv", ".npy", ".tif", ".tiff")
"""The height rasters a site reads: grey PNG, CSV, NumPy array, GeoTIFF."""


@dataclass(frozen=True)
class SiteSettings(Settings, section="site"):
    """Every key of a ``site.yaml``."""

    name: str = ""
    """The site's name in reports and episode rows; empty = the folder's name."""
    heights: str = ""
    """Raster of obstacle heights above ground, metres: ``.png`` (grey value times
    ``height_scale_m``), ``.csv``, ``.npy`` or a GeoTIFF ``.tif`` (its CRS and transform
    georeference the site). Row 0 is the north edge. Required unless ``terrain`` or
    ``surface`` is given."""
    terrain: str = ""
    """GeoTIFF of the bare ground (a DTM), metres above sea level, in any metric CRS: read onto
    the site's grid with rasterio (bilinear). Levels then follow it: level z flies
    (z + 1) x ``level_height_m`` above the terrain under the UAV (docs/sites.md)."""
    surface: str = ""
    """GeoTIFF of the surface (a DSM: ground plus trees and buildings), metres above sea level,
    in any metric CRS, read onto the grid taking the highest pixel (an obstacle never shrinks).
    With ``terrain``, obstacles are ``surface - terrain``; alone, the terrain is estimated from
    it (a grey-scale opening over ``ground_window_m``). Not with ``heights``."""
    min_obstacle_m: float = 1.0
    """Surface above the terrain by less than this is ground, not an obstacle (DEM noise,
    grass, cars)."""
    ground_window_m: float = 40.0
    """A DSM without a DTM: the width of the opening that estimates the ground; wider than
    the widest building, narrower than the narrowest hill top."""
    height_scale_m: float = 1.0
    """PNG rasters: metres per grey level."""
    pixel_size_m: float = 0.0
    """Metres per raster pixel for PNG, CSV and NumPy rasters (a GeoTIFF says its own);
    0 = ``cell_size_m``, so one pixel is one cell."""
    cell_size_m: float = 0.0
    """Metres per grid cell; 0 = the raster's pixel size (one pixel, one cell; 10 m when
    neither is given). Another size resamples: a cell takes the highest pixel whose centre
    lies in it, so an obstacle never shrinks away."""
    level_height_m: float = 0.0
    """Metres between flight levels; 0 = ``cell_size_m``. A cell of height h is blocked from
    the ground up to ceil(h / level_height_m) levels."""
    levels: int = 3
    """Flight levels (the grid's Z)."""
    origin: tuple[float, ...] = ()
    """(lat, lon) of the grid's south-west corner for a raster without a CRS; then GeoJSON
    files are in longitude/latitude. Without a CRS or an origin they are in cell units
    (x east, y north; cell (x, y) spans [x, x+1) x [y, y+1))."""
    area: str = ""
    """GeoJSON polygon(s) of the area to cover; empty = the whole raster."""
    no_fly: str = ""
    """GeoJSON polygon(s) blocked at every altitude (they do not hide the ground)."""
    start: Any = None
    """Where episodes start: a cell ``[x, y]`` (at its lowest free level), ``{lat: .., lon:
    ..}``, or ``{zone: [x0, y0, x1, y1]}`` (cells, inclusive) or ``{zone: FILE.geojson}``, from
    which evaluation draws seeded starts. Empty = every free ground cell of the area."""
    roofs: bool = False
    """Whether building tops count as cells to cover (seen from above, not hidden by their
    own building); by default only the free ground of the area does."""
    max_cells: int = 4_194_304
    """Refuse a grid of more cells (X * Y * Z) than this: 2048 x 2048 x 1, or 724 x 724 x 8."""

    def validate(self) -> None:
        """Files with known suffixes, positive sizes, a (lat, lon) origin, a known start."""
        if not (self.heights or self.terrain or self.surface):
            raise ConfigError(
                "site.heights is missing: name the height raster, or a terrain or surface "
                "model (docs/sites.md)"
            )
        if self.heights and not self.heights.lower().endswith(RASTER_SUFFIXES):
            raise self.refuse("heights", f"expected one of {', '.join(RASTER_SUFFIXES)}")
        if self.heights and self.surface:
            raise self.refuse(
                "surface", "give heights (obstacles above the ground) or surface, not both"
            )
        for key in ("terrain", "surface"):
            if getattr(self, key) and not getattr(self, key).lower().endswith((".tif", ".tiff")):
                raise self.refuse(key, "expected a GeoTIFF (.tif or .tiff) with a CRS")
        for key in (
            "height_scale_m", "pixel_size_m", "cell_size_m", "level_height_m", "min_obstacle_m",
            "ground_window_m",
        ):  # fmt: skip
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise self.refuse(key, "must be a number >= 0")
        if not self.height_scale_m > 0:
            raise self.refuse("height_scale_m", "must be > 0")
        if not 3 <= self.levels <= 64:
            raise self.refuse("levels", "allowed range is 3-64")
        self.require_positive("max_cells")
        if self.origin and (
            len(self.origin) != 2
            or not -90 <= self.origin[0] <= 90
            or not -180 <= self.origin[1] <= 180
        ):
            raise self.refuse("origin", "expected [lat, lon] in degrees")
        for key in ("area", "no_fly"):
            value = getattr(self, key)
            if value and not value.lower().endswith((".geojson", ".json")):
                raise self.refuse(key, "expected a GeoJSON file (.geojson or .json)")
        start_kind(self.start)


def start_kind(start: Any) -> str:
    """What ``site.start`` names: ``none``, ``cell``, ``latlon``, ``box`` or ``zone_file``;
    anything else is refused in one line."""
    if start is None or start == "" or start == {}:
        return "none"
    if isinstance(start, list | tuple):
        if len(start) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in start):
            return "cell"
    elif isinstance(start, dict):
        if set(start) == {"lat", "lon"} and all(
            isinstance(start[k], int | float) and not isinstance(start[k], bool) for k in start
        ):
            return "latlon"
        if set(start) == {"zone"}:
            zone = start["zone"]
            if isinstance(zone, str) and zone.lower().endswith((".geojson", ".json")):
                return "zone_file"
            if (
                isinstance(zone, list)
                and len(zone) == 4
                and all(isinstance(v, int) and not isinstance(v, bool) for v in zone)
            ):
                return "box"
    raise ConfigError(
        f"site.start={start!r}: expected a cell [x, y], {{lat: .., lon: ..}}, "
        "{zone: [x0, y0, x1, y1]} or {zone: FILE.geojson}"
    )


__all__ = ["RASTER_SUFFIXES", "SiteSettings", "start_kind"]
