"""The rules of the grid world, compiled with numba and applied to a batch of worlds.

A single environment is a batch of one: the single and batched environments call the same
kernels, so they cannot disagree. Every kernel reads the worlds' state from one
:class:`~pirl.world.state.WorldArrays` ``w`` (per-world records ``w.status`` and ``w.flags``
with named fields, bookkeeping grids with the batch as first axis) and the fixed settings from
one :class:`~pirl.world.state.Params` ``p``.

**Slots.** A world holds K UAVs (``env.uavs``; 1 is the paper's task). The per-UAV arrays
(pose, camera, counters, battery, wind stream, visits, ...) have one row per *slot*, the
(world, UAV) pair ``e = world * K + uav``; the map and the coverage bookkeeping (``blocked``,
``occluding``, ``coverable``, ``views``, ``redmask``, ``blk_*``) have one row per world, read
at :func:`world_of`. With K = 1 a slot is its world, and every rule reads exactly as it did
for one UAV.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pirl.config.grid import (
    PAN_MAX,
    PAN_MIN,
    PAN_STEP,
    PAPER_NADIR_TILT,
    TILT_MAX,
    TILT_MIN,
    TILT_STEP,
    ZOOM_MAX10,
    ZOOM_MIN10,
    ZOOM_STEP10,
)
from pirl.world.footprint import PAPER, CameraPose, footprint_cells, paper_half_width

# Reward term columns of ``WorldArrays.terms``, in the order of pirl.config.world.REWARD_TERMS
# (a vector, not a record: the reward is its dot product with the weights).
T_COVERAGE, T_REDUNDANT, T_BATTERY, T_CAM, T_CURIOSITY, T_COLLISION, T_IDLE, T_LLM = range(8)
N_TERMS = 8

# Actions in the paper's order; the names say what each one does.
X_PLUS, X_MINUS, Y_PLUS, Y_MINUS, Z_PLUS, Z_MINUS = 0, 1, 2, 3, 4, 5
TILT_PLUS, TILT_MINUS, PAN_PLUS, PAN_MINUS, ZOOM_PLUS, ZOOM_MINUS = 6, 7, 8, 9, 10, 11
N_MOVES = 6  # actions below N_MOVES move the UAV, the others steer the camera
N_ACTIONS = 12
PARKED = TILT_PLUS  # the one action a UAV that has left keeps in its mask (never carried out)
ACTION_NAMES = (
    "x+", "x-", "y+", "y-", "z+", "z-", "tilt+5", "tilt-5", "pan+15", "pan-15", "zoom+0.1",
    "zoom-0.1",
)  # fmt: skip
# The one table of move deltas (x, y, z) of actions 0-5; planners read it as MOVE_DELTAS.
MOVES = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.int64
)
MOVE_DELTAS: tuple[tuple[int, int, int], ...] = tuple(
    (int(dx), int(dy), int(dz)) for dx, dy, dz in MOVES
)
# The four horizontal moves, in the order of the actions 0-3 (x+, x-, y+, y-).
MOVE_DX = (1, -1, 0, 0)
MOVE_DY = (0, 0, 1, -1)
WIND_DIRS = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], dtype=np.int64)

# Options of the loops over worlds (here and in pirl.env), compiled without numba's reference
# counting: they allocate nothing, and with it every inlined call that passes the
# WorldArrays tuple increfs and decrefs each of its arrays, which halved the env's throughput
# (benchmarks/env_throughput.py). Functions that allocate (footprint_cells) keep it.
BATCH_KERNEL = {"cache": True, "_nrt": False}


@numba.njit(cache=True)
def _next_uniform(rng, e):
    """splitmix64: a small counter-based generator per world, so wind is reproducible."""
    state = rng[e] + np.uint64(0x9E3779B97F4A7C15)
    rng[e] = state
    z = state
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True)
def fleet_size(w):
    """UAVs per world (K): the slots over the worlds, read off the arrays' first axes."""
    return w.status.shape[0] // w.coverable.shape[0]


