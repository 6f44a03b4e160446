"""The map of a world given as voxel grids (a site) rather than drawn from spheres."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class MapGrids(NamedTuple):
    """A site's map as one world takes it: shared by every episode (and every UAV) on it."""

    name: str
    """The site's name (episode rows carry it as ``site``)."""
    blocked: np.ndarray
    """(X, Y, Z) where the UAV cannot be."""
    occluding: np.ndarray
    """(X, Y, Z) what hides the ground from the camera."""
    coverable: np.ndarray
    """(X, Y) the coverable cells some camera pose of a reachable cell sees: what an episode
    counts (VCR over seeable cells)."""
    coverable_all: int
    """Coverable cells of the site, seeable or not (the denominator of ``vcr_all``)."""
    starts: np.ndarray
    """(k, 3) start cells; a seeded reset draws one."""
    ground: np.ndarray | None = None
    """(X, Y) the terrain in levels (metres / ``level_height_m``) where the site has a
    terrain model; None on flat ground."""


__all__ = ["MapGrids"]
