"""Boustrophedon (lawnmower) coverage planner: the practitioner's baseline and a test oracle.

Not learned and not an LLM. With the obstacle map known, it

1. sets the camera (and, for the frustum model, the altitude) to the largest footprint,
2. sweeps lanes along x, spaced by the footprint's width across the lane, in serpentine order,
   skipping lane points whose view would add nothing,
3. then visits, nearest first, any place from which an uncovered cell is still visible,

moving along shortest free paths (replanned when wind pushes it off), so it goes around
obstacles. It never plans a leg it cannot pay for: a target whose path costs more energy than
is left is dropped.

A fleet (``env.uavs`` > 1) runs one planner per UAV, each given its part of the area split
(:func:`pirl.world.split.split_area`: balanced connected parts grown from the UAVs' starts):
it sweeps its own part, then helps with whatever is left anywhere; a teammate in the way is an
obstacle for that step's path (:func:`fleet_planners`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from pirl.agents.policy import Policy, hold_action
from pirl.world import dynamics as D
from pirl.world.planning import (
    MOVE_DELTAS,
    Cell,
    WorldView,
    bfs_path,
    largest_footprint_camera,
    nearest,
)
from pirl.world.split import split_area
from pirl.world.state import WorldBatch

_MOVE_ACTION = {delta: action for action, delta in enumerate(MOVE_DELTAS)}


def camera_action(current: tuple[int, int, int], target: tuple[int, int, int]) -> int | None:
    """The camera action that brings (tilt, pan, zoom10) one step closer to ``target``."""
    (tilt, pan, zoom10), (want_tilt, want_pan, want_zoom) = current, target
    if tilt != want_tilt:
        return D.TILT_PLUS if tilt < want_tilt else D.TILT_MINUS
    if pan != want_pan:
        return D.PAN_PLUS if pan < want_pan else D.PAN_MINUS
    if zoom10 != want_zoom:
        return D.ZOOM_PLUS if zoom10 < want_zoom else D.ZOOM_MINUS
    return None


def move_action(a: Cell, b: Cell) -> int:
    """The move action from cell ``a`` to the adjacent cell ``b``."""
    return _MOVE_ACTION[(b[0] - a[0], b[1] - a[1], b[2] - a[2])]


class BoustrophedonPolicy(Policy):
    """Lawnmower sweep with lane spacing from the footprint, detours and a mop-up phase."""

    name = "boustrophedon"
    label = "boustrophedon (planner, not learned)"

    def __init__(self, part: np.ndarray | None = None) -> None:
        self.world: WorldBatch | None = None
        self.part = part
        """(X, Y) ground cells this UAV sweeps first (a fleet's); None: all of them."""

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
        """Serpentine lane points at the sweep altitude, spaced by the footprint's width across
        the lane: along x over the whole grid, or, for a fleet's part, over the part's bounding
        box along whichever axis needs fewer lanes, from the corner nearest the UAV."""
        sx, sy, _ = view.cfg.size
        cx, cy = sx // 2, sy // 2
        fp = view.footprint((cx, cy, self.altitude), self.camera)
        reach = {  # (nearest, farthest) footprint offset across a lane of each axis
            0: (int(fp[:, 1].min()) - cy, int(fp[:, 1].max()) - cy),
            1: (int(fp[:, 0].min()) - cx, int(fp[:, 0].max()) - cx),
        }
        if self.part is None or not self.part.any():
            return _serpentine(0, sx - 1, 0, sy - 1, reach[0], 0, self.altitude)
        xs, ys = np.nonzero(self.part)
        box = (int(xs.min()), int(xs.max()), int(ys.min()), int(ys.max()))
        start = view.position
        best: list[Cell] = []
        for axis in (0, 1):
            for flip in (False, True):
                points = _serpentine(*box, reach[axis], axis, self.altitude, flip)
                if not best or _lanes_cost(points, start) < _lanes_cost(best, start):
                    best = points
        return best

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


def _serpentine(
    x0: int,
    x1: int,
    y0: int,
    y1: int,
    reach: tuple[int, int],
    axis: int,
    z: int,
    flip: bool = False,
) -> list[Cell]:
    """Lane points over the box ``[x0, x1] x [y0, y1]``: lanes along x (``axis`` 0, one per
    footprint width in y) or along y (``axis`` 1); ``flip`` starts at the far lane and the
    far end. ``reach``: the footprint's (nearest, farthest) offset across a lane."""
    lo, hi = (y0, y1) if axis == 0 else (x0, x1)
    a0, a1 = (x0, x1) if axis == 0 else (y0, y1)
    near, far = reach
    spacing = max(1, far - near + 1)
    lanes = list(range(min(hi, max(lo, lo - near)), hi + 1, spacing))
    if lanes[-1] + far < hi:
        lanes.append(max(lanes[-1] + 1, min(hi, hi - far)))
    if flip:
        lanes.reverse()
    points: list[Cell] = []
    for k, lane in enumerate(lanes):
        along = range(a0, a1 + 1) if (k % 2 == 0) != flip else range(a1, a0 - 1, -1)
        points.extend((a, lane, z) if axis == 0 else (lane, a, z) for a in along)
    return points


def _lanes_cost(points: list[Cell], start: Cell) -> int:
    """The moves of a sweep through ``points`` from ``start`` (the way there included)."""
    a = np.array([start, *points])[:, :2]
    return int(np.abs(np.diff(a, axis=0)).sum())


def fleet_planners(world: WorldBatch, g: int) -> list[BoustrophedonPolicy]:
    """One planner per UAV of world ``g`` (reset each with its slot), each given its part of
    the area split at the sweep altitude (:func:`pirl.world.split.split_area`)."""
    k = world.uavs
    if k == 1:  # the single UAV's own planner: a fleet of one flies as it does
        return [BoustrophedonPolicy()]
    view = WorldView.of(world, g * k)
    camera, altitude = largest_footprint_camera(view)
    passable = ~view.blocked[:, :, altitude]
    starts = [world.position(s)[:2] for s in range(g * k, g * k + k)]
    # Ground a sweep covers per move: the area's ground over the single UAV's lane points.
    sweep = BoustrophedonPolicy()
    sweep.camera, sweep.altitude = camera, altitude
    rate = float(view.coverable.sum()) / max(1, len(sweep._lanes(view)))
    owner = split_area(passable, view.coverable, starts, cells_per_step=rate)
    return [BoustrophedonPolicy(owner == u) for u in range(k)]
