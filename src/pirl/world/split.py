"""A fleet's area split: the ground to cover cut into K balanced connected parts, one per UAV.

A fleet takes off from one launch site, so its UAVs' starts are neighbouring cells and
cannot seed a split themselves (DARP, Kapoutsis et al. 2017, grows parts from the robots'
positions; from one launch site its parts degenerate into thin slices or rings). Instead:

1. K seeds are spread over the free cells at the flight altitude by geodesic farthest-point
   sampling (distances by moves around walls and no-fly zones);
2. each cell goes to the seed whose distance plus bias is smallest, and the biases are tuned
   until every part holds about the same number of ground cells; an additive bias keeps each
   part connected by construction (every cell on a shortest way from a seed to a cell of its
   part belongs to the part too, up to ties), where DARP's multiplicative weights need a
   repair step;
3. each seed moves to the cell of its part nearest the part's centre, and 2 repeats
   (:data:`LLOYD_ROUNDS` rounds of Lloyd's iteration), so parts are compact, as a lawnmower
   sweep wants;
4. parts go to UAVs by distance from their starts (greedy, nearest pair first).

Ground cells under an obstacle at the flight altitude belong to the part of the nearest free
column, from which they are seen.
"""

from __future__ import annotations

from collections import deque

import numba
import numpy as np

UNREACHABLE = np.iinfo(np.int64).max // 4
LLOYD_ROUNDS = 6


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


def split_area(
    passable: np.ndarray,
    ground: np.ndarray,
    starts: list[tuple[int, int]],
    iterations: int = 200,
    tolerance: float = 0.03,
    cells_per_step: float = 0.0,
) -> np.ndarray:
    """The owner (0..K-1, a UAV) of each ground cell to cover (``ground``, (X, Y) bool), -1
    for cells no start can reach or that are not ground.

    ``passable`` (X, Y) are the cells free at the flight altitude; ``starts`` the UAVs'
    cells (x, y). Biases are tuned for at most ``iterations`` rounds per Lloyd round, until
    the largest part holds at most ``1 + tolerance`` times its target. With
    ``cells_per_step`` (how many ground cells a sweep covers per move) the targets balance
    time rather than area: a part farther from the launch site holds fewer cells, by the
    moves it takes to get there, so every UAV is due to finish at about the same step.
    """
    k = len(starts)
    owner = np.full(ground.shape, -1, dtype=np.int64)
    if k == 0:
        return owner
    reach = np.zeros(passable.shape, dtype=bool)
    for s in starts:
        reach |= geodesic(passable, s) < UNREACHABLE
    anchor = _anchors(reach)
    gx, gy = np.nonzero(ground & (anchor[..., 0] >= 0))
    if not len(gx):
        return owner
    ax, ay = anchor[gx, gy, 0], anchor[gx, gy, 1]
    if k == 1:
        owner[gx, gy] = 0
        return owner
    seeds = _spread(reach, starts[0], k)
    pick = np.zeros(len(gx), dtype=np.int64)
    targets = np.full(k, len(gx) / k)
    launch = geodesic(reach, starts[0]).astype(np.float64)[ax, ay]
    for _ in range(LLOYD_ROUNDS):
        dist = np.stack([geodesic(reach, c)[ax, ay] for c in seeds]).astype(np.float64)
        pick = _balanced(dist, iterations, tolerance, targets)
        moved = [_centre(gx[pick == r], gy[pick == r], reach, seeds[r]) for r in range(k)]
        if cells_per_step > 0:
            targets = _timed_targets(pick, launch, k, cells_per_step)
        elif moved == seeds:
            break
        seeds = moved
    # Parts to UAVs: the nearest (UAV, part) pair first.
    cost = np.array([[geodesic(reach, s)[c] for c in seeds] for s in starts], dtype=np.float64)
    part_of = np.full(k, -1, dtype=np.int64)
    for _ in range(k):
        u, r = np.unravel_index(np.argmin(cost), cost.shape)
        part_of[r] = u
        cost[u, :] = np.inf
        cost[:, r] = np.inf
    owner[gx, gy] = part_of[pick]
    return owner


def _spread(reach: np.ndarray, launch: tuple[int, int], k: int) -> list[tuple[int, int]]:
    """K cells spread over ``reach`` by geodesic farthest-point sampling from ``launch``."""
    nearest = geodesic(reach, launch).astype(np.float64)
    nearest[~reach] = -1
    seeds: list[tuple[int, int]] = []
    for _ in range(k):
        c = np.unravel_index(int(np.argmax(nearest)), nearest.shape)
        seeds.append((int(c[0]), int(c[1])))
        d = geodesic(reach, seeds[-1]).astype(np.float64)
        nearest = np.where(reach, np.minimum(nearest if len(seeds) > 1 else d, d), -1)
    return seeds


def _timed_targets(pick: np.ndarray, launch: np.ndarray, k: int, rate: float) -> np.ndarray:
    """Part sizes that finish together: part r's UAV first flies to it (the moves from the
    launch site to its nearest cell), then covers ``rate`` cells a move; sizes add up."""
    n = len(pick)
    transit = np.array([launch[pick == r].min() if (pick == r).any() else 0.0 for r in range(k)])
    finish = (n / rate + transit.sum()) / k
    sizes = np.maximum(1.0, (finish - transit) * rate)
    return sizes * n / sizes.sum()


def _balanced(
    dist: np.ndarray, iterations: int, tolerance: float, targets: np.ndarray | None = None
) -> np.ndarray:
    """Each cell's part (``dist``: (K, cells) distances to the seeds), by distance plus a
    bias tuned until the parts hold about their ``targets`` numbers of cells (equal when
    None); the most even seen."""
    k, n = dist.shape
    dist = np.where(dist >= UNREACHABLE, np.inf, dist)
    target = np.full(k, n / k) if targets is None else np.asarray(targets, dtype=np.float64)
    scale = max(1.0, float(np.median(dist[np.isfinite(dist)])))
    bias = np.zeros(k)
    best, best_load = np.argmin(dist, axis=0), np.inf
    step = 0.5 * scale
    for _ in range(iterations):
        pick = np.argmin(dist + bias[:, None], axis=0)
        sizes = np.bincount(pick, minlength=k)
        load = (sizes / target).max()
        if load < best_load:
            best, best_load = pick, load
        if load <= 1.0 + tolerance:
            break
        # A part over the mean grows its bias (its far cells go to a neighbour), one under
        # shrinks it; the step shrinks as the split settles.
        bias += step * (sizes - target) / target
        step *= 0.97
    return best


def _centre(xs: np.ndarray, ys: np.ndarray, reach: np.ndarray, seed: tuple[int, int]):
    """The cell of a part nearest its centre (the part's own cells, anchored), else ``seed``."""
    if not len(xs):
        return seed
    cx, cy = xs.mean(), ys.mean()
    k = int(np.argmin((xs - cx) ** 2 + (ys - cy) ** 2))
    c = (int(xs[k]), int(ys[k]))
    return c if reach[c] else seed


def split_balance(owner: np.ndarray, k: int) -> float:
    """The largest part over the mean part (1.0: perfectly balanced)."""
    sizes = np.bincount(owner[owner >= 0], minlength=k)
    return float(sizes.max() / max(sizes.mean(), 1e-9))


__all__ = ["geodesic", "split_area", "split_balance"]
