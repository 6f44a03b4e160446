"""Geometric planning queries on one world: shortest free paths, useful views, best camera.

Shared by the boustrophedon planner (a policy) and the oracle advisor (advice from geometry),
so both read the map the same way. A :class:`WorldView` is one world's map and pose, either
live (arrays shared with the batch, for a planner acting now) or a frozen copy (for advice
computed later in another thread).
"""

from __future__ import annotations

import functools
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numba
import numpy as np

from pirl.config.world import VCPPConfig
from pirl.world import dynamics as D
from pirl.world.footprint import (
    NO_GROUND,
    CameraPose,
    buffer_rows,
    footprint_cells,
    footprint_model,
    lens_of,
)
from pirl.world.state import WorldBatch

Cell = tuple[int, int, int]
Camera = tuple[int, int, int]  # tilt degrees, pan degrees, zoom tenths

# Move deltas in action order (actions 0-5): the rules' own table.
MOVE_DELTAS: tuple[Cell, ...] = D.MOVE_DELTAS


@dataclass
class WorldView:
    """One world's map and pose. ``views`` counts how often each ground cell was seen."""

    cfg: VCPPConfig
    blocked: np.ndarray
    coverable: np.ndarray
    views: np.ndarray
    obstacles: np.ndarray
    occluding: np.ndarray
    ground: np.ndarray
    position: Cell
    camera: Camera
    energy: float
    teammates: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """(k, 4) rows (x, y, z, battery share) of the UAVs flying beside this one (a fleet's),
    in slot order; none for one UAV."""
    rank: int = 0
    """How many of :attr:`teammates` come before this UAV in slot order."""

    @classmethod
    def of(cls, world: WorldBatch, e: int, copy: bool = False) -> WorldView:
        """Slot ``e``'s view (its world's map, its UAV's pose): live arrays (``copy=False``)
        or a frozen snapshot."""
        take = (lambda a: a.copy()) if copy else (lambda a: a)
        g = world.world_of(e)
        return cls(
            cfg=world.cfg,
            blocked=take(world.blocked[g]),
            coverable=take(world.coverable[g]),
            views=take(world.views[g]),
            obstacles=world.obstacle_list(e),
            occluding=take(world.occluding[g]),
            ground=take(world.ground[g]),
            position=world.position(e),
            camera=world.camera_setting(e),
            energy=float(world.energy[e]),
            teammates=world.teammates(e),
            rank=world.rank(e),
        )

    def footprint(self, pose: Cell, camera: Camera) -> np.ndarray:
        """Ground cells (k, 2) seen from ``pose`` with ``camera``."""
        cfg = self.cfg
        model = footprint_model(cfg.footprint)
        lens = lens_of(model, cfg.size, cfg.fov_deg, cfg.max_range, cfg.occlusion)
        buf = np.empty((buffer_rows(model, cfg.max_range), 2), dtype=np.int64)
        at = CameraPose(*(int(v) for v in pose), *(int(v) for v in camera))
        n = footprint_cells(
            lens, at, np.asarray(self.obstacles, dtype=np.float64), self.occluding, self.ground,
            buf,
        )  # fmt: skip
        return buf[:n]

    def useful(self, pose: Cell, camera: Camera) -> bool:
        """Whether the view from ``pose`` would see a coverable cell not yet covered."""
        fp = self.footprint(pose, camera)
        if not len(fp):
            return False
        i, j = fp[:, 0], fp[:, 1]
        return bool((self.coverable[i, j] & (self.views[i, j] == 0)).any())

    def free(self, cell: Cell) -> bool:
        """Inside the grid, not blocked, and no teammate there (a move into it is masked)."""
        sx, sy, sz = self.cfg.size
        x, y, z = cell
        if not (0 <= x < sx and 0 <= y < sy and 0 <= z < sz) or self.blocked[x, y, z]:
            return False
        return not self.teammates.size or cell not in self.teammate_cells

    @functools.cached_property
    def teammate_cells(self) -> frozenset[Cell]:
        """The cells the teammates hold."""
        return frozenset((int(r[0]), int(r[1]), int(r[2])) for r in self.teammates)

    def neighbours(self, cell: Cell) -> Iterator[Cell]:
        """Free cells one move away, in action order."""
        x, y, z = cell
        for dx, dy, dz in MOVE_DELTAS:
            n = (x + dx, y + dy, z + dz)
            if self.free(n):
                yield n


def _unwind(parent: dict[Cell, Cell | None], cell: Cell) -> list[Cell]:
    path = [cell]
    while parent[path[-1]] is not None:
        path.append(parent[path[-1]])
    return path[::-1]


def bfs_path(view: WorldView, start: Cell, goal: Cell) -> list[Cell] | None:
    """Shortest free path start -> goal (both included), or None when unreachable."""
    if start == goal:
        return [start]
    parent: dict[Cell, Cell | None] = {start: None}
    queue = deque([start])
    while queue:
        cell = queue.popleft()
        for n in view.neighbours(cell):
            if n in parent:
                continue
            parent[n] = cell
            if n == goal:
                return _unwind(parent, n)
            queue.append(n)
    return None


def nearest(view: WorldView, start: Cell, accept: Callable[[Cell], bool]) -> list[Cell] | None:
    """Shortest free path from ``start`` to the nearest other cell ``accept`` takes, or None."""
    parent: dict[Cell, Cell | None] = {start: None}
    queue = deque([start])
    while queue:
        cell = queue.popleft()
        if cell != start and accept(cell):
            return _unwind(parent, cell)
        for n in view.neighbours(cell):
            if n not in parent:
                parent[n] = cell
                queue.append(n)
    return None


