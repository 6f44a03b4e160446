"""Boustrophedon (lawnmower) coverage planner: the practitioner's baseline and a test oracle.

Not learned and not an LLM. With the obstacle map known, it

1. sets the camera (and, for the frustum model, the altitude) to the largest footprint,
2. sweeps lanes along x, spaced by the footprint's width across the lane, in serpentine order,
   skipping lane points whose view would add nothing,
3. then visits, nearest first, any place from which an uncovered cell is still visible,

moving along shortest free paths (replanned when wind pushes it off), so it goes around
obstacles. It never plans a leg it cannot pay for: a target whose path costs more energy than
is left is dropped.

A fleet (``env.uavs`` > 1) runs one planner per UAV, each given its piece of the sweep one UAV
would fly (:func:`pirl.world.split.cut_sweep`: consecutive pieces that finish together) and
the ground that piece sees first: it sweeps its own piece, then helps with whatever is left
anywhere; a teammate in the way is an obstacle for that step's path (:func:`fleet_planners`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from pirl.agents.policy import Policy, hold_action
from pirl.world.planning import (
    MOVE_DELTAS,
    Cell,
    WorldView,
    bfs_path,
    camera_action,
    largest_footprint_camera,
    nearest,
    useful_map,
)
from pirl.world.split import UNREACHABLE, cut_sweep, geodesic, owner_by_anchor
from pirl.world.state import WorldBatch

_MOVE_ACTION = {delta: action for action, delta in enumerate(MOVE_DELTAS)}


def move_action(a: Cell, b: Cell) -> int:
    """The move action from cell ``a`` to the adjacent cell ``b``."""
    return _MOVE_ACTION[(b[0] - a[0], b[1] - a[1], b[2] - a[2])]


class BoustrophedonPolicy(Policy):
    """Lawnmower sweep with lane spacing from the footprint, detours and a mop-up phase."""

    name = "boustrophedon"
    label = "boustrophedon (planner, not learned)"

    def __init__(self, part: np.ndarray | None = None, lanes: list[Cell] | None = None) -> None:
        self.world: WorldBatch | None = None
        self.part = part
        """(X, Y) ground cells this UAV sweeps first (a fleet's); None: all of them."""
        self.lanes = lanes
        """Its lane points in flying order (a fleet's piece of the sweep); None: the sweep."""

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        self.world, self.e = world, index
        self.own = self.part
        view = WorldView.of(world, index)
        self.camera, self.altitude = largest_footprint_camera(view)
        self.waypoints = self._lanes(view)
        self.next_wp = 0
        self.path: list[Cell] = []
        self.target: Cell | None = None
        self.sweeping = True

    def _lanes(self, view: WorldView) -> list[Cell]:
        """Serpentine lane points along x at the sweep altitude, spaced by the footprint's
        width across the lane, or a fleet's piece of such a sweep."""
        if self.lanes is not None:
            return list(self.lanes)
        return _serpentine(_lane_rows(view, self.camera, self.altitude, axis=0))

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        if self.world is None:
            raise RuntimeError("call reset(world, index) before act()")
        view = self._view()
        action = camera_action(view.camera, self.camera)
        if action is not None:
            return action
        pos = view.position
        for _ in range(3):
            stale = self.target is None or pos == self.target
            if stale or not view.useful(self.target, self.camera):
                self.target, self.path = self._next_target(view, pos)
                if self.target is None:
                    break
            # A teammate may stand on the way now (a fleet's): plan round it.
            blocked_ahead = len(self.path) > 1 and not view.free(self.path[1])
            if not self.path or self.path[0] != pos or blocked_ahead:
                self.path = bfs_path(view, pos, self.target) or []
            if len(self.path) >= 2:
                action = move_action(self.path[0], self.path[1])
                self.path = self.path[1:]
                return action
            self.target = None
        # Nothing reachable is left to see: hold still.
        return hold_action(view.camera)

    def _view(self) -> WorldView:
        """The world as this UAV plans on it: a fleet's UAV sees only its own part's ground
        while some of it is left (the view's paths go round its teammates' cells)."""
        view = WorldView.of(self.world, self.e)
        if self.world.uavs == 1:
            return view
        if self.own is not None:
            if (view.coverable & self.own & (view.views == 0)).any():
                view = dataclasses.replace(view, coverable=view.coverable & self.own)
            else:  # its part is done: help with what is left anywhere
                self.own, self.target, self.sweeping = None, None, False
        return view

    def _affordable(self, view: WorldView, path: list[Cell]) -> bool:
        legs = max(0, len(path) - 1)
        return legs * (view.cfg.energy_move + view.cfg.energy_hover) < view.energy

    def _next_target(self, view: WorldView, pos: Cell) -> tuple[Cell | None, list[Cell]]:
        """The next useful lane point, else the nearest useful free cell (mop-up)."""
        while self.sweeping and self.next_wp < len(self.waypoints):
            wp = self.waypoints[self.next_wp]
            self.next_wp += 1
            if not view.free(wp) or not view.useful(wp, self.camera):
                continue
            path = bfs_path(view, pos, wp)
            if path and self._affordable(view, path):
                return wp, path
        self.sweeping = False
        path = nearest(view, pos, lambda cell: view.useful(cell, self.camera))
        if path and self._affordable(view, path):
            return path[-1], path
        return None, []


def _lane_rows(
    view: WorldView, camera: tuple[int, int, int], z: int, axis: int
) -> list[list[Cell]]:
    """The sweep's lanes over the whole grid at altitude ``z``, each in its forward order: along
    x (``axis`` 0, one lane per footprint width in y) or along y (``axis`` 1)."""
    sx, sy, _ = view.cfg.size
    cx, cy = sx // 2, sy // 2
    fp = view.footprint((cx, cy, z), camera)
    # The footprint's (nearest, farthest) offset across a lane.
    near, far = (
        (int(fp[:, 1].min()) - cy, int(fp[:, 1].max()) - cy)
        if axis == 0
        else (int(fp[:, 0].min()) - cx, int(fp[:, 0].max()) - cx)
    )
    hi, length = (sy - 1, sx) if axis == 0 else (sx - 1, sy)
    spacing = max(1, far - near + 1)
    lanes = list(range(min(hi, max(0, -near)), hi + 1, spacing))
    if lanes[-1] + far < hi:
        lanes.append(max(lanes[-1] + 1, min(hi, hi - far)))
    return [[(a, lane, z) if axis == 0 else (lane, a, z) for a in range(length)] for lane in lanes]


def _serpentine(rows: list[list[Cell]], first_backwards: bool = False) -> list[Cell]:
    """The lanes flown one after the other, every other one backwards."""
    points: list[Cell] = []
    for k, row in enumerate(rows):
        points.extend(row[::-1] if (k % 2 == 1) != first_backwards else row)
    return points


def fleet_planners(world: WorldBatch, g: int) -> list[BoustrophedonPolicy]:
    """One planner per UAV of world ``g`` (reset each with its slot), each given its piece of
    the sweep one UAV would fly (:func:`pirl.world.split.cut_sweep`) and, as its part, the
    ground its piece is the first to see in the sweep's order.

    Of the eight sweeps over the grid (lanes along x or y, from either end, the first lane
    either way) the one whose pieces finish earliest is cut. A lane point is kept when it is
    free, reachable from the launch site and sees ground; the transit to a piece is counted
    in moves round walls from the nearest start (the UAVs start side by side)."""
    k = world.uavs
    if k == 1:  # the single UAV's own planner: a fleet of one flies as it does
        return [BoustrophedonPolicy()]
    view = WorldView.of(world, g * k)
    camera, altitude = largest_footprint_camera(view)
    starts = [world.position(s) for s in range(g * k, g * k + k)]
    passable = ~view.blocked[:, :, altitude]
    launch = np.min([geodesic(passable, s[:2]) for s in starts], axis=0)
    sees = useful_map(view, camera, altitude)
    best: tuple[int, list[Cell], list] | None = None
    for axis in (0, 1):
        rows = [
            [p for p in row if launch[p[:2]] < UNREACHABLE and sees[p[:2]]]
            for row in _lane_rows(view, camera, altitude, axis)
        ]
        rows = [row for row in rows if row]
        for order in (rows, rows[::-1]):
            for first_backwards in (False, True):
                points = _serpentine(order, first_backwards)
                if not points:
                    continue
                xy = np.array(points)[:, :2]
                pieces = cut_sweep(xy, launch[xy[:, 0], xy[:, 1]], k)
                makespan = max(p.moves for p in pieces)
                if best is None or makespan < best[0]:
                    best = (makespan, points, pieces)
    if best is None:  # no lane point both reachable and useful: each UAV plans on its own
        return [BoustrophedonPolicy() for _ in range(k)]
    _, points, pieces = best
    # Each ground cell to the first piece that sees it; cells no lane point sees to the
    # piece of the nearest cell that has one.
    owner = np.full(view.coverable.shape, -1, dtype=np.int64)
    for r, piece in enumerate(pieces):
        for p in points[piece.start : piece.stop]:
            fp = view.footprint(p, camera)
            fresh = fp[owner[fp[:, 0], fp[:, 1]] < 0]
            owner[fresh[:, 0], fresh[:, 1]] = r
    owner = np.where(view.coverable, owner, -1)
    owner = owner_by_anchor(owner, view.coverable)
    lanes = [
        points[p.start : p.stop][::-1] if p.backwards else points[p.start : p.stop] for p in pieces
    ]
    # Pieces to UAVs: the nearest (UAV, first lane point) pair first.
    cost = np.array(
        [[abs(s[0] - ln[0][0]) + abs(s[1] - ln[0][1]) for ln in lanes] for s in starts],
        dtype=np.float64,
    )
    piece_of = [-1] * k
    for _ in range(len(lanes)):
        u, r = np.unravel_index(np.argmin(cost), cost.shape)
        piece_of[u] = int(r)
        cost[u, :] = np.inf
        cost[:, r] = np.inf
    nothing = np.zeros_like(view.coverable)
    return [  # a UAV without a piece (a sweep too short to share) only helps
        BoustrophedonPolicy(owner == r, lanes[r]) if r >= 0 else BoustrophedonPolicy(nothing, [])
        for r in piece_of
    ]
