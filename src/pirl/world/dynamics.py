"""The rules of the grid world, compiled with numba and applied to a batch of worlds.

A single environment is a batch of one: the single and batched environments call the same
kernels, so they cannot disagree. Per-world integer state lives in one table ``ints`` whose
columns are named below; per-world bookkeeping grids have the batch as first axis.
"""

from __future__ import annotations

import numba
import numpy as np

from pirl.config.grid import (
    PAN_MAX,
    PAN_MIN,
    PAN_STEP,
    TILT_MAX,
    TILT_MIN,
    TILT_STEP,
    ZOOM_MAX10,
    ZOOM_MIN10,
    ZOOM_STEP10,
)
from pirl.world.footprint import footprint_cells

# Columns of the per-world integer table.
PX, PY, PZ, TILT, PAN, ZOOM = 0, 1, 2, 3, 4, 5
STEPS, COVERED, COVERABLE, RED_CELLS, MULTI_CELLS, VIEWS = 6, 7, 8, 9, 10, 11
COLLISIONS, RED_STEPS, CAM_ACTIONS, N_OBS, FOOT_SUM, WIND_PUSHES = 12, 13, 14, 15, 16, 17
N_INT_COLS = 18

# Columns of the per-step flag table.
F_COLLISION, F_REDUNDANT, F_IDLE, F_TERMINATED, F_TRUNCATED, F_WIND, F_NEW = 0, 1, 2, 3, 4, 5, 6
N_FLAG_COLS = 7

# Reward term columns, in the order of pirl.config.world.REWARD_TERMS.
T_COVERAGE, T_REDUNDANT, T_BATTERY, T_CAM, T_CURIOSITY, T_COLLISION, T_IDLE, T_LLM = range(8)
N_TERMS = 8

# Scalar parameters passed to the kernels (floats and ints, see WorldBatch.params).
PF_FOV, PF_RANGE, PF_WIND, PF_E_MOVE, PF_E_CLIMB, PF_E_DESCEND, PF_E_CAM, PF_E_HOVER = range(8)
PF_MAX_FP = 8
N_PF = 9
PI_MODEL, PI_OCCLUSION, PI_X, PI_Y, PI_Z, PI_STEP_LIMIT = range(6)
N_PI = 6

# Actions in the paper's order; the names say what each one does.
X_PLUS, X_MINUS, Y_PLUS, Y_MINUS, Z_PLUS, Z_MINUS = 0, 1, 2, 3, 4, 5
TILT_PLUS, TILT_MINUS, PAN_PLUS, PAN_MINUS, ZOOM_PLUS, ZOOM_MINUS = 6, 7, 8, 9, 10, 11
N_MOVES = 6  # actions below N_MOVES move the UAV, the others steer the camera
N_ACTIONS = 12
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
WIND_DIRS = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], dtype=np.int64)


@numba.njit(cache=True, inline="always")
def _next_uniform(rng, e):
    """splitmix64: a small counter-based generator per world, so wind is reproducible."""
    state = rng[e] + np.uint64(0x9E3779B97F4A7C15)
    rng[e] = state
    z = state
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, inline="always")
def _free(blocked, e, x, y, z, sx, sy, sz):
    return 0 <= x < sx and 0 <= y < sy and 0 <= z < sz and not blocked[e, x, y, z]


@numba.njit(cache=True, inline="always")
def book_view(e, cells, n, ints, coverable, views, redmask, blk_todo, bx, by, mark_redundant):
    """Book one view of world e (the first ``n`` distinct rows (i, j) of ``cells``).

    Counts new cells, views and cells seen twice, keeps the coarse map's per-block counts and,
    with ``mark_redundant``, marks the cells of a view that adds nothing as redundantly viewed
    (the set C_redundant of the RVC metric). Returns the number of new cells. The grid books
    its footprint here; the physics evaluation books the union of a flight's views here too.
    """
    new = 0
    seen = 0
    for k in range(n):
        i, j = cells[k, 0], cells[k, 1]
        if not coverable[e, i, j]:
            continue
        seen += 1
        v = views[e, i, j]
        if v == 0:
            new += 1
            blk_todo[e, bx[i], by[j]] -= 1
        elif v == 1:
            ints[e, MULTI_CELLS] += 1
        views[e, i, j] = v + 1
    ints[e, COVERED] += new
    ints[e, VIEWS] += seen
    if new == 0 and mark_redundant:
        for k in range(n):
            i, j = cells[k, 0], cells[k, 1]
            if coverable[e, i, j] and not redmask[e, i, j]:
                redmask[e, i, j] = True
                ints[e, RED_CELLS] += 1
    return new


