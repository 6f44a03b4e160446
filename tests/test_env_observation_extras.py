"""The optional observation blocks: visit counts around the UAV, and the way to the work left."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from pirl.env import make_vec_env
from pirl.env.observation import N_SCALARS, TARGET_RANGE, obs_size
from pirl.world import dynamics as D

W, G = 11, 8
BASE = obs_size(W, G)
SMALL = {"size": (20, 20, 3), "max_steps": 80, "scale_by_alpha": False, "wind_prob": 0.0}


def test_sizes_and_default_layout_unchanged():
    assert BASE == 2 * W * W + G * G + N_SCALARS == 317
    plain = gym.make("pirl/VCPP-v0", **SMALL).unwrapped
    both = gym.make("pirl/VCPP-v0", obs_visits=True, obs_target=True, **SMALL).unwrapped
    assert both.observation_space.shape == (BASE + W * W + 3,)
    a, _ = plain.reset(seed=4)
    b, _ = both.reset(seed=4)
    assert np.array_equal(a, b[:BASE])  # the paper's block comes first, unchanged
    assert ((b >= 0) & (b <= 1)).all()


def test_visit_window_counts_the_cells_flown_through():
    env = gym.make("pirl/VCPP-v0", obs_visits=True, **SMALL).unwrapped
    env.reset(seed=2)
    mask = env.action_masks()
    move = next(a for a in (D.X_PLUS, D.X_MINUS, D.Y_PLUS, D.Y_MINUS) if mask[a])
    back = move + 1 if move % 2 == 0 else move - 1
    obs = None
    for a in (move, back, move, back):
        obs, *_ = env.step(a)
    window = obs[BASE : BASE + W * W].reshape(W, W)
    centre = W // 2
    assert window[centre, centre] == 1.0  # the start (a visit at reset) and two returns
    dx, dy, _ = D.MOVE_DELTAS[move]
    assert np.isclose(window[centre + dx, centre + dy], 2 / 3)  # flown into twice
    assert window.sum() == np.float32(1.0) + np.float32(2 / 3)


def test_target_points_at_the_nearest_uncovered_cell():
    venv = make_vec_env(3, seed=9, obs_target=True, **SMALL)
    obs = venv.reset()
    w = venv.world
    for e in range(3):
        x, y, _ = w.position(e)
        todo = np.argwhere(w.coverable[e] & (w.views[e] == 0))
        d = np.sqrt(((todo - [x, y]) ** 2).sum(axis=1))
        k = int(np.argmin(d))
        tx, ty, dist = obs[e, -3:]
        assert np.isclose(tx, ((todo[k, 0] - x) / d[k] + 1) / 2, atol=1e-6)
        assert np.isclose(ty, ((todo[k, 1] - y) / d[k] + 1) / 2, atol=1e-6)
        assert np.isclose(dist, min(d[k], TARGET_RANGE) / TARGET_RANGE, atol=1e-6)


def _way(blocked: np.ndarray, todo: np.ndarray, x: int, y: int, z: int):
    """Breadth-first search in plain Python, moves in the action order x+, x-, y+, y-: the
    first move and length of the way to the nearest cell of ``todo``, or None."""
    from collections import deque

    sx, sy = todo.shape
    first = {(x, y): None}
    moves = {(x, y): 0}
    queue = deque([(x, y)])
    while queue:
        c = queue.popleft()
        if c != (x, y) and todo[c]:
            return first[c], moves[c]
        for m in (D.X_PLUS, D.X_MINUS, D.Y_PLUS, D.Y_MINUS):
            dx, dy, _ = D.MOVE_DELTAS[m]
            n = (c[0] + dx, c[1] + dy)
            if 0 <= n[0] < sx and 0 <= n[1] < sy and not blocked[n[0], n[1], z] and n not in moves:
                moves[n] = moves[c] + 1
                first[n] = m if c == (x, y) else first[c]
                queue.append(n)
    return None


def test_path_target_follows_the_way_round_obstacles():
    """With obs_target_path the block gives the first move of the shortest way (at the UAV's
    altitude, round blocked cells) to the nearest uncovered cell: a move the mask allows, the
    same as an independent search, at every step of random flights."""
    venv = make_vec_env(4, seed=5, obs_target=True, obs_target_path=True, **SMALL)
    obs = venv.reset()
    rng = np.random.default_rng(0)
    w = venv.world
    checked = 0
    for _ in range(40):
        masks = venv.action_masks()
        for e in range(4):
            x, y, z = w.position(e)
            todo = w.coverable[e] & (w.views[e] == 0)
            way = _way(w.blocked[e], todo, x, y, z)
            if todo[x, y] or way is None:  # above work, or none reachable at this altitude
                continue
            move, moves = way
            dx, dy, _ = D.MOVE_DELTAS[move]
            assert np.allclose(obs[e, -3:], [(dx + 1) / 2, (dy + 1) / 2, min(moves, 16) / 16])
            assert masks[e, move]  # never into a wall or off the grid
            checked += 1
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
        obs, *_ = venv.step(actions)
    assert checked > 100
    assert w.blocked.any()  # the worlds had obstacles to go round


def test_path_target_needs_the_target_block():
    import pytest

    from pirl.config.errors import ConfigError
    from pirl.config.world import VCPPConfig

    with pytest.raises(ConfigError, match="obs_target_path.*needs obs_target"):
        VCPPConfig(obs_target_path=True)


def test_visit_window_saturates_at_its_cap():
    env = gym.make("pirl/VCPP-v0", obs_visits=True, obs_visits_cap=8, **SMALL).unwrapped
    env.reset(seed=2)
    mask = env.action_masks()
    move = next(a for a in (D.X_PLUS, D.X_MINUS, D.Y_PLUS, D.Y_MINUS) if mask[a])
    back = move + 1 if move % 2 == 0 else move - 1
    for a in (move, back) * 6:
        obs, *_ = env.step(a)
    window = obs[BASE : BASE + W * W].reshape(W, W)
    centre = W // 2
    dx, dy, _ = D.MOVE_DELTAS[move]
    # Seven visits (the start and six returns) and six: under a cap of 3 both would read 1.
    assert np.isclose(window[centre, centre], 7 / 8)
    assert np.isclose(window[centre + dx, centre + dy], 6 / 8)
