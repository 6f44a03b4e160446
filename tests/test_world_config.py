"""VCPPConfig: the paper's defaults, alpha scaling, strict validation, YAML, gym.make errors."""

from __future__ import annotations

import gymnasium as gym
import pytest
import yaml

from pirl.config.errors import ConfigError
from pirl.config.world import EWRI_RANGES, REWARD_TERMS, STATIC_WEIGHTS, VCPPConfig
from pirl.env import VCPPEnv, make_vec_env


def test_defaults_match_the_design():
    cfg = VCPPConfig()
    assert cfg.size == (15, 15, 3)
    assert cfg.footprint == "paper"
    assert cfg.occlusion is False
    assert cfg.wind_prob == 0.1
    assert cfg.battery_capacity == 100.0
    assert cfg.max_steps == 200
    assert (cfg.energy_move, cfg.energy_climb, cfg.energy_descend) == (1.0, 1.5, 0.7)
    assert (cfg.energy_camera, cfg.energy_hover) == (0.2, 0.1)
    assert (cfg.start_tilt, cfg.start_pan, cfg.start_zoom, cfg.start_zoom10) == (90, 0, 1.0, 10)
    assert (cfg.obstacles_min, cfg.obstacles_max) == (2, 5)
    assert (cfg.radius_min, cfg.radius_max) == (1.0, 2.0)
    assert cfg.fov_deg == 90.0 and cfg.max_range == 8.0
    assert cfg.reward == "static"
    assert REWARD_TERMS == (
        "coverage", "redundant", "battery", "cam_usage", "curiosity", "collision", "idle", "llm",
    )  # fmt: skip
    assert STATIC_WEIGHTS == (1.0, -0.6, -0.3, 0.4, 0.35, -1.15, -0.55, 0.4)
    assert EWRI_RANGES == (
        (0.5, 1.5), (-1.0, -0.2), (-0.5, -0.1), (0.2, 0.6), (0.2, 0.5), (-1.5, -0.8),
        (-0.8, -0.3), (0.2, 0.6),
    )  # fmt: skip


@pytest.mark.parametrize(
    ("size", "alpha"),
    [
        ((15, 15, 3), 1.0),
        ((30, 30, 3), 4.0),
        ((45, 45, 3), 9.0),
        ((60, 60, 3), 16.0),
        ((40, 25, 4), 4000 / 675),
        ((5, 5, 3), 75 / 675),
    ],
)
def test_alpha_scales_battery_and_step_limit(size, alpha):
    cfg = VCPPConfig(size=size)
    assert cfg.alpha == pytest.approx(alpha)
    assert cfg.capacity == pytest.approx(100.0 * alpha)
    assert cfg.step_limit == round(200 * alpha)
    flat = VCPPConfig(size=size, scale_by_alpha=False)
    assert (flat.capacity, flat.step_limit) == (100.0, 200)


def test_env_uses_the_scaled_values(make_env):
    env = make_env(size=(30, 30, 3))
    world = env.unwrapped.world
    assert world.capacity == pytest.approx(400.0)
    assert world.step_limit == 800
    env = make_env(size=(40, 25, 4))
    assert env.unwrapped.world.step_limit == 1185
    assert env.unwrapped.world.capacity == pytest.approx(100 * 4000 / 675)
    env = make_env(size=(30, 30, 3), scale_by_alpha=False, battery_capacity=50.0, max_steps=70)
    assert (env.unwrapped.world.capacity, env.unwrapped.world.step_limit) == (50.0, 70)


def test_unknown_key_names_the_key_and_the_allowed_keys():
    with pytest.raises(ConfigError) as err:
        VCPPConfig.from_dict({"wind_prb": 0.2})
    msg = str(err.value)
    assert "'wind_prb'" in msg
    assert "did you mean 'wind_prob'" in msg
    for key in ("wind_prob", "footprint", "size", "battery_capacity", "max_steps"):
        assert key in msg


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("wind_prob", "0.1"),
        ("max_steps", 10.5),
        ("max_steps", True),
        ("occlusion", 1),
        ("footprint", 3),
        ("battery_capacity", "full"),
        ("start_tilt", 90.0),
        ("size", "15x15x3"),
        ("size", (15.0, 15, 3)),
        ("size", (15, 15)),
        ("size", (15, True, 3)),
    ],
)
def test_wrong_type_is_refused(key, value):
    with pytest.raises(ConfigError, match=key):
        VCPPConfig.from_dict({key: value})


