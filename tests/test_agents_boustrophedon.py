"""The boustrophedon planner: coverage, obstacles, battery, wind."""

from __future__ import annotations

import numpy as np
import pytest

from pirl.agents import BoustrophedonPolicy, RandomPolicy
from pirl.env import VCPPEnv
from pirl.evaluate import run_episode
from pirl.world.scenario import Scenario

EMPTY = np.zeros((0, 4))


def _fly(env: VCPPEnv, scenario: Scenario | None, seed: int = 0) -> dict:
    obs, info = env.reset(seed=seed, options={"scenario": scenario} if scenario else None)
    policy = BoustrophedonPolicy()
    policy.reset(env.world, 0)
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        done = terminated or truncated
    return info["episode_metrics"]


@pytest.mark.parametrize("start", [(0, 0, 0), (17, 9, 2), (29, 29, 1)])
def test_obstacle_free_30x30_reaches_full_coverage(start):
    env = VCPPEnv(size=(30, 30, 3), wind_prob=0.0)
    metrics = _fly(env, Scenario(EMPTY, start, 0))
    assert metrics["vcr"] >= 0.98
    assert metrics["collisions"] == 0
    # A lawnmower with a 9x9 footprint needs about 30*30/9 moves plus set-up, far below 800.
    assert metrics["steps"] < 250


def test_covers_around_obstacles_with_wind():
    env = VCPPEnv(size=(30, 30, 3), wind_prob=0.1)
    vcrs = [_fly(env, None, seed)["vcr"] for seed in range(4)]
    assert min(vcrs) >= 0.98


@pytest.mark.parametrize("size", [(40, 25, 4), (15, 15, 3)])
def test_non_square_and_frustum(size):
    for footprint in ("paper", "frustum"):
        env = VCPPEnv(size=size, footprint=footprint)
        assert _fly(env, None, 3)["vcr"] >= 0.95


def test_respects_the_battery():
    # With energy for about 60 moves it must stop planning legs it cannot pay for and never
    # collide; it still covers a good share of the world first.
    env = VCPPEnv(size=(30, 30, 3), wind_prob=0.0, battery_capacity=15.0)
    metrics = _fly(env, Scenario(EMPTY, (0, 0, 0), 0))
    assert metrics["collisions"] == 0
    assert 0.2 < metrics["vcr"] < 0.98


def test_beats_random_by_far():
    env = VCPPEnv(size=(30, 30, 3))
    planner = run_episode(env, BoustrophedonPolicy(), seed=5).metrics
    random = run_episode(env, RandomPolicy(5), seed=5).metrics
    assert planner["vcr"] > random["vcr"] + 0.5
    assert planner["be"] > random["be"]