@numba.njit(cache=True, inline="always")
def observe(
    e, ints, coverable, views, redmask, blk_todo, bx, by, obstacles, pf, pi, buf, mark_redundant
):
    """Look from world e's current pose, book the view (:func:`book_view`); return new cells."""
    n = footprint_cells(
        pi[PI_MODEL], ints[e, PX], ints[e, PY], ints[e, PZ], ints[e, TILT], ints[e, PAN],
        ints[e, ZOOM], pi[PI_X], pi[PI_Y], pf[PF_FOV], pf[PF_RANGE], pi[PI_OCCLUSION] != 0,
        obstacles[e], ints[e, N_OBS], buf,
    )  # fmt: skip
    ints[e, FOOT_SUM] += n
    return book_view(e, buf, n, ints, coverable, views, redmask, blk_todo, bx, by, mark_redundant)


@numba.njit(cache=True, inline="always")
def camera_action(e, a, ints):
    """Apply camera action ``a`` (6-11) to world e: steps of 5 degrees, 15 degrees and 0.1
    zoom; at a limit the setting holds. Counts the camera action."""
    ints[e, CAM_ACTIONS] += 1
    if a == TILT_PLUS:
        ints[e, TILT] = min(TILT_MAX, ints[e, TILT] + TILT_STEP)
    elif a == TILT_MINUS:
        ints[e, TILT] = max(TILT_MIN, ints[e, TILT] - TILT_STEP)
    elif a == PAN_PLUS:
        ints[e, PAN] = min(PAN_MAX, ints[e, PAN] + PAN_STEP)
    elif a == PAN_MINUS:
        ints[e, PAN] = max(PAN_MIN, ints[e, PAN] - PAN_STEP)
    elif a == ZOOM_PLUS:
        ints[e, ZOOM] = min(ZOOM_MAX10, ints[e, ZOOM] + ZOOM_STEP10)
    else:
        ints[e, ZOOM] = max(ZOOM_MIN10, ints[e, ZOOM] - ZOOM_STEP10)


@numba.njit(cache=True, inline="always")
def action_mask(e, ints, blocked, pi, out):
    """Write into ``out[e]`` which of world e's 12 actions can change something.

    A move is valid when its cell lies inside the grid and is free; a camera action when its
    setting is not already at the limit it pushes towards. An invalid action is a collision or
    a camera action that holds: it only spends energy, and a policy that repeats it loops.
    At least one tilt action is always valid, so a mask never rules out every action.
    """
    x, y, z = ints[e, PX], ints[e, PY], ints[e, PZ]
    sx, sy, sz = pi[PI_X], pi[PI_Y], pi[PI_Z]
    for a in range(N_MOVES):
        out[e, a] = _free(blocked, e, x + MOVES[a, 0], y + MOVES[a, 1], z + MOVES[a, 2], sx, sy, sz)
    out[e, TILT_PLUS] = ints[e, TILT] < TILT_MAX
    out[e, TILT_MINUS] = ints[e, TILT] > TILT_MIN
    out[e, PAN_PLUS] = ints[e, PAN] < PAN_MAX
    out[e, PAN_MINUS] = ints[e, PAN] > PAN_MIN
    out[e, ZOOM_PLUS] = ints[e, ZOOM] < ZOOM_MAX10
    out[e, ZOOM_MINUS] = ints[e, ZOOM] > ZOOM_MIN10


@numba.njit(cache=True)
def action_masks(worlds, ints, blocked, pi, out):
    """:func:`action_mask` of each world index in ``worlds`` (after a reset)."""
    for k in range(worlds.shape[0]):
        action_mask(worlds[k], ints, blocked, pi, out)


@numba.njit(cache=True, inline="always")
def visit(e, ints, visits):
    """Count a visit to world e's current cell; return its curiosity term 1/sqrt(visits)."""
    x, y, z = ints[e, PX], ints[e, PY], ints[e, PZ]
    visits[e, x, y, z] += 1
    return 1.0 / np.sqrt(visits[e, x, y, z])


