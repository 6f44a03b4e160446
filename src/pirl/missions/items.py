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


# -- the items --------------------------------------------------------------------------------
@dataclass
class Item:
    """One mission item in grid terms; ``kind`` names it (see
    :func:`~pirl.missions.formats.mavlink_items`)."""

    kind: str  # takeoff, waypoint, gimbal, zoom, capture, trigger, rtl
    cell: tuple[int, int, int] | None = None
    camera: tuple[int, int, int] | None = None
    value: float = 0.0  # trigger: its distance (m); waypoint: photos triggered on the way


# -- on the Earth -----------------------------------------------------------------------------
@dataclass
class Geo:
    """Cells to the Earth: latitude, longitude and altitude above home."""

    georef: Any
    level_m: float
    real: bool
    home: tuple[float, float]

    def lonlat(self, cells: np.ndarray) -> np.ndarray:
        """(n, 2) lon, lat of grid coordinates (cell centres at +0.5)."""
        cells = np.asarray(cells, dtype=float).reshape(-1, 2)
        lon, lat = self.georef.lonlat_from_cells(cells[:, 0], cells[:, 1])
        return np.stack([lon, lat], axis=1)

    def position(self, cell: tuple[int, int, int]) -> tuple[float, float, float]:
        """(lat, lon, altitude above home in metres) of a cell's centre."""
        lon, lat = self.lonlat(np.array([[cell[0] + 0.5, cell[1] + 0.5]]))[0]
        return float(lat), float(lon), (cell[2] + 1) * self.level_m


# -- sorties -----------------------------------------------------------------------------------
@dataclass
class Sortie:
    """One battery's mission: its items (take-off first, return last) and its figures."""

    items: list[Item] = field(default_factory=list)
    seconds: float = 0.0
    distance_m: float = 0.0
    photos: int = 0


__all__ = ["Episode", "Geo", "Item", "Sortie", "Step"]
