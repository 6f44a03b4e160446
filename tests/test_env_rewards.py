"""Reward terms triggered on purpose, the weighted sum, static and EWRI weights."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from conftest import scenario
from pirl.config.world import EWRI_RANGES, REWARD_TERMS, STATIC_WEIGHTS

STATIC = dict(zip(REWARD_TERMS, STATIC_WEIGHTS, strict=True))
RANGES = dict(zip(REWARD_TERMS, EWRI_RANGES, strict=True))


def recomputed(info) -> float:
    return sum(info["reward_weights"][k] * info["reward_terms"][k] for k in REWARD_TERMS)


def terms_except(info, *names):
    return {k: v for k, v in info["reward_terms"].items() if k not in names}


# -- weights -------------------------------------------------------------------------------


def test_static_weights_equal_the_table_and_llm_is_zero(make_env):
    env = make_env(size=(15, 15, 3), reward="static")
    for seed in (0, 1):
        _, info = env.reset(seed=seed)
        assert info["reward_weights"] == {**STATIC, "llm": 0.0}
    _, _, _, _, info = env.step(0)
    assert info["reward_weights"] == {**STATIC, "llm": 0.0}


def test_llm_weight_is_kept_when_asked(make_env):
    env = make_env(size=(15, 15, 3), reward="static", llm_weight=True)
    _, info = env.reset(seed=0)
    assert info["reward_weights"] == STATIC
    env = make_env(size=(15, 15, 3), reward="ewri", llm_weight=True)
    _, info = env.reset(seed=0)
    low, high = RANGES["llm"]
    assert low <= info["reward_weights"]["llm"] <= high


def test_ewri_weights_in_range_redrawn_at_each_reset(make_env):
    env = make_env(size=(15, 15, 3), reward="ewri")
    _, info = env.reset(seed=0)
    draws = []
    for episode in range(30):
        if episode:
            _, info = env.reset()
        weights = info["reward_weights"]
        assert weights["llm"] == 0.0
        for term in REWARD_TERMS[:-1]:
            low, high = RANGES[term]
            assert low <= weights[term] <= high, (term, weights[term])
        # Constant within an episode.
        for action in (0, 8, 2):
            _, _, _, _, step_info = env.step(action)
            assert step_info["reward_weights"] == weights
        draws.append([weights[t] for t in REWARD_TERMS[:-1]])
    draws = np.array(draws)
    # Every reset draws anew: all 30 draws differ, and they spread over the ranges.
    assert len({tuple(d) for d in draws.tolist()}) == 30
    spread = draws.max(axis=0) - draws.min(axis=0)
    widths = np.array([h - lo for lo, h in EWRI_RANGES[:-1]])
    assert (spread > 0.5 * widths).all()


def test_ewri_weights_follow_the_seed(make_env):
    a = make_env(size=(15, 15, 3), reward="ewri")
    b = make_env(size=(15, 15, 3), reward="ewri")
    _, ia = a.reset(seed=4)
    _, ib = b.reset(seed=4)
    assert ia["reward_weights"] == ib["reward_weights"]
    _, ib = b.reset(seed=5)
    assert ia["reward_weights"] != ib["reward_weights"]


def test_ewri_with_a_replayed_scenario_still_draws_weights(open_env):
    env, _, first = open_env((2, 2, 1), reward="ewri")
    _, again = env.reset(options={"scenario": scenario((2, 2, 1))})
    assert first["reward_weights"] != again["reward_weights"]
    assert again["position"] == (2, 2, 1)


# -- the weighted sum --------------------------------------------------------------------------


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
@pytest.mark.parametrize("reward", ["static", "ewri"])
def test_reward_is_the_weighted_sum_of_the_info_terms(footprint, reward):
    env = gym.make(
        "pirl/VCPP-v0", size=(12, 12, 3), footprint=footprint, reward=reward, wind_prob=0.2,
        max_steps=50,
    )  # fmt: skip
    env.reset(seed=1)
    rng = np.random.default_rng(2)
    seen = set()
    for _ in range(300):
        _, reward_value, terminated, truncated, info = env.step(int(rng.integers(12)))
        assert reward_value == pytest.approx(recomputed(info), rel=1e-12, abs=1e-12)
        assert set(info["reward_terms"]) == set(REWARD_TERMS)
        assert 0.0 <= info["reward_terms"]["coverage"] <= 1.0
        seen |= {k for k, v in info["reward_terms"].items() if v != 0.0}
        if terminated or truncated:
            env.reset()
    assert seen == set(REWARD_TERMS) - {"llm"}


# -- each term on purpose ------------------------------------------------------------------------


def test_coverage_term_is_new_cells_over_81_for_paper(open_env):
    env, _, info = open_env((4, 4, 0), size=(9, 9, 3), scale_by_alpha=False)
    assert info["covered"] == 9
    _, reward, _, _, info = env.step(0)  # x+: column x = 6 of the 3x3 square is new
    assert info["new_cells"] == 3
    assert info["reward_terms"]["coverage"] == pytest.approx(3 / 81)
    assert info["reward_terms"]["redundant"] == 0.0
    assert info["reward_terms"]["curiosity"] == 1.0
    assert info["reward_terms"]["battery"] == pytest.approx(1.1)
    assert terms_except(info, "coverage", "curiosity", "battery") == dict.fromkeys(
        ["redundant", "cam_usage", "collision", "idle", "llm"], 0.0
    )
    assert reward == pytest.approx(3 / 81 - 0.3 * 1.1 + 0.35)


def test_coverage_term_for_frustum_uses_its_largest_footprint(open_env):
    env, _, _ = open_env((6, 6, 2), size=(13, 13, 3), footprint="frustum")
    world = env.unwrapped.world
    assert world.max_footprint > 81  # zoom 0.5 from 3 cells up sees more than any paper square
    _, _, _, _, info = env.step(0)
    assert info["new_cells"] > 0
    expected = info["new_cells"] / world.max_footprint
    assert info["reward_terms"]["coverage"] == pytest.approx(expected)


def test_redundant_term(open_env):
    env, _, _ = open_env((4, 4, 0), size=(9, 9, 3))
    env.step(0)
    _, reward, _, _, info = env.step(1)  # back: nothing new
    assert info["new_cells"] == 0
    assert info["reward_terms"]["redundant"] == 1.0
    assert info["reward_terms"]["coverage"] == 0.0
    assert info["reward_terms"]["curiosity"] == pytest.approx(1 / math.sqrt(2))
    assert reward == pytest.approx(-0.6 - 0.3 * 1.1 + 0.35 / math.sqrt(2))


@pytest.mark.parametrize(
    ("action", "battery"),
    [(0, 1.1), (2, 1.1), (4, 1.6), (5, 0.8), (7, 0.3), (9, 0.3), (10, 0.3)],
)
def test_battery_term_is_energy_over_one_move(open_env, action, battery):
    env, _, _ = open_env((4, 4, 1), size=(9, 9, 3))
    _, _, _, _, info = env.step(action)
    assert info["reward_terms"]["battery"] == pytest.approx(battery)


def test_cam_usage_term(open_env):
    env, _, _ = open_env((4, 4, 1), size=(9, 9, 3), start_tilt=80)
    _, reward, _, _, info = env.step(7)  # tilt 75: the square grows from 3x3 to 5x5
    assert info["camera"][0] == 75
    assert info["new_cells"] == 16
    assert info["reward_terms"]["cam_usage"] == 1.0
    assert info["reward_terms"]["coverage"] == pytest.approx(16 / 81)
    assert info["reward_terms"]["curiosity"] == 0.0
    assert reward == pytest.approx(16 / 81 + 0.4 - 0.3 * 0.3)
    # A camera action that adds nothing earns nothing.
    _, _, _, _, info = env.step(9)  # pan changes; the paper square does not care
    assert info["reward_terms"]["cam_usage"] == 0.0
    assert info["redundant"] and not info["idle"]
    # A move that adds cells is not camera usage.
    _, _, _, _, info = env.step(0)
    assert info["new_cells"] == 5
    assert info["reward_terms"]["cam_usage"] == 0.0


def test_cam_usage_needs_a_camera_change(open_env):
    """A camera action at its limit changes nothing; cells the wind brings are not its doing.

    The rule (docs/design.md): cam_usage = 1 if a camera action added new cells.
    """
    env, _, _ = open_env((7, 7, 1), size=(15, 15, 3), wind_prob=1.0, wind_seed=3)
    windy_new = 0
    for _ in range(5):
        _, _, _, _, info = env.step(6)  # tilt+5 at tilt 90: no change
        assert info["camera"] == (90, 0, 1.0)
        if info["new_cells"] > 0:
            windy_new += 1
            assert info["wind"]
            assert info["reward_terms"]["cam_usage"] == 0.0
    assert windy_new >= 1


def test_curiosity_term_counts_visits(open_env):
    env, _, _ = open_env((4, 4, 1), size=(9, 9, 3))
    expected = [
        (0, 1.0),  # (5,4,1) first visit
        (1, 1 / math.sqrt(2)),  # start cell, visited at reset too
        (0, 1 / math.sqrt(2)),
        (1, 1 / math.sqrt(3)),
        (4, 1.0),  # (4,4,2)
        (5, 1 / math.sqrt(4)),
        (8, 0.0),  # camera: no move
    ]
    for action, curiosity in expected:
        _, _, _, _, info = env.step(action)
        assert info["reward_terms"]["curiosity"] == pytest.approx(curiosity), action
    _, _, _, _, info = env.step(3)
    _, _, _, _, info = env.step(3)
    _, _, _, _, info = env.step(3)
    _, _, _, _, info = env.step(3)
    _, _, _, _, info = env.step(3)  # (4,0,1) -> out of the grid
    assert info["collision"] and info["reward_terms"]["curiosity"] == 0.0
    # Visits restart with the episode.
    _, info = env.reset(options={"scenario": scenario((4, 4, 1))})
    _, _, _, _, info = env.step(1)
    assert info["reward_terms"]["curiosity"] == 1.0


def test_collision_term(open_env):
    env, _, _ = open_env((0, 0, 0), size=(5, 5, 3))
    _, reward, _, _, info = env.step(1)
    assert info["reward_terms"]["collision"] == 1.0
    assert info["reward_terms"]["idle"] == 0.0
    assert info["reward_terms"]["redundant"] == 1.0
    assert reward == pytest.approx(-1.15 - 0.6 - 0.3 * 1.1)


def test_idle_term(open_env):
    env, _, _ = open_env((2, 2, 1), size=(5, 5, 3))
    _, reward, _, _, info = env.step(6)  # tilt+5 at 90
    assert info["reward_terms"]["idle"] == 1.0
    assert info["reward_terms"]["collision"] == 0.0
    assert reward == pytest.approx(-0.55 - 0.6 - 0.3 * 0.3)


def test_llm_term_is_zero_without_pare(make_env):
    env = make_env(size=(8, 8, 3), reward="ewri", llm_weight=True)
    env.reset(seed=0)
    for a in range(12):
        _, _, _, _, info = env.step(a)
        assert info["reward_terms"]["llm"] == 0.0
