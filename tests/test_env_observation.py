"""The observation: fixed size, in [0, 1], and its channels on hand-made worlds."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from pirl.env.observation import N_SCALARS, obs_size

W, G = 11, 8
WW = W * W
SCALARS = 2 * WW + G * G


def split(obs: np.ndarray, w: int = W, g: int = G):
    """(uncovered window, blocked window, global map, scalars) of an observation."""
    ww = w * w
    return (
        obs[:ww].reshape(w, w),
        obs[ww : 2 * ww].reshape(w, w),
        obs[2 * ww : 2 * ww + g * g].reshape(g, g),
        obs[2 * ww + g * g :],
    )


@pytest.mark.parametrize("size", [(3, 3, 3), (15, 15, 3), (60, 60, 3), (40, 25, 4)])
@pytest.mark.parametrize("footprint", ["paper", "frustum"])
def test_fixed_size_and_range(size, footprint):
    env = gym.make("pirl/VCPP-v0", size=size, footprint=footprint, wind_prob=0.3)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (317,) and obs.dtype == np.float32
    rng = np.random.default_rng(0)
    for _ in range(60):
        obs, _, terminated, truncated, _ = env.step(int(rng.integers(12)))
        assert obs.shape == (317,) and obs.dtype == np.float32
        assert (obs >= 0.0).all() and (obs <= 1.0).all()
        if terminated or truncated:
            obs, _ = env.reset()


def test_size_follows_window_and_global_settings():
    assert obs_size(11, 8) == 317 == 2 * 121 + 64 + N_SCALARS
    env = gym.make("pirl/VCPP-v0", obs_window=5, obs_global=4)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2 * 25 + 16 + 11,) == env.observation_space.shape


def test_window_channels_on_a_hand_made_world(open_env):
    # Sphere at (9, 7, 1), radius 1: at the UAV's level z = 1 it blocks (9,7), (8,7), (10,7),
    # (9,6), (9,8); on the ground only (9,7) (distance 1 from the centre).
    env, obs, _ = open_env((7, 7, 1), size=(15, 15, 3), obstacles=[[9.0, 7.0, 1.0, 1.0]])
    uncovered, blocked, _, _ = split(obs)
    # The window covers x 2..12 (rows) and y 2..12 (columns).
    expected_uncovered = np.ones((W, W))
    expected_uncovered[4:7, 4:7] = 0.0  # the 3x3 view around (7, 7) is covered
    expected_uncovered[7, 5] = 0.0  # (9, 7) is not coverable
    assert np.array_equal(uncovered, expected_uncovered)
    expected_blocked = np.zeros((W, W))
    for x, y in [(9, 7), (8, 7), (10, 7), (9, 6), (9, 8)]:
        expected_blocked[x - 2, y - 2] = 1.0
    assert np.array_equal(blocked, expected_blocked)

    # One step along +y: the window slides and the new column is covered.
    obs, _, _, _, _ = env.step(2)  # (7, 8, 1)
    uncovered, blocked, _, _ = split(obs)
    expected_uncovered = np.ones((W, W))
    expected_uncovered[4:7, 3:7] = 0.0  # y 6..9 of x 6..8 covered, window now y 3..13
    expected_uncovered[7, 4] = 0.0
    assert np.array_equal(uncovered, expected_uncovered)
    expected_blocked = np.zeros((W, W))
    for x, y in [(9, 7), (8, 7), (10, 7), (9, 6), (9, 8)]:
        expected_blocked[x - 2, y - 3] = 1.0
    assert np.array_equal(blocked, expected_blocked)


def test_window_outside_the_grid_is_blocked_and_not_uncovered(open_env):
    env, obs, _ = open_env((0, 0, 0), size=(15, 15, 3))
    uncovered, blocked, _, _ = split(obs)
    outside = np.ones((W, W), dtype=bool)
    outside[5:, 5:] = False  # rows/cols 5.. are x/y 0..5
    assert (blocked[outside] == 1.0).all()
    assert (blocked[~outside] == 0.0).all()
    assert (uncovered[outside] == 0.0).all()
    expected = np.ones((6, 6))
    expected[:2, :2] = 0.0  # the clipped 2x2 view is covered
    assert np.array_equal(uncovered[5:, 5:], expected)


def test_scalars(open_env):
    env, obs, info = open_env(
        (7, 7, 1), size=(15, 15, 3), obstacles=[[9.0, 7.0, 1.0, 1.0]], start_tilt=45,
        start_pan=-30, start_zoom=1.4,
    )  # fmt: skip
    s = split(obs)[3]
    assert s.shape == (11,)
    coverable = info["coverable"]
    assert coverable == 15 * 15 - 1
    expected = [
        7 / 14, 7 / 14, 1 / 2, 45 / 90, 60 / 180, (1.4 - 0.5) / 1.5, 1.0,
        info["covered"] / coverable, 1.0, 0.0, 0.0,
    ]  # fmt: skip
    assert s == pytest.approx(expected, abs=1e-6)
    obs, _, _, _, info = env.step(2)  # y+ to (7, 8, 1)
    s = split(obs)[3]
    limit = env.unwrapped.world.step_limit
    assert s[1] == pytest.approx(8 / 14)
    assert s[6] == pytest.approx(info["battery"])
    assert s[7] == pytest.approx(info["covered"] / coverable)
    assert s[8] == pytest.approx((limit - 1) / limit)


def test_blocked_above_and_below(open_env):
    # UAV at the top level, right above the sphere's top cell (9, 7, 1).
    env, obs, _ = open_env((9, 7, 2), size=(15, 15, 3), obstacles=[[9.0, 7.0, 0.0, 1.0]])
    s = split(obs)[3]
    assert (s[9], s[10]) == (1.0, 1.0)  # above: outside the grid; below: the sphere
    env, obs, _ = open_env((3, 3, 0), size=(15, 15, 3))
    s = split(obs)[3]
    assert (s[9], s[10]) == (0.0, 1.0)  # below the ground level is outside


def test_global_map_is_the_uncovered_share_per_block(open_env):
    env, obs, _ = open_env((7, 7, 1), size=(15, 15, 3), obstacles=[[9.0, 7.0, 1.0, 1.0]])
    for action in (0, 0, 2, 2, 2):
        obs, _, _, _, _ = env.step(action)
    world = env.unwrapped.world
    global_map = split(obs)[2]
    todo = world.coverable[0] & ~world.covered(0)
    # Cells split into G blocks per axis by floor(i * G / X).
    block = np.arange(15) * G // 15
    expected = np.zeros((G, G))
    for bi in range(G):
        for bj in range(G):
            cells = np.ix_(block == bi, block == bj)
            total = world.coverable[0][cells].sum()
            expected[bi, bj] = todo[cells].sum() / total if total else 0.0
    assert global_map == pytest.approx(expected, abs=1e-6)
    assert global_map.min() < 1.0 and global_map.max() == 1.0


def test_global_map_on_a_large_world_has_the_same_resolution(open_env):
    env, obs, _ = open_env((0, 0, 0), size=(60, 60, 3))
    global_map = split(obs)[2]
    # Only the 2x2 corner view is covered: block (0, 0) holds 8x8 = 64 cells, 4 of them seen.
    assert global_map[0, 0] == pytest.approx(60 / 64)
    assert (np.delete(global_map.ravel(), 0) == 1.0).all()


def test_a_block_without_coverable_cells_reads_zero(open_env):
    # A 3x3 world with G = 8: cells x (and y) 0, 1, 2 fall in blocks 0, 2, 5; the other blocks
    # hold no cell and read 0. From (0, 0) the view covers x/y 0..1, leaving x = 2 or y = 2.
    env, obs, _ = open_env((0, 0, 2), size=(3, 3, 3))
    global_map = split(obs)[2]
    expected = np.zeros((G, G))
    for i in (0, 2, 5):
        expected[5, i] = expected[i, 5] = 1.0
    assert np.array_equal(global_map, expected)
