"""The data of a mission: the episode it is written from, its items, its sorties and where
its cells are on the Earth.

:mod:`pirl.missions.write` records an :class:`Episode` and turns it into :class:`Item` s split
into :class:`Sortie` s, placed by a :class:`Geo`; :mod:`pirl.missions.formats` writes them as
files and :mod:`pirl.missions.fly` reads them back through the same :class:`Geo`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


# -- the episode ------------------------------------------------------------------------------
@dataclass
class Step:
    """One grid step: where the UAV ended, its camera, whether its view added cells."""

    cell: tuple[int, int, int]
    camera: tuple[int, int, int]
    captured: bool
    footprint: np.ndarray  # (k, 2) cells seen, when captured


@dataclass
class Episode:
    """The episode a mission is written from."""

    start: tuple[int, int, int]
    camera: tuple[int, int, int]
    first_view: np.ndarray
    steps: list[Step]
    metrics: dict[str, float]

    def start_point(self) -> tuple[float, float, int]:
        """The start cell's centre at its level."""
        return (self.start[0] + 0.5, self.start[1] + 0.5, self.start[2])


# -- the items --------------------------------------------------------------------------------
Point = tuple[float, float, int]
"""A point of the flight: grid x, y (cell units; a cell's centre is at +0.5) and its level."""


@dataclass
class Item:
    """One mission item in grid terms; ``kind`` names it (see
    :func:`~pirl.missions.formats.mavlink_items`)."""

    kind: str  # takeoff, waypoint, gimbal, zoom, capture, trigger, rtl
    cell: tuple[int, int, int] | None = None
    camera: tuple[int, int, int] | None = None
    value: float = 0.0  # trigger: its distance (m); waypoint: photos triggered on the way
    xy: tuple[float, float] | None = None
    """A waypoint between cell centres (one inserted to follow the terrain), in grid units;
    None = the centre of ``cell``."""

    def point(self) -> Point:
        """Where the item is: its ``xy`` or its cell's centre, at its cell's level."""
        assert self.cell is not None
        x, y = self.xy if self.xy is not None else (self.cell[0] + 0.5, self.cell[1] + 0.5)
        return (x, y, self.cell[2])


# -- on the Earth -----------------------------------------------------------------------------
@dataclass
class Geo:
    """Cells to the Earth: latitude, longitude and the height written in ``frame``: above
    home (``relative``), above sea level (``amsl``) or above the terrain (``terrain``).
    Level z flies (z + 1) x ``level_m`` above the ground under it (the terrain where the site
    has a model, flat ground otherwise)."""

    georef: Any
    level_m: float
    real: bool
    home: tuple[float, float]
    frame: str = "relative"
    ground: Any = None
    """The site's :class:`~pirl.world.terrain.GroundProfile`; None on flat ground."""
    home_point: Point = (0.5, 0.5, 0)
    """Where the UAV takes off (its start cell's centre)."""
    home_ground_m: float = 0.0
    """The terrain at home, metres above sea level (0 on flat ground)."""
    way_home: Any = None
    """Over terrain, the :class:`~pirl.missions.terrain.WayHome` through free cells."""

    def agl(self, z: int) -> float:
        """Level z's height above the ground under it, metres."""
        return (z + 1) * self.level_m

    def amsl(self, p: Point) -> float:
        """The height above sea level of point p (on flat ground: above the ground)."""
        ground = 0.0 if self.ground is None else float(self.ground.terrain([p[0]], [p[1]])[0])
        return ground + self.agl(p[2])

    def lonlat(self, cells: np.ndarray) -> np.ndarray:
        """(n, 2) lon, lat of grid coordinates (cell centres at +0.5)."""
        cells = np.asarray(cells, dtype=float).reshape(-1, 2)
        lon, lat = self.georef.lonlat_from_cells(cells[:, 0], cells[:, 1])
        return np.stack([lon, lat], axis=1)

    def position(
        self, cell: tuple[int, int, int], xy: tuple[float, float] | None = None
    ) -> tuple[float, float, float]:
        """(lat, lon, height in :attr:`frame`, metres) of a cell's centre, or of point ``xy``
        at the cell's level."""
        x, y = xy if xy is not None else (cell[0] + 0.5, cell[1] + 0.5)
        lon, lat = self.lonlat(np.array([[x, y]]))[0]
        if self.ground is None or self.frame == "terrain":
            return float(lat), float(lon), self.agl(cell[2])
        amsl = self.amsl((x, y, cell[2]))
        return float(lat), float(lon), amsl if self.frame == "amsl" else amsl - self.home_ground_m


# -- sorties -----------------------------------------------------------------------------------
@dataclass
class Sortie:
    """One battery's mission: its items (take-off first, return last) and its figures."""

    items: list[Item] = field(default_factory=list)
    seconds: float = 0.0
    distance_m: float = 0.0
    photos: int = 0


__all__ = ["Episode", "Geo", "Item", "Point", "Sortie", "Step"]