def claims(view: WorldView) -> np.ndarray:
    """(X, Y, Z) int32: for each free cell, the UAV nearest to it by moves (its index in slot
    order among the view's UAV and its teammates; -1 where none reaches). Ties go to the
    earlier UAV in slot order, so every UAV of a fleet draws the same borders."""
    me = np.array([view.position], dtype=np.int64)
    team = view.teammates[:, :3].astype(np.int64)
    sources = np.concatenate([team[: view.rank], me, team[view.rank :]])
    return _claim(view.blocked, sources, D.MOVES)


@numba.njit(cache=True)
def _claim(blocked, sources, moves):
    """Breadth-first search from every source at once, in source order, by ``moves``."""
    sx, sy, sz = blocked.shape
    owner = np.full((sx, sy, sz), -1, dtype=np.int32)
    queue = np.empty((sx * sy * sz, 3), dtype=np.int64)
    head = tail = 0
    for i in range(sources.shape[0]):
        x, y, z = sources[i, 0], sources[i, 1], sources[i, 2]
        if owner[x, y, z] < 0:
            owner[x, y, z] = i
            queue[tail] = sources[i]
            tail += 1
    while head < tail:
        x, y, z = queue[head, 0], queue[head, 1], queue[head, 2]
        head += 1
        for d in range(moves.shape[0]):
            i, j, k = x + moves[d, 0], y + moves[d, 1], z + moves[d, 2]
            inside = 0 <= i < sx and 0 <= j < sy and 0 <= k < sz
            if inside and not blocked[i, j, k] and owner[i, j, k] < 0:
                owner[i, j, k] = owner[x, y, z]
                queue[tail, 0], queue[tail, 1], queue[tail, 2] = i, j, k
                tail += 1
    return owner


def camera_action(current: Camera, target: Camera) -> int | None:
    """The camera action that brings (tilt, pan, zoom10) one step closer to ``target``."""
    (tilt, pan, zoom10), (want_tilt, want_pan, want_zoom) = current, target
    if tilt != want_tilt:
        return D.TILT_PLUS if tilt < want_tilt else D.TILT_MINUS
    if pan != want_pan:
        return D.PAN_PLUS if pan < want_pan else D.PAN_MINUS
    if zoom10 != want_zoom:
        return D.ZOOM_PLUS if zoom10 < want_zoom else D.ZOOM_MINUS
    return None


def largest_footprint_camera(view: WorldView) -> tuple[Camera, int]:
    """Camera (tilt, pan 0, zoom10) and altitude whose footprint is largest.

    Ties go to the setting cheapest to reach from the current camera and altitude. Altitude is
    searched only for the frustum model (it does not matter in the paper model). Obstacles are
    ignored: the choice is about the camera, not about one scene.
    """
    return _largest_footprint_camera(view.cfg, view.position[2], tuple(view.camera))


@functools.lru_cache(maxsize=4096)
def _largest_footprint_camera(cfg: VCPPConfig, z: int, camera: Camera) -> tuple[Camera, int]:
    sx, sy, sz = cfg.size
    tilt0, pan0, zoom0 = camera
    empty = WorldView(
        cfg, np.zeros((0, 0, 0), bool), np.zeros((0, 0), bool), np.zeros((0, 0), np.int32),
        np.zeros((0, 4)), np.zeros((0, 0, 0), bool), NO_GROUND, (0, 0, z), camera, 0.0,
    )  # fmt: skip
    centre = (sx // 2, sy // 2)
    altitudes = [z] if cfg.footprint == "paper" else range(sz)
    best, best_key = ((tilt0, pan0, zoom0), z), None
    for alt in altitudes:
        for tilt in range(0, 91, 5):
            for zoom10 in range(5, 21):
                n = len(empty.footprint((*centre, alt), (tilt, 0, zoom10)))
                steps = abs(tilt - tilt0) // 5 + abs(zoom10 - zoom0) + abs(pan0) // 15
                cost = steps * cfg.energy_camera + abs(alt - z) * cfg.energy_climb
                key = (n, -cost)
                if best_key is None or key > best_key:
                    best, best_key = ((tilt, 0, zoom10), alt), key
    return best


def useful_map(view: WorldView, camera: Camera, altitude: int) -> np.ndarray:
    """Boolean (X, Y): positions at ``altitude`` whose view would add an uncovered cell.

    The footprint is taken at the grid centre and translated (exact for the paper model away
    from the borders; for the frustum model it ignores occlusion, which is fine for advice).
    """
    sx, sy, _ = view.cfg.size
    cx, cy = sx // 2, sy // 2
    offsets = view.footprint((cx, cy, altitude), camera) - np.array([cx, cy])
    todo = view.coverable & (view.views == 0)
    out = np.zeros_like(todo)
    _dilate(todo, offsets, out)
    return out


@numba.njit(cache=True)
def _dilate(todo, offsets, out):
    """out[x, y] = any(todo[x + dx, y + dy] for (dx, dy) in offsets, inside the grid)."""
    sx, sy = todo.shape
    for x in range(sx):
        for y in range(sy):
            for k in range(offsets.shape[0]):
                i, j = x + offsets[k, 0], y + offsets[k, 1]
                if 0 <= i < sx and 0 <= j < sy and todo[i, j]:
                    out[x, y] = True
                    break
