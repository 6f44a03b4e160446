"""Missions over terrain: waypoints that hold a height above the ground, and every leg
checked for clearance above the surface.

On a site with a terrain model (:mod:`pirl.world.terrain`) a level is a height above the
ground, so a straight leg between two waypoints would cut into a rise or float off a fall.
In the ``amsl`` and ``relative`` frames (``mission.altitude_frame``) a leg gets points
inserted where the ground under it departs from the leg's height above ground by more than
``mission.terrain_tolerance_m`` (the farthest sample first, until every sample is within the
tolerance: Douglas-Peucker on the height profile, sampled every metre from the site's own
DTM). In the ``terrain`` frame (``MAV_FRAME_GLOBAL_TERRAIN_ALT``) the autopilot follows the
ground itself and no point is inserted. Then every leg of every sortie is sampled every metre
(along the straight line an autopilot flies between waypoints) and its clearance above the
DSM is checked against ``mission.min_clearance_m``; a plan that comes closer is refused in
one line, naming where.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.mission import ALTITUDE_FRAMES, MissionSettings
from pirl.missions.items import Geo, Item, Point, Sortie

SAMPLE_M = 1.0
"""Metres between the samples of a leg's profile (insertion and the clearance check)."""


def altitude_frame(s: MissionSettings, has_terrain: bool) -> str:
    """The frame a mission's heights are written in: ``mission.altitude_frame``, or by
    default ``amsl`` on a site with a terrain model and ``relative`` elsewhere. A frame
    above sea level or the terrain needs a terrain model (one line otherwise)."""
    frame = s.altitude_frame or ("amsl" if has_terrain else "relative")
    if frame != "relative" and not has_terrain:
        raise ConfigError(
            f"mission.altitude_frame={frame}: needs a site with a terrain or surface model "
            f"(this one is flat ground); allowed here: relative (of {', '.join(ALTITUDE_FRAMES)})"
        )
    return frame


