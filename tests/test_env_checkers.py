"""Gymnasium's and Stable-Baselines3's environment checkers on several sizes and footprints."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from pirl.env import VCPPEnv

SIZES = [(3, 3, 3), (15, 15, 3), (30, 30, 3), (40, 25, 4)]


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
@pytest.mark.parametrize("size", SIZES)
def test_gymnasium_check_env(size, footprint):
    env = gym.make("pirl/VCPP-v0", size=size, footprint=footprint)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        gym_check_env(env.unwrapped)


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
@pytest.mark.parametrize("size", SIZES)
def test_sb3_check_env(size, footprint):
    env = gym.make("pirl/VCPP-v0", size=size, footprint=footprint)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize(
    "settings",
    [
        {"reward": "ewri", "wind_prob": 1.0},
        {"footprint": "frustum", "occlusion": True, "obstacles_max": 8},
        {"render_mode": "rgb_array", "size": (20, 12, 3)},
        {"obs_window": 5, "obs_global": 4, "start_tilt": 0, "start_zoom": 2.0},
    ],
)
def test_checkers_on_other_settings(settings):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(gym.make("pirl/VCPP-v0", **settings).unwrapped)
        sb3_check_env(VCPPEnv(**settings), warn=True)


def test_spaces():
    env = gym.make("pirl/VCPP-v0")
    assert env.action_space == gym.spaces.Discrete(12)
    assert env.observation_space.shape == (317,)
    assert env.observation_space.dtype == np.float32
    assert (env.observation_space.low == 0).all() and (env.observation_space.high == 1).all()


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
def test_random_rollout_stays_in_the_spaces(footprint):
    env = gym.make("pirl/VCPP-v0", size=(10, 8, 3), footprint=footprint, max_steps=40)
    obs, info = env.reset(seed=0)
    rng = np.random.default_rng(0)
    episodes = 0
    for _ in range(400):
        obs, reward, terminated, truncated, info = env.step(int(rng.integers(12)))
        assert env.observation_space.contains(obs)
        assert isinstance(reward, float) and np.isfinite(reward)
        assert isinstance(terminated, bool) and isinstance(truncated, bool)
        if terminated or truncated:
            episodes += 1
            obs, info = env.reset()
            assert env.observation_space.contains(obs)
    assert episodes >= 3


def test_numpy_actions_are_accepted_and_bad_ones_refused():
    env = gym.make("pirl/VCPP-v0", wind_prob=0.0).unwrapped
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.int64(6))
    assert info["steps"] == 1 and info["idle"]  # tilt+5 at tilt 90
    _, _, _, _, info = env.step(np.array(7))
    assert info["steps"] == 2 and info["camera"][0] == 85
    for bad in (12, -1, 3.5, np.array([1, 2])):
        with pytest.raises(ValueError):
            env.step(bad)


def test_size_one_array_action_is_accepted_without_deprecation():
    """The env accepts a size-1 array action; converting it must not rely on int(ndim>0 array).

    NumPy >= 1.25 deprecates int() of an array with ndim > 0 (an error in later releases).
    """
    env = gym.make("pirl/VCPP-v0", wind_prob=0.0).unwrapped
    env.reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, _, _, _, info = env.step(np.array([6]))
    assert info["steps"] == 1