@numba.njit(cache=True)
def world_of(w, e):
    """The world of slot e: the row of the shared map and coverage arrays."""
    return e // fleet_size(w)


@numba.njit(cache=True)
def free(blocked, p, g, x, y, z):
    """Whether cell (x, y, z) of world g lies inside the grid and out of every obstacle."""
    inside = 0 <= x < p.size_x and 0 <= y < p.size_y and 0 <= z < p.size_z
    return inside and not blocked[g, x, y, z]


@numba.njit(cache=True)
def held(w, e, x, y, z):
    """Whether a teammate of slot e that is still flying holds cell (x, y, z) (never with one
    UAV). Two UAVs never share a cell: the mask and the move read this."""
    k = fleet_size(w)
    if k == 1:
        return False
    first = (e // k) * k
    for t in range(first, first + k):
        if t != e and not w.left[t]:
            st = w.status[t]
            if st["x"] == x and st["y"] == y and st["z"] == z:
                return True
    return False


@numba.njit(cache=True)
def open_cell(w, p, e, x, y, z):
    """Whether slot e's UAV may fly into cell (x, y, z): free, and no teammate holds it."""
    return free(w.blocked, p, world_of(w, e), x, y, z) and not held(w, e, x, y, z)


@numba.njit(cache=True)
def book_view(w, e, cells, mark_redundant):
    """Book one view of world e: the distinct ground cells (rows (i, j)) of ``cells``.

    Counts new cells, views and cells seen twice, keeps the coarse map's per-block counts and,
    with ``mark_redundant``, marks the cells of a view that adds nothing as redundantly viewed
    (the set C_redundant of the RVC metric). Returns the number of new cells. The grid books
    its footprint here; the physics evaluation books the union of a flight's views here too.
    """
    st = w.status[e]
    g = world_of(w, e)
    coverable, views, redmask = w.coverable, w.views, w.redmask
    new = 0
    seen = 0
    for k in range(cells.shape[0]):
        i, j = cells[k, 0], cells[k, 1]
        if not coverable[g, i, j]:
            continue
        seen += 1
        v = views[g, i, j]
        if v == 0:
            new += 1
            w.blk_todo[g, w.block_x[i], w.block_y[j]] -= 1
        elif v == 1:
            st["multi_cells"] += 1
        views[g, i, j] = v + 1
    # Coverage is the world's: every teammate's count grows (a fleet of one: this UAV's); the
    # new cells are credited to the UAV that booked them first.
    k = fleet_size(w)
    for t in range(g * k, g * k + k):
        w.status[t]["covered"] += new
    w.credit[e] += new
    if k > 1:
        bit = 1 << (e - g * k)
        for r in range(cells.shape[0]):
            i, j = cells[r, 0], cells[r, 1]
            if coverable[g, i, j]:
                w.seen_by[g, i, j] |= bit
    st["cell_views"] += seen
    if new == 0 and mark_redundant:
        for k in range(cells.shape[0]):
            i, j = cells[k, 0], cells[k, 1]
            if coverable[g, i, j] and not redmask[g, i, j]:
                redmask[g, i, j] = True
                st["redundant_cells"] += 1
    return new


@numba.njit(cache=True)
def camera_pose(w, e):
    """World e's camera as a :class:`~pirl.world.footprint.CameraPose` (grid integers)."""
    st = w.status[e]
    return CameraPose(st["x"], st["y"], st["z"], st["tilt"], st["pan"], st["zoom10"])


@numba.njit(cache=True)
def observe(w, p, e, mark_redundant):
    """Look from world e's current pose, book the view (:func:`book_view`); return new cells."""
    st = w.status[e]
    buf = w.buf[e]
    g = world_of(w, e)
    n = footprint_cells(
        p, camera_pose(w, e), w.obstacles[g, : st["n_obstacles"]], w.occluding[g], w.ground[g],
        buf,
    )  # fmt: skip
    st["footprint_sum"] += n
    w.seen_now[e] = n
    return book_view(w, e, buf[:n], mark_redundant)


@numba.njit(cache=True)
def camera_action(w, e, a):
    """Apply camera action ``a`` (6-11) to world e: steps of 5 degrees, 15 degrees and 0.1
    zoom; at a limit the setting holds. Counts the camera action."""
    st = w.status[e]
    st["camera_actions"] += 1
    if a == TILT_PLUS:
        st["tilt"] = min(TILT_MAX, st["tilt"] + TILT_STEP)
    elif a == TILT_MINUS:
        st["tilt"] = max(TILT_MIN, st["tilt"] - TILT_STEP)
    elif a == PAN_PLUS:
        st["pan"] = min(PAN_MAX, st["pan"] + PAN_STEP)
    elif a == PAN_MINUS:
        st["pan"] = max(PAN_MIN, st["pan"] - PAN_STEP)
    elif a == ZOOM_PLUS:
        st["zoom10"] = min(ZOOM_MAX10, st["zoom10"] + ZOOM_STEP10)
    else:
        st["zoom10"] = max(ZOOM_MIN10, st["zoom10"] - ZOOM_STEP10)


@numba.njit(cache=True)
def _work_within(w, g, cx, cy, reach, sx, sy):
    """Whether a coverable ground cell of world g not yet covered lies within ``reach`` cells
    (the square of half-width ``reach``) of (cx, cy)."""
    for i in range(max(0, cx - reach), min(sx, cx + reach + 1)):
        for j in range(max(0, cy - reach), min(sy, cy + reach + 1)):
            if w.coverable[g, i, j] and w.views[g, i, j] == 0:
                return True
    return False


@numba.njit(cache=True)
def path_to_work(w, e, x, y, z, sx, sy, reach):
    """Breadth-first search from (x, y) over the cells free at altitude z: (dx, dy) of the first
    move towards the nearest cell within ``reach`` cells of a coverable cell not yet covered
    (0: above one), and the number of moves; moves -1 when none is reachable at that altitude.
    The observation's target (reach 0) and the stall guard of :func:`action_mask` read it.
    Unlike the straight line, this way round an obstacle never points into it, so a greedy
    policy that follows it cannot oscillate in front of a wall. Uses ``w.path[e]`` as scratch
    (the kernels allocate nothing): ``seen`` is -1 everywhere between calls, and only the
    cells a search reached are reset after it, so a search costs the cells it explores, not
    the grid (a 256 x 256 site)."""
    queue, seen = w.path[e, 0], w.path[e, 1]
    g = world_of(w, e)
    start = x * sy + y
    seen[start] = 0
    queue[0] = start
    head, tail = 0, 1
    while head < tail:
        c = queue[head]
        head += 1
        cx, cy = c // sy, c % sy
        if c != start and _work_within(w, g, cx, cy, reach, sx, sy):
            m = seen[c] % 4
            found = MOVE_DX[m], MOVE_DY[m], seen[c] // 4
            for r in range(tail):
                seen[queue[r]] = -1
            return found
        for m in range(4):
            nx, ny = cx + MOVE_DX[m], cy + MOVE_DY[m]
            if 0 <= nx < sx and 0 <= ny < sy and not w.blocked[g, nx, ny, z]:
                k = nx * sy + ny
                if seen[k] < 0:
                    # moves * 4 + the first move of the way (inherited past the start)
                    seen[k] = (seen[c] // 4 + 1) * 4 + (m if c == start else seen[c] % 4)
                    queue[tail] = k
                    tail += 1
    for r in range(tail):
        seen[queue[r]] = -1
    return 0, 0, -1


@numba.njit(cache=True)
def action_mask(w, p, e, out):
    """Write into ``out[e]`` which of world e's 12 actions can change something.

    A move is valid when its cell lies inside the grid and is free; a camera action when its
    setting is not already at the limit it pushes towards. An invalid action is a collision or
    a camera action that holds: it only spends energy, and a policy that repeats it loops.
    At least one tilt action is always valid, so a mask never rules out every action.

    The stall guard: once coverage has not grown for ``p.stall_guard`` steps (0: never), one
    action stays valid until coverage grows again, and :func:`step_one` carries it out
    whatever the policy chose; the first of these that exists: the first move of the way, at
    the UAV's altitude, to the nearest ground not yet covered (the observation's target by
    path); with the paper's camera, the first move of the way to the nearest cell whose
    footprint, at the camera's pose now, holds such ground (ground seen only from beside it,
    say in a courtyard); a zoom or tilt that widens that footprint; a climb (more cells are
    free higher up). Else the mask is left as it is. A deterministic policy that a state
    leaves nearly indifferent otherwise repeats a two-cell loop until its battery ends
    (docs/results.md, "The stall guard").
    """
    st = w.status[e]
    if w.left[e]:
        # A UAV that has left the episode (a fleet's): one action, which the step ignores;
        # a masked policy's only choice carries no gradient.
        out[e, :] = False
        out[e, PARKED] = True
        return
    x, y, z = st["x"], st["y"], st["z"]
    for a in range(N_MOVES):
        out[e, a] = open_cell(w, p, e, x + MOVES[a, 0], y + MOVES[a, 1], z + MOVES[a, 2])
    out[e, TILT_PLUS] = st["tilt"] < TILT_MAX
    out[e, TILT_MINUS] = st["tilt"] > TILT_MIN
    out[e, PAN_PLUS] = st["pan"] < PAN_MAX
    out[e, PAN_MINUS] = st["pan"] > PAN_MIN
    out[e, ZOOM_PLUS] = st["zoom10"] < ZOOM_MAX10
    out[e, ZOOM_MINUS] = st["zoom10"] > ZOOM_MIN10
    way = guard_action(w, p, e)
    if way >= 0:
        out[e, :] = False
        out[e, way] = True


@numba.njit(cache=True)
def guard_action(w, p, e):
    """The stall guard's one action for world e now (see :func:`action_mask`), or -1 when the
    guard is off, not yet due, or finds nothing to do."""
    if not guarded(w, p, e):
        return -1
    st = w.status[e]
    x, y, z = st["x"], st["y"], st["z"]
    dx, dy, moves = path_to_work(w, e, x, y, z, p.size_x, p.size_y, 0)
    if moves < 0 and p.model == PAPER:
        reach = paper_half_width(st["tilt"], st["zoom10"])
        if reach > 0:
            dx, dy, moves = path_to_work(w, e, x, y, z, p.size_x, p.size_y, reach)
    way = -1
    if moves > 0:
        way = X_PLUS if dx > 0 else X_MINUS if dx < 0 else Y_PLUS if dy > 0 else Y_MINUS
    elif p.model == PAPER and st["zoom10"] < ZOOM_MAX10:
        way = ZOOM_PLUS
    elif p.model == PAPER and st["tilt"] >= PAPER_NADIR_TILT:
        way = TILT_MINUS
    elif open_cell(w, p, e, x, y, z + 1):
        way = Z_PLUS
    return way


@numba.njit(cache=True)
def steer(w, p, e, a):
    """The action world e carries out when its policy chose ``a``: the stall guard's, while
    the guard holds (a policy that ignores the mask is steered all the same), else ``a``."""
    way = guard_action(w, p, e)
    return a if way < 0 else way


@numba.njit(cache=True)
def guarded(w, p, e):
    """Whether world e's next action is under the stall guard (``env.stall_guard``): its
    coverage has not grown for that many steps."""
    return p.stall_guard > 0 and w.status[e]["steps"] - w.progress[e] >= p.stall_guard


@numba.njit(**BATCH_KERNEL)
def action_masks(w, p, worlds, out):
    """:func:`action_mask` of each world index in ``worlds`` (after a reset)."""
    for k in range(worlds.shape[0]):
        action_mask(w, p, worlds[k], out)


@numba.njit(cache=True)
def visit(w, e):
    """Count a visit to world e's current cell; return its curiosity term 1/sqrt(visits)."""
    st = w.status[e]
    w.visits[e, st["x"], st["y"], st["z"]] += 1
    return 1.0 / np.sqrt(w.visits[e, st["x"], st["y"], st["z"]])


class StepOutcome(NamedTuple):
    """What one step did to a world, as :func:`close_step` books it."""

    used: float
    """Energy units the step spent."""
    new: int
    """Ground cells its view added."""
    moved: bool
    """Whether the UAV's cell changed."""
    cam_changed: bool
    """Whether tilt, pan or zoom changed."""
    collision: bool
    """Whether the move was blocked (an obstacle, the grid's edge, a contact in flight)."""
    wind: bool
    """Whether something other than the action moved the UAV (a gust, a drift)."""
    curiosity: float
    """The curiosity term of the cell moved into (0 without a move)."""


@numba.njit(cache=True)
def close_step(w, p, e, out):
    """Book the end of world e's step (``out``, a :class:`StepOutcome`): battery, counters,
    raw reward terms, episode end. Fills ``w.terms[e]`` and ``w.flags[e]``."""
    st = w.status[e]
    terms = w.terms
    new = out.new
    redundant = new == 0
    idle = not out.moved and not out.cam_changed and not out.collision
    w.energy[e] -= out.used
    if guarded(w, p, e):
        w.guarded[e] += 1
    st["steps"] += 1
    if out.collision:
        st["collisions"] += 1
    if redundant:
        st["redundant_steps"] += 1
    if out.wind:
        st["wind_pushes"] += 1

    terms[e, T_COVERAGE] = new / p.max_footprint
    terms[e, T_REDUNDANT] = 1.0 if redundant else 0.0
    terms[e, T_BATTERY] = out.used / p.energy_move
    terms[e, T_CAM] = 1.0 if (out.cam_changed and new > 0) else 0.0
    terms[e, T_CURIOSITY] = out.curiosity
    terms[e, T_COLLISION] = 1.0 if out.collision else 0.0
    terms[e, T_IDLE] = 1.0 if idle else 0.0
    terms[e, T_LLM] = 0.0

    terminated = w.energy[e] <= 0.0 or st["covered"] >= st["coverable"]
    f = w.flags[e]
    f["collision"] = out.collision
    f["redundant"] = redundant
    f["idle"] = idle
    f["terminated"] = terminated
    f["truncated"] = (not terminated) and st["steps"] >= p.step_limit
    f["wind"] = out.wind
    f["new_cells"] = new
    if new > 0:
        w.progress[e] = st["steps"]


@numba.njit(cache=True)
def park(w, e):
    """Book a step of slot e, whose UAV has left the episode: nothing happens, no reward
    term, and the slot reports its end again (each such step is an episode of one step with
    reward 0; the mask leaves one action, so a masked policy learns nothing from it)."""
    w.terms[e, :] = 0.0
    f = w.flags[e]
    f["collision"] = 0
    f["redundant"] = 0
    f["idle"] = 0
    f["terminated"] = 1
    f["truncated"] = 0
    f["wind"] = 0
    f["new_cells"] = 0


@numba.njit(cache=True)
def step_fleet(w, p, g, actions):
    """Step every UAV of world g (``actions``: one per slot of the batch); return 1 when the
    world's episode ended.

    The UAVs move one after another, each seeing where the ones before it went: a move into
    a cell a teammate took earlier in the step holds (a yield, not a collision), and a ground
    cell that several UAVs see in one step is credited to the first. The order turns by one
    every step (UAV ``t mod K`` first at step t), so no UAV is first more often than another.
    A UAV leaves when its battery is spent or the fleet's coverage is complete; the episode
    ends when every UAV has left or the step limit truncates the ones still flying.
    """
    k = fleet_size(w)
    first = g * k
    turn = w.clock[g]
    w.clock[g] = turn + 1
    parked = 0  # bit u: UAV u had left before this step (K <= MAX_UAVS)
    for j in range(k):
        u = (turn + j) % k
        e = first + u
        if w.left[e]:
            park(w, e)
            parked |= 1 << u
        else:
            step_one(w, p, e, actions[e])
    for a in range(first, first + k):
        if w.left[a]:
            continue
        sa = w.status[a]
        for b in range(a + 1, first + k):
            if not w.left[b]:
                sb = w.status[b]
                d = abs(sa["x"] - sb["x"]) + abs(sa["y"] - sb["y"]) + abs(sa["z"] - sb["z"])
                if d == 1:
                    w.near[g] += 1
    complete = w.status[first]["covered"] >= w.status[first]["coverable"]
    flying = 0
    for u in range(k):
        if parked & (1 << u):
            continue
        e = first + u
        f = w.flags[e]
        if complete and not f["terminated"]:
            # The fleet finished on a later UAV's view: every UAV still flying ends here.
            f["terminated"] = 1
            f["truncated"] = 0
        if f["terminated"]:
            w.left[e] = True
        elif not f["truncated"]:
            flying += 1
    return 1 if flying == 0 else 0


@numba.njit(cache=True)
def step_one(w, p, e, a):
    """Apply action ``a`` (or the stall guard's, :func:`steer`) to world e; fill its ``terms``
    (raw reward terms) and ``flags``.

    Flight (a move to a free cell, else a collision) and the wind gust are the grid's own; the
    camera, the view, the visit and the step's close are the rules above, which the physics
    evaluation shares.
    """
    st = w.status[e]
    g = world_of(w, e)
    x, y, z = st["x"], st["y"], st["z"]
    tilt, pan, zoom = st["tilt"], st["pan"], st["zoom10"]
    collision = False
    if p.stall_guard > 0:
        a = steer(w, p, e, a)
    if a < N_MOVES:
        nx, ny, nz = x + MOVES[a, 0], y + MOVES[a, 1], z + MOVES[a, 2]
        if open_cell(w, p, e, nx, ny, nz):
            st["x"], st["y"], st["z"] = nx, ny, nz
        elif held(w, e, nx, ny, nz) and free(w.blocked, p, world_of(w, e), nx, ny, nz):
            # A teammate took the cell earlier in this step: the UAV holds, no collision.
            w.yields[e] += 1
        else:
            collision = True
        if a < Z_PLUS:
            used = p.energy_move
            if w.ground.shape[1] > 0 and (st["x"] != x or st["y"] != y):
                # Over terrain a level move climbs or descends with the ground, paid as the
                # level moves are, per level of height (docs/sites.md).
                rise = w.ground[g, st["x"], st["y"]] - w.ground[g, x, y]
                used += rise * p.energy_climb if rise > 0 else -rise * p.energy_descend
        elif a == Z_PLUS:
            used = p.energy_climb
        else:
            used = p.energy_descend
    else:
        used = p.energy_camera
        camera_action(w, e, a)
    used += p.energy_hover

    wind = False
    if p.wind_prob > 0.0 and _next_uniform(w.rng, e) < p.wind_prob:
        d = min(3, int(_next_uniform(w.rng, e) * 4.0))
        wx, wy = st["x"] + WIND_DIRS[d, 0], st["y"] + WIND_DIRS[d, 1]
        if open_cell(w, p, e, wx, wy, st["z"]):
            st["x"], st["y"] = wx, wy
            wind = True

    moved = st["x"] != x or st["y"] != y or st["z"] != z
    cam_changed = st["tilt"] != tilt or st["pan"] != pan or st["zoom10"] != zoom
    new = observe(w, p, e, True)
    curiosity = visit(w, e) if moved else 0.0
    close_step(w, p, e, StepOutcome(used, new, moved, cam_changed, collision, wind, curiosity))
