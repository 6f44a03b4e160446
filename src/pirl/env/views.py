"""Candidate views: macro actions for a coverage policy that chooses where to look next.

A primitive policy picks one of 12 moves or camera steps at every step, so crossing ground it
has already seen takes a long run of right choices. A policy over candidate views picks one
of ``K_VIEWS`` places from which the camera would see ground not yet covered; the grid's
breadth-first moves carry the UAV there (one env step per cell, every step booked by the
rules as usual), and then it chooses again. The camera and altitude are the planner's
(:func:`~pirl.world.planning.largest_footprint_camera`), set at the start of an episode.

The candidates are the nearest useful place in each of eight compass sectors around the
UAV (by moves at its altitude, the way round obstacles), so the choice is about direction
and distance, as a sweep's is. Each is described by its offset, its distance in moves, the
new cells its view would see and the share of the work left that lies in its sector.

:class:`ViewPilot` flies one choice; :class:`ViewsWorld` is one world flown choice by
choice; :class:`ViewsEnv` is its Gymnasium env and :class:`~pirl.env.views_sb3.ViewsVecEnv`
the batched one a chooser trains in. :mod:`pirl.agents.views` plays a chooser as a policy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numba
import numpy as np
from gymnasium import spaces

from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore, require_one_uav
from pirl.world import dynamics as D
from pirl.world.metrics import episode_metrics
from pirl.world.planning import (
    Camera,
    Cell,
    WorldView,
    camera_action,
    largest_footprint_camera,
)
from pirl.world.state import WorldBatch

K_VIEWS = 8
"""Candidates per choice: one per compass sector."""
VIEW_FEATURES = 6
"""Per candidate: present, dx, dy, moves, new cells, work in its sector."""
COARSE = 4
"""The global block: a COARSE x COARSE map of the share of each block's work left."""
GLOBAL_FEATURES = 6 + COARSE * COARSE
OBS_SIZE = K_VIEWS * VIEW_FEATURES + GLOBAL_FEATURES
UNREACHED = np.iinfo(np.int32).max


def views_spaces() -> tuple[spaces.Box, spaces.Discrete]:
    """The observation and action spaces of a chooser of candidate views."""
    return spaces.Box(-1.0, 1.0, (OBS_SIZE,), np.float32), spaces.Discrete(K_VIEWS)


@numba.njit(cache=True)
def _gains(todo, offsets, out):
    """out[x, y] = how many ``todo`` cells the footprint ``offsets`` sees from (x, y)."""
    sx, sy = todo.shape
    for x in range(sx):
        for y in range(sy):
            n = 0
            for k in range(offsets.shape[0]):
                i, j = x + offsets[k, 0], y + offsets[k, 1]
                if 0 <= i < sx and 0 <= j < sy and todo[i, j]:
                    n += 1
            out[x, y] = n


@numba.njit(cache=True)
def _box_gains(todo, x0, y0, x1, y1, out):
    """out[x, y] = how many ``todo`` cells the box of offsets [x0, x1] x [y0, y1] sees from
    (x, y), from a summed-area table: exact, and in time independent of the box's size."""
    sx, sy = todo.shape
    table = np.zeros((sx + 1, sy + 1), dtype=np.int64)
    for x in range(sx):
        for y in range(sy):
            table[x + 1, y + 1] = todo[x, y] + table[x, y + 1] + table[x + 1, y] - table[x, y]
    for x in range(sx):
        lo_x, hi_x = min(max(x + x0, 0), sx), min(max(x + x1 + 1, 0), sx)
        for y in range(sy):
            lo_y, hi_y = min(max(y + y0, 0), sy), min(max(y + y1 + 1, 0), sy)
            inside = table[hi_x, hi_y] - table[lo_x, hi_y]
            out[x, y] = inside - table[hi_x, lo_y] + table[lo_x, lo_y]


@numba.njit(cache=True)
def _moves_from(blocked, x0, y0, out):
    """Breadth-first moves from (x0, y0) over the free cells of one altitude ``blocked``
    (X, Y); UNREACHED where no way leads."""
    sx, sy = blocked.shape
    out[:, :] = UNREACHED
    queue = np.empty(sx * sy, dtype=np.int64)
    out[x0, y0] = 0
    queue[0] = x0 * sy + y0
    head, tail = 0, 1
    while head < tail:
        c = queue[head]
        head += 1
        cx, cy = c // sy, c % sy
        for m in range(4):
            nx, ny = cx + D.MOVE_DX[m], cy + D.MOVE_DY[m]
            if 0 <= nx < sx and 0 <= ny < sy and not blocked[nx, ny] and out[nx, ny] == UNREACHED:
                out[nx, ny] = out[cx, cy] + 1
                queue[tail] = nx * sy + ny
                tail += 1


