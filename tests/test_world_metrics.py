"""Episode metrics (VCR, BE, RVC and the rest) on tiny scripted episodes computed by hand."""

from __future__ import annotations

import pytest

from pirl.world.metrics import episode_metrics

# 5x5x3 world, no obstacles, paper footprint, no wind, start (1, 1, 0), tilt 90, zoom 1.0.
# The reset view is x 0..2 / y 0..2 (9 cells). Then, step by step:
#   1 z-     collision at the floor; view x0-2 y0-2 again      new 0  (redundant) energy 0.8
#   2 x+     (2, 1, 0): view x1-3 y0-2                        new 3               1.1
#   3 x-     (1, 1, 0): view x0-2 y0-2                        new 0  (redundant)  1.1
#   4 tilt-5 tilt 85: still m = 1, same 3x3 view              new 0  (redundant)  0.3
#   5 tilt-5 tilt 80: still m = 1                             new 0  (redundant)  0.3
#   6 tilt-5 tilt 75: m = 2, h = 2, view x0-3 y0-3 (16)       new 4  (row y3)     0.3
#   7 y+     (1, 2, 0): view x0-3 y0-4 (20)                   new 4  (row y4)     1.1
#   8 x+     (2, 2, 0): view x0-4 y0-4 (25)                   new 5  (column x4)  1.1
# All 25 cells covered at step 8: terminated.
SCRIPT = [5, 0, 1, 7, 7, 7, 2, 0]
NEW_CELLS = [0, 3, 0, 0, 0, 4, 4, 5]
ENERGY = [0.8, 1.1, 1.1, 0.3, 0.3, 0.3, 1.1, 1.1]


def test_scripted_episode_metrics(open_env):
    env, _, info = open_env((1, 1, 0), size=(5, 5, 3), scale_by_alpha=False)
    assert (info["covered"], info["coverable"]) == (9, 25)
    for k, action in enumerate(SCRIPT):
        _, _, terminated, truncated, info = env.step(action)
        assert info["new_cells"] == NEW_CELLS[k], k
        assert info["redundant"] is (NEW_CELLS[k] == 0)
        assert info["reward_terms"]["battery"] == pytest.approx(ENERGY[k])
        assert terminated is (k == len(SCRIPT) - 1)
        assert not truncated
    m = info["episode_metrics"]
    assert m == episode_metrics(env.unwrapped.world, 0)

    battery_left = (100 - sum(ENERGY)) / 100  # 0.939
    assert m["covered"] == 25 and m["coverable"] == 25
    assert m["vcr"] == 1.0
    assert m["battery_left"] == pytest.approx(battery_left)
    assert m["be"] == pytest.approx(1.0 / (2.0 - 0.939))
    # Redundant steps 1, 3, 4, 5 all saw x0-2 / y0-2: C_redundant has 9 cells.
    assert m["redundant_steps"] == 4
    assert m["rvc"] == pytest.approx(9 / 25)
    # Seen in two or more steps: x0-2/y0-2 (9), x3/y0-2 (3), row y3 x0-3 (4), row y4 x0-3 (4).
    assert m["overlap"] == pytest.approx(20 / 25)
    # Coverable-cell views: 9 (reset) + 5 * 9 + 9 + 16 + 20 + 25 = 115 (step 2 also saw 9).
    assert m["views_per_cell"] == pytest.approx(115 / 25)
    assert m["mean_footprint"] == pytest.approx(115 / 9)
    assert m["steps"] == 8
    assert m["collisions"] == 1
    assert m["camera_share"] == pytest.approx(3 / 8)
    assert (m["final_tilt"], m["final_zoom"]) == (75, 1.0)
    assert m["wind_pushes"] == 0


def test_metrics_mid_episode(open_env):
    env, _, _ = open_env((1, 1, 0), size=(5, 5, 3), scale_by_alpha=False)
    world = env.unwrapped.world
    m0 = episode_metrics(world, 0)
    assert m0["vcr"] == pytest.approx(9 / 25)
    assert m0["be"] == pytest.approx((9 / 25) / 1.0)
    assert m0["rvc"] == 0.0 and m0["overlap"] == 0.0
    assert m0["views_per_cell"] == 1.0
    assert m0["steps"] == 0 and m0["camera_share"] == 0.0
    for action in SCRIPT[:3]:
        env.step(action)
    m = episode_metrics(world, 0)
    assert m["covered"] == 12
    assert m["vcr"] == pytest.approx(12 / 25)
    assert m["be"] == pytest.approx((12 / 25) / (2 - (100 - 3.0) / 100))
    assert m["rvc"] == pytest.approx(9 / 12)
    # Steps 1 and 2 saw x0-2 / y0-2 again, step 2 saw x1-2 / y0-2 a third time.
    assert m["overlap"] == pytest.approx(9 / 12)
    assert m["views_per_cell"] == pytest.approx(36 / 12)
    assert m["redundant_steps"] == 2


def test_coverable_excludes_ground_under_obstacles(open_env):
    # Sphere at (2, 2, 0), radius 1: blocks ground (2,2), (1,2), (3,2), (2,1), (2,3).
    env, _, info = open_env(
        (0, 0, 1), size=(5, 5, 3), obstacles=[[2.0, 2.0, 0.0, 1.0]], start_tilt=75,
        scale_by_alpha=False,
    )  # fmt: skip
    world = env.unwrapped.world
    assert info["coverable"] == 20
    assert int(world.coverable[0].sum()) == 20
    # Tilt 75, zoom 1: x0-2 / y0-2, of which (2,2), (1,2), (2,1) are blocked.
    assert info["covered"] == 6
    m = episode_metrics(world, 0)
    assert m["vcr"] == pytest.approx(6 / 20)
    assert m["mean_footprint"] == 9.0
    assert m["views_per_cell"] == 1.0
    # Uncoverable cells never count as covered, however often they are seen.
    _, _, _, _, info = env.step(0)  # (1, 0, 1): x0-3 / y0-2, new (3,0), (3,1)
    assert info["new_cells"] == 2
    assert not world.covered(0)[~world.coverable[0]].any()


def test_metrics_on_battery_end(open_env):
    env, _, _ = open_env((1, 1, 0), size=(5, 5, 3), battery_capacity=1.0, scale_by_alpha=False)
    _, _, terminated, _, info = env.step(0)  # 1.1 > 1.0
    assert terminated
    m = info["episode_metrics"]
    assert m["battery_left"] == 0.0
    assert m["vcr"] == pytest.approx(12 / 25)
    assert m["be"] == pytest.approx((12 / 25) / 2.0)