def test_int_is_accepted_where_a_float_is_expected():
    cfg = VCPPConfig.from_dict({"battery_capacity": 50, "wind_prob": 0})
    assert cfg.capacity == 50.0
    assert cfg.wind_prob == 0


@pytest.mark.parametrize("size", [(2, 15, 3), (15, 2, 3), (15, 15, 2), (0, 0, 0), (15, -3, 3)])
def test_size_below_three_is_refused(size):
    with pytest.raises(ConfigError, match="size"):
        VCPPConfig(size=size)


def test_smallest_world_is_accepted():
    assert VCPPConfig(size=(3, 3, 3)).alpha == pytest.approx(27 / 675)


@pytest.mark.parametrize("zoom", [1.05, 0.4, 2.1, 0.55, 3.0])
def test_zoom_off_the_grid_is_refused(zoom):
    with pytest.raises(ConfigError, match="start_zoom"):
        VCPPConfig(start_zoom=zoom)


@pytest.mark.parametrize("zoom", [0.5, 0.7, 1.3, 2.0])
def test_zoom_on_the_grid_is_stored_in_tenths(zoom):
    assert VCPPConfig(start_zoom=zoom).start_zoom10 == round(zoom * 10)


@pytest.mark.parametrize("capacity", [-1.0, 0.0, -100, float("nan"), float("inf")])
def test_battery_capacity_must_be_positive(capacity):
    with pytest.raises(ConfigError, match="battery_capacity"):
        VCPPConfig(battery_capacity=capacity)


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("footprint", "cone"),
        ("reward", "dynamic"),
        ("wind_prob", 1.5),
        ("wind_prob", -0.1),
        ("start_tilt", 7),
        ("start_tilt", 95),
        ("start_pan", 20),
        ("start_pan", 105),
        ("max_steps", 0),
        ("obs_window", 4),
        ("obs_window", 1),
        ("fov_deg", 180.0),
        ("max_range", 0.0),
        ("energy_camera", -0.2),
        ("energy_move", 0.0),
    ],
)
def test_impossible_values_are_refused(key, value):
    with pytest.raises(ConfigError, match=key):
        VCPPConfig.from_dict({key: value})


def test_bad_footprint_lists_the_allowed_models():
    with pytest.raises(ConfigError) as err:
        VCPPConfig(footprint="cone")
    assert "paper" in str(err.value) and "frustum" in str(err.value)


def test_obstacle_ranges_are_checked():
    with pytest.raises(ConfigError, match="obstacles_min"):
        VCPPConfig(obstacles_min=4, obstacles_max=2)
    with pytest.raises(ConfigError, match="radius_min"):
        VCPPConfig(radius_min=2.5, radius_max=1.0)
    with pytest.raises(ConfigError, match="static_weights"):
        VCPPConfig(static_weights=(1.0, 2.0))
    with pytest.raises(ConfigError, match="ewri_ranges"):
        VCPPConfig(ewri_ranges=((1.0, 0.0),) * 8)


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, ValueError)


def test_yaml_file_loads_and_lists_become_tuples(tmp_path):
    path = tmp_path / "world.yaml"
    path.write_text(
        "size: [30, 30, 3]\nfootprint: frustum\nreward: ewri\nwind_prob: 0.25\n"
        "start_zoom: 1.5\nstatic_weights: [1, -0.6, -0.3, 0.4, 0.35, -1.15, -0.55, 0.4]\n"
    )
    cfg = VCPPConfig.from_yaml(path)
    assert cfg.size == (30, 30, 3)
    assert isinstance(cfg.size, tuple)
    assert (cfg.footprint, cfg.reward, cfg.wind_prob) == ("frustum", "ewri", 0.25)
    assert cfg.start_zoom10 == 15
    assert cfg.static_weights == STATIC_WEIGHTS
    assert cfg.capacity == pytest.approx(400.0)


