"""Exploring starts: a training option that draws the starting camera pose per scenario."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pirl.agents.train import resolved_config, train, training_env
from pirl.config import grid
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.config.world import VCPPConfig
from pirl.world.scenario import draw_scenario

TEST_CFG = Path(__file__).resolve().parents[1] / "configs" / "test.yaml"


def test_fixed_start_draws_the_same_scenarios_as_before() -> None:
    """The random pose is drawn last, so fixed-start scenarios (every evaluation) are unchanged."""
    fixed = draw_scenario(VCPPConfig(), np.random.default_rng(7))
    drawn = draw_scenario(VCPPConfig(start_camera="random"), np.random.default_rng(7))
    assert fixed.camera is None
    assert fixed.start == drawn.start and fixed.wind_seed == drawn.wind_seed
    np.testing.assert_array_equal(fixed.obstacles, drawn.obstacles)


def test_random_start_covers_the_camera_grid() -> None:
    cfg = VCPPConfig(start_camera="random")
    rng = np.random.default_rng(0)
    poses = {draw_scenario(cfg, rng).camera for _ in range(400)}
    tilts, pans, zooms = (sorted({p[k] for p in poses}) for k in range(3))
    assert tilts == list(grid.tilt_steps()) and pans == list(grid.pan_steps())
    assert zooms == list(range(grid.ZOOM_MIN10, grid.ZOOM_MAX10 + 1))


def test_mixed_start_draws_half_its_scenarios_at_random_poses() -> None:
    cfg = VCPPConfig(start_camera="mixed")
    rng = np.random.default_rng(1)
    drawn = sum(draw_scenario(cfg, rng).camera is not None for _ in range(400))
    assert 160 < drawn < 240


def test_camera_start_reaches_the_training_env_only(tmp_path) -> None:
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(train={"camera_start": "random"})
    assert training_env(resolved_config("ppo-ewri", cfg)).start_camera == "random"
    assert resolved_config("ppo-ewri", cfg).env.start_camera == "fixed"
    # The run's config.yaml (what evaluations build their env from) keeps the fixed start.
    train("ppo-ewri", cfg, tmp_path / "run", seed=0, show_progress=False)
    saved = RunConfig.from_yaml(tmp_path / "run" / "config.yaml")
    assert saved.train.camera_start == "random" and saved.env.start_camera == "fixed"


def test_unknown_camera_start_is_one_line() -> None:
    with pytest.raises(ConfigError, match="train.camera_start='sometimes'"):
        RunConfig.from_dict({"train": {"camera_start": "sometimes"}})
    with pytest.raises(ConfigError, match="start_camera"):
        VCPPConfig(start_camera="sometimes")


def test_training_obstacles_reach_the_training_env_only() -> None:
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(train={"obstacles": [4, 10]})
    trained = training_env(resolved_config("ppo-ewri", cfg))
    assert (trained.obstacles_min, trained.obstacles_max) == (4, 10)
    env = resolved_config("ppo-ewri", cfg).env
    assert (env.obstacles_min, env.obstacles_max) == (2, 5)  # what evaluations build
    with pytest.raises(ConfigError, match="train.obstacles"):
        RunConfig.from_dict({"train": {"obstacles": [5, 2]}})


def test_the_stall_guard_can_be_left_out_of_training_only() -> None:
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(
        env={"stall_guard": 32}, train={"stall_guard": 0}
    )
    assert training_env(resolved_config("ppo-ewri", cfg)).stall_guard == 0
    assert resolved_config("ppo-ewri", cfg).env.stall_guard == 32  # what evaluations build
    plain = RunConfig.from_yaml(TEST_CFG).with_overrides(env={"stall_guard": 32})
    assert training_env(resolved_config("ppo-ewri", plain)).stall_guard == 32
    with pytest.raises(ConfigError, match="train.stall_guard"):
        RunConfig.from_dict({"train": {"stall_guard": -1}})
    with pytest.raises(ConfigError, match="env.stall_guard"):
        RunConfig.from_dict({"env": {"stall_guard": -1}})


def test_surveyed_starts_leave_one_box_of_work() -> None:
    cfg = VCPPConfig(size=(15, 15, 3), start_surveyed=1.0)
    plain = draw_scenario(VCPPConfig(size=(15, 15, 3)), np.random.default_rng(3))
    drawn = draw_scenario(cfg, np.random.default_rng(3))
    assert plain.work is None and drawn.start == plain.start  # drawn last: the rest unchanged
    x0, y0, x1, y1 = drawn.work
    assert 2 <= x1 - x0 + 1 <= 7 and 2 <= y1 - y0 + 1 <= 7
    from pirl.env.core import EnvCore

    core = EnvCore(cfg, 1)
    core.reset_world(0, np.random.default_rng(3), scenario=drawn)
    w = core.world
    todo = w.coverable[0] & (w.views[0] == 0)
    box = np.zeros_like(todo)
    box[x0 : x1 + 1, y0 : y1 + 1] = True
    assert not (todo & ~box).any()  # only the box is left (less what the first view saw)
    assert w.status[0]["covered"] == int((w.views[0] > 0).sum())
    assert w.blk_todo[0].sum() == int(todo.sum())
    with pytest.raises(ConfigError, match="train.surveyed_start"):
        RunConfig.from_dict({"train": {"surveyed_start": 2}})
