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