def _samples(a: Point, b: Point, cell_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, x, y) of points every :data:`SAMPLE_M` metres from a to b, both ends included."""
    n = max(1, math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) * cell_m / SAMPLE_M))
    t = np.linspace(0.0, 1.0, n + 1)
    return t, a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])


def via_points(geo: Geo, a: Point, b: Point, tolerance_m: float) -> list[Point]:
    """Points to insert on the level leg a -> b so that the straight lines between them stay
    within ``tolerance_m`` of the leg's height above the terrain; none on flat ground, in the
    terrain frame, or on a vertical leg."""
    if geo.ground is None or geo.frame == "terrain" or a[2] != b[2] or a[:2] == b[:2]:
        return []
    t, x, y = _samples(a, b, geo.georef.cell_size_m)
    want = geo.ground.terrain(x, y)  # the wanted height less the leg's constant height above it
    keep = {0, len(t) - 1}
    stack = [(0, len(t) - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        line = want[i] + (want[j] - want[i]) * (t[i : j + 1] - t[i]) / (t[j] - t[i])
        err = np.abs(line - want[i : j + 1])
        k = int(err.argmax())
        if err[k] > tolerance_m:
            keep.add(i + k)
            stack += [(i, i + k), (i + k, j)]
    return [(float(x[k]), float(y[k]), a[2]) for k in sorted(keep)[1:-1]]


def follow_ground(items: list[Item], start: Point, geo: Geo, s: MissionSettings) -> list[Item]:
    """``items`` with waypoints inserted along every level leg where the ground departs from
    its height by more than ``mission.terrain_tolerance_m``."""
    if geo.ground is None or geo.frame == "terrain":
        return items
    out: list[Item] = []
    where = start
    for item in items:
        if item.kind == "waypoint":
            to = item.point()
            for p in via_points(geo, where, to, s.terrain_tolerance_m):
                out.append(Item("waypoint", item.cell, xy=(p[0], p[1])))
            where = to
        out.append(item)
    return out


class WayHome:
    """The ways between home and any free cell over terrain, through the grid's free cells
    (a breadth-first field from home over the site's ``blocked`` voxels, 6-neighbour): a
    straight line home at one level could cross a building or a copse the plan went round.
    """

    def __init__(self, blocked: np.ndarray, home: tuple[int, int, int]) -> None:
        from collections import deque

        self.home = home
        self.blocked = blocked
        dist = np.full(blocked.shape, -1, dtype=np.int64)
        dist[home] = 0
        queue = deque([home])
        sx, sy, sz = blocked.shape
        while queue:
            x, y, z = queue.popleft()
            for dx, dy, dz in _STEPS:
                n = (x + dx, y + dy, z + dz)
                inside = 0 <= n[0] < sx and 0 <= n[1] < sy and 0 <= n[2] < sz
                if inside and dist[n] < 0 and not blocked[n]:
                    dist[n] = dist[x, y, z] + 1
                    queue.append(n)
        self.dist = dist

    def corners(self, cell: tuple[int, int, int]) -> list[tuple[int, int, int]]:
        """The cells where the way from ``cell`` home turns, home last (empty at home)."""
        if self.dist[cell] < 0:
            raise ConfigError(f"cell {cell}: no way home through free cells (a closed pocket)")
        path, here, heading = [], cell, None
        while here != self.home:
            d = self.dist[here]
            steps = [st for st in _STEPS if self._dist(here, st) == d - 1]
            step = heading if heading in steps else steps[0]  # keep straight where it can
            if heading is not None and step != heading:
                path.append(here)
            heading = step
            here = (here[0] + step[0], here[1] + step[1], here[2] + step[2])
        return [*path, self.home]

    def _dist(self, c: tuple[int, int, int], st: tuple[int, int, int]) -> int:
        n = (c[0] + st[0], c[1] + st[1], c[2] + st[2])
        if all(0 <= v < s for v, s in zip(n, self.dist.shape, strict=True)):
            return int(self.dist[n])
        return -1


_STEPS = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))
"""Grid moves, level moves last: a way home changes level only where it must."""


def sampled_legs(
    parts: list[Sortie], geo: Geo
) -> Iterator[tuple[int, int, bool, int, np.ndarray, np.ndarray, np.ndarray]]:
    """Every leg of every sortie sampled every metre: (sortie, item, level leg, level, x, y,
    height above sea level). A leg is the straight line an autopilot flies between waypoints
    (in the terrain frame a level leg holds its height above the ground instead); the first
    starts above home at the take-off's level."""
    home = geo.home_point
    for n, sortie in enumerate(parts, start=1):
        where: Point | None = None
        for k, item in enumerate(sortie.items, start=1):
            if item.kind not in ("takeoff", "waypoint"):
                continue
            to = item.point() if item.kind == "waypoint" else (home[0], home[1], item.cell[2])
            a = where or (home[0], home[1], to[2])
            t, x, y = _samples(a, to, geo.georef.cell_size_m)
            level = a[2] == to[2]
            if geo.frame == "terrain" and level:
                alt = geo.ground.terrain(x, y) + geo.agl(to[2])
            else:
                alt = geo.amsl(a) + t * (geo.amsl(to) - geo.amsl(a))
            yield n, k, level, to[2], x, y, alt
            where = to


def check_profile(parts: list[Sortie], geo: Geo, s: MissionSettings) -> dict[str, Any]:
    """Sample every leg of every sortie every metre (:func:`sampled_legs`) against the site's
    own terrain and surface; refuse a plan closer than ``mission.min_clearance_m`` to the
    surface. Returns the figures that ``summary.json`` keeps under ``terrain``."""
    worst_clearance, worst_error, samples = math.inf, 0.0, 0
    for n, k, level, z, x, y, alt in sampled_legs(parts, geo):
        clearance = alt - geo.ground.surface(x, y)
        samples += len(x)
        low = int(clearance.argmin())
        if clearance[low] < s.min_clearance_m:
            lat, lon, _ = geo.position((0, 0, z), xy=(float(x[low]), float(y[low])))
            raise ConfigError(
                f"mission.min_clearance_m={s.min_clearance_m:g}: sortie {n}, item {k} passes "
                f"{clearance[low]:.1f} m above the surface model at lat {lat:.6f}, lon "
                f"{lon:.6f}; fly higher levels or raise site.level_height_m; nothing written"
            )
        worst_clearance = min(worst_clearance, float(clearance[low]))
        if level and geo.frame != "terrain":
            agl = alt - geo.ground.terrain(x, y)
            worst_error = max(worst_error, float(np.abs(agl - geo.agl(z)).max()))
    return {
        "frame": geo.frame,
        "tolerance_m": s.terrain_tolerance_m,
        "max_height_error_m": round(worst_error, 3),
        "min_clearance_m": round(worst_clearance, 2),
        "samples": samples,
        "sample_every_m": SAMPLE_M,
        "inserted_points": sum(1 for sortie in parts for i in sortie.items if i.xy is not None),
    }


def profile_figure(parts: list[Sortie], geo: Geo, path: Path) -> Path:
    """``profile.png``: the flight's height above sea level along its path against the
    terrain (DTM) and the surface (DSM) under it, sortie after sortie. Written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pirl._atomic import replacing

    dist, alt, ground, surface = [], [], [], []
    along = 0.0
    for *_, x, y, a in sampled_legs(parts, geo):
        step = np.hypot(np.diff(x, prepend=x[0]), np.diff(y, prepend=y[0]))
        dist.append(along + np.cumsum(step) * geo.georef.cell_size_m)
        along = float(dist[-1][-1])
        alt.append(a)
        ground.append(geo.ground.terrain(x, y))
        surface.append(geo.ground.surface(x, y))
    d, a, g, sf = (np.concatenate(v) for v in (dist, alt, ground, surface))
    fig, ax = plt.subplots(figsize=(10, 3.2), dpi=110)
    ax.fill_between(d, g.min() - 5, sf, color="#bbbbbb", label="surface (DSM)", step="mid")
    ax.fill_between(d, g.min() - 5, g, color="#8c6d46", label="terrain (DTM)")
    ax.plot(d, a, color="#1f5fbf", lw=0.9, label=f"flight ({geo.frame} frame)")
    ax.set_xlim(0, d[-1])
    ax.set_ylim(g.min() - 5, max(a.max(), sf.max()) + 5)
    ax.set_xlabel("metres flown (horizontally)")
    ax.set_ylabel("metres above sea level")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    with replacing(Path(path)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


__all__ = [
    "SAMPLE_M",
    "WayHome",
    "altitude_frame",
    "check_profile",
    "follow_ground",
    "profile_figure",
    "sampled_legs",
    "via_points",
]
