"""A fleet's split: one UAV's sweep cut into K consecutive pieces that finish together.

A fleet takes off from one launch site, so its UAVs' starts are neighbouring cells and
cannot seed an area split themselves (DARP, Kapoutsis et al. 2017, grows parts from the
robots' positions; from one launch site its parts degenerate into thin slices or rings).
PIRL cuts the sweep one UAV would fly instead (tour splitting, as in Frederickson, Hecht and
Kim 1978): the sweep's lane points in flying order, each piece flown by one UAV, which first
flies from the launch site to the nearer end of its piece. :func:`cut_sweep` chooses the cuts
so that the last UAV finishes as early as it can (the smallest makespan for which a greedy
cut, each piece as long as the budget allows, needs at most K pieces, found by bisection).

Pieces of one sweep share no lane, so neighbouring UAVs' footprints overlap only where a
piece ends mid-lane; a part grown around a seed shares every border with its neighbours'
footprints (docs/fleets.md measures both).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numba
import numpy as np

UNREACHABLE = np.iinfo(np.int64).max // 4


@numba.njit(cache=True)
def _bfs(passable, sx0, sy0, dist):
    sx, sy = passable.shape
    qx = np.empty(sx * sy, dtype=np.int64)
    qy = np.empty(sx * sy, dtype=np.int64)
    dist[sx0, sy0] = 0
    qx[0], qy[0] = sx0, sy0
    head, tail = 0, 1
    while head < tail:
        x, y = qx[head], qy[head]
        head += 1
        d = dist[x, y] + 1
        for m in range(4):
            nx = x + (1 if m == 0 else -1 if m == 1 else 0)
            ny = y + (1 if m == 2 else -1 if m == 3 else 0)
            if 0 <= nx < sx and 0 <= ny < sy and passable[nx, ny] and dist[nx, ny] > d:
                dist[nx, ny] = d
                qx[tail], qy[tail] = nx, ny
                tail += 1


def geodesic(passable: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """(X, Y) moves from ``start`` over ``passable`` cells (4 neighbours); UNREACHABLE else."""
    dist = np.full(passable.shape, UNREACHABLE, dtype=np.int64)
    if passable[start]:
        _bfs(passable, int(start[0]), int(start[1]), dist)
    return dist


def _anchors(passable: np.ndarray) -> np.ndarray:
    """(X, Y, 2): for every cell, the nearest passable cell (itself when passable), by a
    breadth-first search from all passable cells at once; -1 where none exists."""
    sx, sy = passable.shape
    anchor = np.full((sx, sy, 2), -1, dtype=np.int64)
    queue: deque[tuple[int, int]] = deque()
    for x, y in zip(*np.nonzero(passable), strict=True):
        anchor[x, y] = (x, y)
        queue.append((int(x), int(y)))
    while queue:
        x, y = queue.popleft()
        for nx, ny in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if 0 <= nx < sx and 0 <= ny < sy and anchor[nx, ny, 0] < 0:
                anchor[nx, ny] = anchor[x, y]
                queue.append((nx, ny))
    return anchor


@dataclass(frozen=True)
class Piece:
    """Lane points ``start`` to ``stop - 1`` of a sweep, flown backwards when the last one is
    nearer the launch site; ``moves`` is the transit to it plus the sweep through it."""

    start: int
    stop: int
    backwards: bool
    moves: int


def cut_sweep(points: np.ndarray, transit: np.ndarray, k: int) -> list[Piece]:
    """At most ``k`` consecutive pieces of the sweep ``points`` ((N, 2) cells in flying order),
    the largest piece's ``moves`` as small as a greedy cut allows; ``transit`` (N) is the moves
    from the launch site to each point. Pieces are in sweep order; fewer than ``k`` when the
    sweep is too short to share."""
    n = len(points)
    if n == 0 or k < 1:
        return []
    steps = np.abs(np.diff(points, axis=0)).sum(axis=1) if n > 1 else np.zeros(0)
    along = np.concatenate([[0], np.cumsum(steps)]).astype(np.int64)
    transit = np.asarray(transit, dtype=np.int64)

    def greedy(budget: int) -> list[Piece] | None:
        pieces: list[Piece] = []
        s = 0
        while s < n:
            if len(pieces) == k:
                return None
            inner = along[s:] - along[s]
            ahead, back = transit[s] + inner, transit[s:] + inner
            over = np.flatnonzero(np.minimum(ahead, back) > budget)
            last = max(0, int(over[0]) - 1) if len(over) else n - s - 1
            backwards = bool(back[last] < ahead[last])
            moves = int(back[last] if backwards else ahead[last])
            pieces.append(Piece(s, s + last + 1, backwards, moves))
            s += last + 1
        return pieces

    lo, hi = int(transit.min()), int(along[-1] + transit.max())
    while lo < hi:
        mid = (lo + hi) // 2
        if greedy(mid) is None:
            lo = mid + 1
        else:
            hi = mid
    return greedy(lo) or []


def owner_by_anchor(owner: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """``owner`` with every ``ground`` cell that has none given the owner of its nearest owned
    cell (by moves over the grid, walls ignored: a view reaches over them)."""
    anchor = _anchors(owner >= 0)
    out = owner.copy()
    gx, gy = np.nonzero(ground & (owner < 0) & (anchor[..., 0] >= 0))
    out[gx, gy] = owner[anchor[gx, gy, 0], anchor[gx, gy, 1]]
    return out


__all__ = ["Piece", "cut_sweep", "geodesic", "owner_by_anchor"]