def test_yaml_round_trip(tmp_path):
    cfg = VCPPConfig(size=(40, 25, 4), footprint="frustum", occlusion=True, wind_prob=0.3)
    path = tmp_path / "round.yaml"
    path.write_text(yaml.safe_dump(cfg.to_dict()))
    assert VCPPConfig.from_yaml(path) == cfg


def test_empty_yaml_is_refused_and_braces_give_the_defaults(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("")
    with pytest.raises(ConfigError, match="is empty"):
        VCPPConfig.from_yaml(path)
    path.write_text("{}\n")
    assert VCPPConfig.from_yaml(path) == VCPPConfig()


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("size: [30, 30, 3]\nwindprob: 0.2\n", "windprob"),
        ("size: [30, 30\n", "not valid YAML"),
        ("- 1\n- 2\n", "mapping"),
        ("size: [2, 30, 3]\n", "size"),
    ],
)
def test_bad_yaml_raises_config_error(tmp_path, text, match):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        VCPPConfig.from_yaml(path)


def test_missing_yaml_file(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        VCPPConfig.from_yaml(tmp_path / "nope.yaml")


def test_gym_make_with_a_bad_kwarg_raises_the_same_clear_error():
    with pytest.raises(ConfigError) as direct:
        VCPPConfig.from_dict({"wind_prb": 0.2})
    with pytest.raises(ConfigError) as made:
        gym.make("pirl/VCPP-v0", wind_prb=0.2)
    assert str(made.value) == str(direct.value)
    with pytest.raises(ConfigError, match="footprint"):
        gym.make("pirl/VCPP-v0", footprint="cone")
    with pytest.raises(ConfigError, match="size"):
        gym.make("pirl/VCPP-v0", size=(2, 2, 2))
    with pytest.raises(ConfigError, match="render_mode"):
        VCPPEnv(render_mode="ansi")


def test_make_vec_env_with_a_bad_kwarg_raises():
    with pytest.raises(ConfigError, match="wind_prb"):
        make_vec_env(2, wind_prb=0.2)
    with pytest.raises(ConfigError, match="num_envs"):
        make_vec_env(0)


def test_gym_make_accepts_a_config_object_or_mapping_plus_overrides():
    env = gym.make("pirl/VCPP-v0", config=VCPPConfig(size=(20, 10, 3)), wind_prob=0.0)
    assert env.unwrapped.cfg.size == (20, 10, 3)
    assert env.unwrapped.cfg.wind_prob == 0.0
    env = gym.make("pirl/VCPP-v0", config={"size": [20, 10, 3], "footprint": "frustum"})
    assert env.unwrapped.cfg.size == (20, 10, 3)
    assert env.unwrapped.cfg.footprint == "frustum"
    with pytest.raises(ConfigError, match="config"):
        gym.make("pirl/VCPP-v0", config=42)


def test_replace_validates():
    cfg = VCPPConfig()
    assert cfg.replace(size=[30, 30, 3]).size == (30, 30, 3)
    with pytest.raises(ConfigError, match="start_zoom"):
        cfg.replace(start_zoom=1.05)


def test_a_fresh_interpreter_makes_the_env_by_its_gymnasium_id():
    """Without ``import pirl``: the bare id (the start-up hook ``make`` installs in the venv,
    ``python -m pirl_gym``) and Gymnasium's own ``module:id`` form both make the env, and
    importing gymnasium alone does not import PIRL."""
    import subprocess
    import sys

    code = (
        "import sys, gymnasium as gym; assert 'pirl' not in sys.modules; "
        "env = gym.make('pirl/VCPP-v0', size=(10, 10, 3)); obs, _ = env.reset(seed=0); "
        "env2 = gym.make('pirl:pirl/VCPP-v0', size=(10, 10, 3)); print(obs.shape)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr + "\n(is pirl_gym.pth installed? python -m pirl_gym)"
    assert proc.stdout.strip().startswith("(")