def view_gains(todo: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(X, Y) int64: how many ``todo`` cells the footprint ``offsets`` (rows (dx, dy)) sees
    from each position. A footprint that fills its bounding box (the paper's square) is
    counted from a summed-area table, exactly and in time independent of its size; any other
    shape cell by cell."""
    sx, sy = todo.shape
    if not len(offsets):
        return np.zeros((sx, sy), dtype=np.int64)
    (x0, y0), (x1, y1) = offsets.min(axis=0), offsets.max(axis=0)
    box = np.zeros((x1 - x0 + 1, y1 - y0 + 1), dtype=bool)
    box[offsets[:, 0] - x0, offsets[:, 1] - y0] = True
    if not box.all():
        out = np.zeros((sx, sy), dtype=np.int64)
        _gains(todo, offsets, out)
        return out
    out = np.empty((sx, sy), dtype=np.int64)
    _box_gains(todo, int(x0), int(y0), int(x1), int(y1), out)
    return out


_SECTOR_TABLES: dict[tuple[int, int], np.ndarray] = {}


def sector_table(sx: int, sy: int) -> np.ndarray:
    """(2 sx - 1, 2 sy - 1) int64: the compass sector (0 .. K_VIEWS - 1) of the offset
    (dx, dy) at ``[dx + sx - 1, dy + sy - 1]``, made once per grid size. numpy's arctan2 on
    flat integer offsets, so a cell on a sector's edge (a diagonal) falls on the same side
    on every call."""
    table = _SECTOR_TABLES.get((sx, sy))
    if table is None:
        dx = np.repeat(np.arange(-(sx - 1), sx, dtype=np.int64), 2 * sy - 1)
        dy = np.tile(np.arange(-(sy - 1), sy, dtype=np.int64), 2 * sx - 1)
        angle = (np.arctan2(dy, dx) + np.pi) / (2 * np.pi) * K_VIEWS
        table = (angle.astype(int) % K_VIEWS).reshape(2 * sx - 1, 2 * sy - 1)
        _SECTOR_TABLES[(sx, sy)] = table
    return table


@numba.njit(cache=True)
def _survey(todo, coverable, gains, moves, at, sectors, best, blocks):
    """One pass over the grid from the UAV at ``at`` = (x0, y0): per sector k, ``best[k]`` =
    x, y, moves and new cells of the nearest place whose view adds cells (x = -1 where none;
    ties: more new cells, then the first in row-major order), and the sector's uncovered
    cells; per COARSE x COARSE block its coverable and uncovered cells (``blocks``)."""
    sx, sy = todo.shape
    x0, y0 = at
    ox, oy = sx - 1 - x0, sy - 1 - y0
    bx, by = -(-sx // COARSE), -(-sy // COARSE)
    best[:, :4] = -1
    best[:, 4] = 0
    blocks[:, :] = 0
    for x in range(sx):
        for y in range(sy):
            s = sectors[x + ox, y + oy]
            b = (x // bx) * COARSE + y // by
            if coverable[x, y]:
                blocks[b, 0] += 1
            if todo[x, y]:
                best[s, 4] += 1
                blocks[b, 1] += 1
            g, d = gains[x, y], moves[x, y]
            if not (g > 0 and 0 < d < UNREACHED):
                continue
            if best[s, 0] < 0 or d < best[s, 2] or (d == best[s, 2] and g > best[s, 3]):
                best[s, 0], best[s, 1], best[s, 2], best[s, 3] = x, y, d, g


@dataclass
class Candidates:
    """One choice: up to K_VIEWS places (x, y, altitude) and the observation describing them."""

    cells: list[Cell | None]
    """Slot k's place, or None where sector k has no useful place."""
    obs: np.ndarray
    """(OBS_SIZE,) float32: the candidates' features, then the global block."""
    moves: list[int]
    """Slot k's distance in moves (0 where absent)."""
    gains: list[int]
    """The new cells slot k's view would see (0 where absent)."""

    @property
    def mask(self) -> np.ndarray:
        """Which slots hold a place (never all False while :attr:`any`)."""
        return np.array([c is not None for c in self.cells], dtype=bool)

    @property
    def any(self) -> bool:
        return any(c is not None for c in self.cells)

    def place(self, k: int) -> Cell | None:
        """The place chosen by slot ``k``: an absent one (which a masked chooser never picks)
        stands for the nearest present one."""
        if self.cells[int(k)] is None and self.any:
            k = nearest_view(self)
        return self.cells[int(k)]


def candidates(view: WorldView, camera: Camera, altitude: int) -> Candidates:
    """The nearest useful place in each compass sector around the UAV, seen with ``camera``
    from ``altitude`` (ties: the one whose view adds more cells). A view's new cells are
    counted with the footprint translated from the grid's centre, as
    :func:`~pirl.world.planning.useful_map` does: exact for the paper model; for the frustum
    model occlusion by obstacles is not counted."""
    sx, sy, _ = view.cfg.size
    x0, y0, _ = view.position
    todo = view.coverable & (view.views == 0)
    cx, cy = sx // 2, sy // 2
    offsets = view.footprint((cx, cy, altitude), camera) - np.array([cx, cy])
    gains = view_gains(todo, offsets)
    moves = np.empty((sx, sy), dtype=np.int64)
    _moves_from(view.blocked[:, :, altitude], x0, y0, moves)
    best = np.empty((K_VIEWS, 5), dtype=np.int64)
    blocks = np.empty((COARSE * COARSE, 2), dtype=np.int64)
    _survey(todo, view.coverable, gains, moves, (x0, y0), sector_table(sx, sy), best, blocks)
    # Distances in footprint widths, squashed: the same numbers on a 15x15 training world
    # and on a 256x256 site, so what the chooser learned near by carries to any size.
    scale = 4.0 * max(1.0, float(np.sqrt(len(offsets))))
    n_todo = int(blocks[:, 1].sum())
    left = max(1, n_todo)
    obs = np.zeros(OBS_SIZE, dtype=np.float32)
    cells: list[Cell | None] = [None] * K_VIEWS
    far, new = [0] * K_VIEWS, [0] * K_VIEWS
    fp = max(1, len(offsets))
    for k in range(K_VIEWS):
        x, y, dist, gain, work = best[k]
        if x < 0:
            continue
        dx, dy = x - x0, y - y0
        cells[k] = (int(x), int(y), int(altitude))
        far[k], new[k] = int(dist), int(gain)
        obs[k * VIEW_FEATURES : (k + 1) * VIEW_FEATURES] = (
            1.0, np.tanh(dx / scale), np.tanh(dy / scale), np.tanh(dist / scale),
            gain / fp,
            work / left,
        )  # fmt: skip
    coverable = max(1, int(blocks[:, 0].sum()))
    g = K_VIEWS * VIEW_FEATURES
    obs[g : g + 6] = (
        x0 / max(1, sx - 1), y0 / max(1, sy - 1), view.energy / view.cfg.capacity,
        1.0 - n_todo / coverable, n_todo / (sx * sy), altitude / max(1, view.cfg.size[2] - 1),
    )  # fmt: skip
    for b, (in_block, done) in enumerate(blocks):
        if in_block:
            obs[g + 6 + b] = done / in_block
    return Candidates(cells, obs, far, new)


class ViewPilot:
    """Flies one UAV to a chosen place with the episode's camera: camera steps first, then
    the altitude, then one move at a time down the moves-to-target map (recomputed only when a
    new place is chosen; a gust that pushes the UAV aside is followed from where it lands)."""

    def __init__(self, world: WorldBatch, e: int) -> None:
        self.world, self.e = world, e
        view = WorldView.of(world, e)
        self.camera, self.altitude = largest_footprint_camera(view)
        self.target: Cell | None = None
        self._moves = np.empty(world.cfg.size[:2], dtype=np.int64)

    def aim(self, cell: Cell) -> None:
        """Fly to ``cell`` from now on."""
        self.target = cell
        blocked = self.world.blocked[self.world.world_of(self.e), :, :, self.altitude]
        _moves_from(blocked, cell[0], cell[1], self._moves)

    def arrived(self) -> bool:
        return self.target is None or self.world.position(self.e) == self.target

    def action(self) -> int | None:
        """The next primitive action, or None once at the target with the camera set (or when
        no way leads there now)."""
        step = camera_action(self.world.camera_setting(self.e), self.camera)
        if step is not None:
            return step
        x, y, z = self.world.position(self.e)
        if z != self.altitude:
            return D.Z_PLUS if z < self.altitude else D.Z_MINUS
        if self.arrived():
            return None
        here = self._moves[x, y]
        for a in range(4):
            nx, ny = x + D.MOVE_DX[a], y + D.MOVE_DY[a]
            sx, sy = self._moves.shape
            if 0 <= nx < sx and 0 <= ny < sy and self._moves[nx, ny] < here:
                return a
        return None


def nearest_view(c: Candidates) -> int:
    """The rule a learned chooser is measured against: the nearest candidate (then the one
    whose view adds more cells)."""
    present = [k for k in range(K_VIEWS) if c.cells[k] is not None]
    return min(present, key=lambda k: (c.moves[k], -c.gains[k]), default=0)


def flight_limit(cfg: VCPPConfig) -> int:
    """Primitive steps after which a choice's flight ends short of its place (gusts may keep
    the UAV from it): four crossings of the grid."""
    return 4 * sum(cfg.size)


@dataclass
class Flight:
    """What one choice did: the inner env's rewards and reward terms summed over its
    primitive steps, how many there were, and how the episode stands after it."""

    reward: float
    terms: np.ndarray
    steps: int
    terminated: bool
    truncated: bool
    info: dict[str, Any]


class ViewsWorld:
    """One world flown choice by choice (a one-world :class:`~pirl.env.core.EnvCore`, the
    rules of every env): its pilot and its current candidates. :class:`ViewsEnv` and
    :class:`ViewsVecEnv` are this, one world or many."""

    def __init__(self, cfg: VCPPConfig) -> None:
        require_one_uav(cfg, "candidate views")
        self.core = EnvCore(cfg, 1)
        self.limit = flight_limit(cfg)
        self.pilot: ViewPilot | None = None
        self.candidates: Candidates | None = None

    @property
    def world(self) -> WorldBatch:
        return self.core.world

    def reset(self, rng: np.random.Generator, scenario: Any = None) -> dict[str, Any]:
        """A new episode drawn from ``rng`` (or ``scenario``); its first info."""
        self.core.reset_world(0, rng, scenario)
        self.pilot = ViewPilot(self.world, 0)
        self._offer()
        return self.core.infos()[0]

    def _offer(self) -> None:
        view = WorldView.of(self.world, 0)
        self.candidates = candidates(view, self.pilot.camera, self.pilot.altitude)

    @property
    def obs(self) -> np.ndarray:
        return self.candidates.obs.copy()

    @property
    def mask(self) -> np.ndarray:
        return self.candidates.mask

    def fly(self, k: int) -> Flight:
        """Fly to candidate ``k`` (an absent one, which a masked chooser never picks: the
        nearest present one)."""
        cell = self.candidates.place(k)
        if cell is not None:
            self.pilot.aim(cell)
        core = self.core
        reward, terms, steps = 0.0, np.zeros(core.world.terms.shape[1]), 0
        terminated = truncated = False
        while steps < self.limit:
            a = self.pilot.action()
            if a is None:
                break
            core.step(np.array([a], dtype=np.int64))
            reward += float(core.rewards[0])
            terms += core.world.terms[0]
            steps += 1
            terminated, truncated = bool(core.terminated[0]), bool(core.truncated[0])
            if terminated or truncated:
                break
        info = core.infos()[0]
        self._offer()
        if not (terminated or truncated) and not self.candidates.any:
            truncated = True  # nothing useful is reachable: the episode ends here
            info["episode_metrics"] = episode_metrics(self.world, 0)
        return Flight(reward, terms, steps, terminated, truncated, info)

    def state_dict(self) -> dict[str, Any]:
        """What continues the episode exactly: the core, the pilot's camera, altitude and
        place (its way there and the candidates follow from the world)."""
        pilot = self.pilot
        return {
            "core": self.core.state_dict(),
            "pilot": (pilot.camera, pilot.altitude, pilot.target),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.core.load_state_dict(state["core"])
        self.pilot = ViewPilot(self.world, 0)
        camera, altitude, target = state["pilot"]
        self.pilot.camera, self.pilot.altitude = tuple(camera), int(altitude)
        if target is not None:
            self.pilot.aim(tuple(target))
        self._offer()


class ViewsEnv(gym.Env):
    """Choosing candidate views, one choice per step (Gymnasium API).

    ## Description
    The VCPP task (:class:`~pirl.env.vcpp_env.VCPPEnv`, same settings) played by choosing
    where to look next: each step flies the UAV to one of ``K_VIEWS`` candidate places with
    the planner's camera, one primitive env step per cell.

    ## Action Space
    ``Discrete(K_VIEWS)``: fly to candidate k; ``action_masks()`` gives the present ones.

    ## Observation Space
    ``Box(-1, 1, (OBS_SIZE,), float32)``: per candidate (present, dx, dy, moves, new cells,
    work in its sector), then position, battery, coverage, work left, altitude and a
    ``COARSE x COARSE`` map of the work left.

    ## Rewards
    The inner env's reward, summed over the primitive steps of the flight; ``info`` carries
    ``primitive_steps``.

    ## Episode End
    When the inner episode ends, or (truncated) when no useful place is reachable.
    """

    metadata = {"render_modes": []}

    def __init__(self, cfg: VCPPConfig) -> None:
        self.views = ViewsWorld(cfg)
        self.observation_space, self.action_space = views_spaces()

    @property
    def world(self) -> WorldBatch:
        return self.views.world

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        info = self.views.reset(self.np_random, (options or {}).get("scenario"))
        return self.views.obs, info

    def action_masks(self) -> np.ndarray:
        return self.views.mask.copy()

    def step(self, action: int):
        f = self.views.fly(int(action))
        info = {**f.info, "primitive_steps": f.steps}
        return self.views.obs, f.reward, f.terminated, f.truncated, info
