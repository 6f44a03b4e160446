"""Boustrophedon (lawnmower) coverage planner: the practitioner's baseline and a test oracle.

Not learned and not an LLM. With the obstacle map known, it

1. sets the camera (and altitude) to the setting with the largest footprint,
2. sweeps lanes along x, spaced by the footprint's width across the lane, in serpentine order,
   skipping lane points whose view would add nothing,
3. then visits, nearest first, any place from which an uncovered cell is still visible,

moving along shortest free paths (breadth-first search, replanned when wind pushes it off),
so it goes around obstacles. It never plans a leg it cannot pay for: a target whose path costs
more energy than is left is dropped for a nearer one.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from pirl.agents.policy import Policy
from pirl.world import dynamics as D
from pirl.world.state import WorldBatch

# Action for each move delta (dx, dy, dz).
_MOVE_ACTION = {
    (1, 0, 0): 0,
    (-1, 0, 0): 1,
    (0, 1, 0): 2,
    (0, -1, 0): 3,
    (0, 0, 1): 4,
    (0, 0, -1): 5,
}
_TILT_UP, _TILT_DOWN, _PAN_UP, _PAN_DOWN, _ZOOM_IN, _ZOOM_OUT = 6, 7, 8, 9, 10, 11


class BoustrophedonPolicy(Policy):
    """Lawnmower sweep with lane spacing from the footprint, detours and a mop-up phase."""

    name = "boustrophedon"
    label = "boustrophedon (planner, not learned)"

    def __init__(self) -> None:
        self.world: WorldBatch | None = None
        self.e = 0

    # -- episode set-up -------------------------------------------------------------------
    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        self.world, self.e = world, index
        self.camera, self.altitude = self._best_camera()
        self.waypoints = self._lanes()
        self.next_wp = 0
        self.path: list[tuple[int, int, int]] = []
        self.target: tuple[int, int, int] | None = None
        self.sweeping = True

    def _best_camera(self) -> tuple[tuple[int, int, int], int]:
        """(tilt, pan, zoom10) and altitude with the largest footprint, cheapest to reach."""
        w = self.world
        sx, sy, sz = w.cfg.size
        x, y, z = w.position(self.e)
        tilt0, pan0, zoom0 = (int(v) for v in w.ints[self.e, [D.TILT, D.PAN, D.ZOOM]])
        centre = (sx // 2, sy // 2)
        best, best_key = None, None
        altitudes = [z] if w.cfg.footprint == "paper" else range(sz)
        for alt in altitudes:
            for tilt in range(0, 91, 5):
                for zoom10 in range(5, 21):
                    n = len(w.footprint(self.e, pose=(*centre, alt), camera=(tilt, 0, zoom10)))
                    cost = (abs(tilt - tilt0) // 5 + abs(zoom10 - zoom0) + abs(pan0) // 15) * (
                        w.cfg.energy_camera
                    ) + abs(alt - z) * w.cfg.energy_climb
                    key = (n, -cost)
                    if best_key is None or key > best_key:
                        best, best_key = ((tilt, 0, zoom10), alt), key
        return best

    def _lanes(self) -> list[tuple[int, int, int]]:
        """Serpentine lane points at the sweep altitude, spaced by the footprint width."""
        w = self.world
        sx, sy, _ = w.cfg.size
        cx, cy = sx // 2, sy // 2
        fp = w.footprint(self.e, pose=(cx, cy, self.altitude), camera=self.camera)
        dy_min, dy_max = int(fp[:, 1].min()) - cy, int(fp[:, 1].max()) - cy
        spacing = max(1, dy_max - dy_min + 1)
        first = min(sy - 1, max(0, -dy_min))
        lanes = list(range(first, sy, spacing))
        if lanes[-1] + dy_max < sy - 1:
            lanes.append(sy - 1 - dy_max if sy - 1 - dy_max > lanes[-1] else sy - 1)
        points = []
        for k, lane_y in enumerate(lanes):
            xs = range(sx) if k % 2 == 0 else range(sx - 1, -1, -1)
            points.extend((x, lane_y, self.altitude) for x in xs)
        return points

    # -- acting ---------------------------------------------------------------------------
    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        w, e = self.world, self.e
        if w is None:
            raise RuntimeError("call reset(world, index) before act()")
        camera_action = self._camera_action()
        if camera_action is not None:
            return camera_action
        pos = w.position(e)
        for _ in range(3):
            if self.target is None or not self._useful(self.target) or pos == self.target:
                self.target, self.path = self._next_target(pos)
                if self.target is None:
                    return _TILT_UP if w.ints[e, D.TILT] == 90 else _TILT_DOWN
            if not self.path or self.path[0] != pos:
                self.path = self._bfs(pos, self.target) or []
            if len(self.path) >= 2:
                step = tuple(b - a for a, b in zip(self.path[0], self.path[1], strict=True))
                self.path = self.path[1:]
                return _MOVE_ACTION[step]
            self.target = None
        return _TILT_UP if w.ints[e, D.TILT] == 90 else _TILT_DOWN

    def _camera_action(self) -> int | None:
        tilt, pan, zoom10 = (int(v) for v in self.world.ints[self.e, [D.TILT, D.PAN, D.ZOOM]])
        want_tilt, want_pan, want_zoom = self.camera
        if tilt != want_tilt:
            return _TILT_UP if tilt < want_tilt else _TILT_DOWN
        if pan != want_pan:
            return _PAN_UP if pan < want_pan else _PAN_DOWN
        if zoom10 != want_zoom:
            return _ZOOM_IN if zoom10 < want_zoom else _ZOOM_OUT
        return None

    def _useful(self, pose: tuple[int, int, int]) -> bool:
        """Whether the view from ``pose`` would add an uncovered coverable cell."""
        w, e = self.world, self.e
        fp = w.footprint(e, pose=pose, camera=self.camera)
        if not len(fp):
            return False
        todo = w.coverable[e, fp[:, 0], fp[:, 1]] & (w.views[e, fp[:, 0], fp[:, 1]] == 0)
        return bool(todo.any())

    def _affordable(self, path: list) -> bool:
        w = self.world
        legs = max(0, len(path) - 1)
        return legs * (w.cfg.energy_move + w.cfg.energy_hover) < w.energy[self.e]

    def _next_target(self, pos):
        """The next useful lane point, else the nearest useful free cell (mop-up)."""
        blocked = self.world.blocked[self.e]
        while self.sweeping and self.next_wp < len(self.waypoints):
            wp = self.waypoints[self.next_wp]
            self.next_wp += 1
            if blocked[wp] or not self._useful(wp):
                continue
            path = self._bfs(pos, wp)
            if path and self._affordable(path):
                return wp, path
        self.sweeping = False
        return self._nearest_useful(pos)

    def _neighbours(self, cell):
        sx, sy, sz = self.world.cfg.size
        blocked = self.world.blocked[self.e]
        x, y, z = cell
        for dx, dy, dz in _MOVE_ACTION:
            n = (x + dx, y + dy, z + dz)
            if 0 <= n[0] < sx and 0 <= n[1] < sy and 0 <= n[2] < sz and not blocked[n]:
                yield n

    def _bfs(self, start, goal) -> list[tuple[int, int, int]] | None:
        """Shortest free path start -> goal (inclusive), or None when unreachable."""
        if start == goal:
            return [start]
        parent = {start: None}
        queue = deque([start])
        while queue:
            cell = queue.popleft()
            for n in self._neighbours(cell):
                if n in parent:
                    continue
                parent[n] = cell
                if n == goal:
                    path = [n]
                    while parent[path[-1]] is not None:
                        path.append(parent[path[-1]])
                    return path[::-1]
                queue.append(n)
        return None

    def _nearest_useful(self, pos):
        """Breadth-first search for the nearest free cell whose view adds something."""
        parent = {pos: None}
        queue = deque([pos])
        while queue:
            cell = queue.popleft()
            if cell != pos and self._useful(cell):
                path = [cell]
                while parent[path[-1]] is not None:
                    path.append(parent[path[-1]])
                path = path[::-1]
                return (cell, path) if self._affordable(path) else (None, [])
            for n in self._neighbours(cell):
                if n not in parent:
                    parent[n] = cell
                    queue.append(n)
        return None, []