@numba.njit(cache=True, inline="always")
def close_step(
    e, ints, energy, pf, pi, terms, flags, used, new, moved, cam_changed, collision, wind,
    curiosity,
):  # fmt: skip
    """Book the end of world e's step: battery, counters, raw reward terms, episode end.

    ``used`` is the energy the step spent, ``new`` the cells its view added; ``wind`` whether
    something other than the action moved the UAV. Fills ``terms[e]`` and ``flags[e]``.
    """
    redundant = new == 0
    idle = not moved and not cam_changed and not collision
    energy[e] -= used
    ints[e, STEPS] += 1
    if collision:
        ints[e, COLLISIONS] += 1
    if redundant:
        ints[e, RED_STEPS] += 1
    if wind:
        ints[e, WIND_PUSHES] += 1

    terms[e, T_COVERAGE] = new / pf[PF_MAX_FP]
    terms[e, T_REDUNDANT] = 1.0 if redundant else 0.0
    terms[e, T_BATTERY] = used / pf[PF_E_MOVE]
    terms[e, T_CAM] = 1.0 if (cam_changed and new > 0) else 0.0
    terms[e, T_CURIOSITY] = curiosity
    terms[e, T_COLLISION] = 1.0 if collision else 0.0
    terms[e, T_IDLE] = 1.0 if idle else 0.0
    terms[e, T_LLM] = 0.0

    terminated = energy[e] <= 0.0 or ints[e, COVERED] >= ints[e, COVERABLE]
    flags[e, F_COLLISION] = collision
    flags[e, F_REDUNDANT] = redundant
    flags[e, F_IDLE] = idle
    flags[e, F_TERMINATED] = terminated
    flags[e, F_TRUNCATED] = (not terminated) and ints[e, STEPS] >= pi[PI_STEP_LIMIT]
    flags[e, F_WIND] = wind
    flags[e, F_NEW] = new


@numba.njit(cache=True, inline="always")
def step_one(
    e, actions, ints, energy, rng, blocked, coverable, views, redmask, visits, blk_todo, bx, by,
    obstacles, pf, pi, buf, terms, flags,
):  # fmt: skip
    """Apply world e's action; fill its ``terms`` (raw reward terms) and ``flags``.

    Flight (a move to a free cell, else a collision) and the wind gust are the grid's own; the
    camera, the view, the visit and the step's close are the rules above, which the physics
    evaluation shares.
    """
    sx, sy, sz = pi[PI_X], pi[PI_Y], pi[PI_Z]
    a = actions[e]
    x, y, z = ints[e, PX], ints[e, PY], ints[e, PZ]
    tilt, pan, zoom = ints[e, TILT], ints[e, PAN], ints[e, ZOOM]
    collision = False
    if a < N_MOVES:
        nx, ny, nz = x + MOVES[a, 0], y + MOVES[a, 1], z + MOVES[a, 2]
        if _free(blocked, e, nx, ny, nz, sx, sy, sz):
            ints[e, PX], ints[e, PY], ints[e, PZ] = nx, ny, nz
        else:
            collision = True
        if a < Z_PLUS:
            used = pf[PF_E_MOVE]
        elif a == Z_PLUS:
            used = pf[PF_E_CLIMB]
        else:
            used = pf[PF_E_DESCEND]
    else:
        used = pf[PF_E_CAM]
        camera_action(e, a, ints)
    used += pf[PF_E_HOVER]

    wind = False
    if pf[PF_WIND] > 0.0 and _next_uniform(rng, e) < pf[PF_WIND]:
        d = min(3, int(_next_uniform(rng, e) * 4.0))
        wx, wy = ints[e, PX] + WIND_DIRS[d, 0], ints[e, PY] + WIND_DIRS[d, 1]
        if _free(blocked, e, wx, wy, ints[e, PZ], sx, sy, sz):
            ints[e, PX], ints[e, PY] = wx, wy
            wind = True

    moved = ints[e, PX] != x or ints[e, PY] != y or ints[e, PZ] != z
    cam_changed = ints[e, TILT] != tilt or ints[e, PAN] != pan or ints[e, ZOOM] != zoom
    new = observe(
        e, ints, coverable, views, redmask, blk_todo, bx, by, obstacles, pf, pi, buf[e], True
    )
    curiosity = visit(e, ints, visits) if moved else 0.0
    close_step(
        e, ints, energy, pf, pi, terms, flags, used, new, moved, cam_changed, collision, wind,
        curiosity,
    )  # fmt: skip
