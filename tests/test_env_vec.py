"""The batched env: exact equivalence with N single envs, and SB3 auto-reset semantics."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecEnv, VecMonitor

from pirl.env import VCPPVecEnv, make_vec_env
from pirl.env.observation import obs_size

# Small world, short episodes: truncation at 12 steps, and a battery that random actions
# (about 0.7 units per step) usually empty a little before or after that.
SMALL = {"size": (6, 6, 3), "max_steps": 12, "scale_by_alpha": False, "battery_capacity": 8.0}
SCALARS = 2 * 11 * 11 + 8 * 8  # first scalar of the default observation
BATTERY, STEPS_LEFT = SCALARS + 6, SCALARS + 8


def run_side_by_side(
    num: int, seed: int, steps: int, parallel: bool = False, **settings
) -> dict[str, int]:
    """Step make_vec_env(num, seed) and num single envs (seeds seed+i) with the same actions.

    Asserts equal observations, rewards, dones and infos at every step, the vec's terminal
    observation against the single env's final one, and the vec's auto-reset against the
    single env's unseeded reset(). Returns how many episodes ended each way.
    """
    venv = make_vec_env(num, seed=seed, parallel=parallel, **settings)
    assert venv.world.parallel is (parallel and num > 1)
    singles = [gym.make("pirl/VCPP-v0", **settings) for _ in range(num)]
    vobs = venv.reset()
    assert vobs.shape == (num, obs_size(11, 8)) and vobs.dtype == np.float32
    for i, env in enumerate(singles):
        obs, info = env.reset(seed=seed + i)
        assert np.array_equal(vobs[i], obs)
        assert dict(venv.reset_infos[i]) == info
    rng = np.random.default_rng(seed + 1000)
    ends = {"terminated": 0, "truncated": 0}
    for t in range(steps):
        actions = rng.integers(0, 12, size=num)
        vobs, vrew, vdone, vinfos = venv.step(actions)
        assert vrew.dtype == np.float32 and vdone.dtype == bool
        for i, env in enumerate(singles):
            obs, reward, terminated, truncated, info = env.step(int(actions[i]))
            where = f"step {t}, world {i}"
            assert vrew[i] == np.float32(reward), where
            assert bool(vdone[i]) == (terminated or truncated), where
            vinfo = dict(vinfos[i])
            terminal_obs = vinfo.pop("terminal_observation", None)
            time_limit = vinfo.pop("TimeLimit.truncated", None)
            assert vinfo == info, where
            if terminated or truncated:
                ends["terminated" if terminated else "truncated"] += 1
                assert "episode_metrics" in info
                assert np.array_equal(terminal_obs, obs), where
                assert time_limit is (truncated and not terminated), where
                obs, info = env.reset()
                assert dict(venv.reset_infos[i]) == info, where
            else:
                assert terminal_obs is None and time_limit is None, where
            assert np.array_equal(vobs[i], obs), where
    return ends


@pytest.mark.parametrize(
    "settings",
    [
        {"footprint": "paper", "reward": "static", "wind_prob": 0.0},
        {"footprint": "frustum", "reward": "static", "wind_prob": 0.0},
        {"footprint": "paper", "reward": "ewri", "wind_prob": 0.3},
        {"footprint": "frustum", "reward": "ewri", "wind_prob": 0.3, "occlusion": True},
    ],
    ids=["paper-static", "frustum-static", "paper-ewri-wind", "frustum-ewri-wind-occlusion"],
)
def test_vec_equals_single_envs(settings):
    ends = run_side_by_side(4, seed=3, steps=150, **SMALL, **settings)
    assert ends["terminated"] >= 3 and ends["truncated"] >= 3, ends


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
def test_vec_equals_single_envs_with_threads(footprint):
    # parallel=True spreads the worlds over numba threads; the results must not change.
    ends = run_side_by_side(
        16, seed=50, steps=40, parallel=True, **SMALL, footprint=footprint, reward="ewri",
        wind_prob=0.5,
    )  # fmt: skip
    assert ends["terminated"] + ends["truncated"] >= 16


def test_vec_is_deterministic_under_a_seed():
    def trajectory(seed):
        venv = make_vec_env(3, seed=seed, **SMALL, wind_prob=0.3)
        out = [venv.reset()]
        rng = np.random.default_rng(0)
        for _ in range(40):
            obs, rew, done, _ = venv.step(rng.integers(0, 12, size=3))
            out += [obs, rew, done]
        return out

    a, b, c = trajectory(1), trajectory(1), trajectory(2)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], c[0])


def test_worlds_in_a_batch_are_seeded_apart():
    venv = make_vec_env(4, seed=0, size=(15, 15, 3))
    obs = venv.reset()
    assert len({row.tobytes() for row in obs}) == 4


def test_auto_reset_on_truncation():
    venv = make_vec_env(
        3, seed=0, size=(6, 6, 3), max_steps=5, scale_by_alpha=False, battery_capacity=1e6,
        wind_prob=0.0,
    )  # fmt: skip
    obs = venv.reset()
    assert (obs[:, STEPS_LEFT] == 1.0).all()
    camera = np.array([8, 9, 8])
    for step in range(1, 5):
        obs, rewards, dones, infos = venv.step(camera if step % 2 else 17 - camera)
        assert not dones.any()
        assert all("terminal_observation" not in info for info in infos)
        assert all("TimeLimit.truncated" not in info for info in infos)
        assert obs[:, STEPS_LEFT] == pytest.approx(1 - step / 5)
    obs, rewards, dones, infos = venv.step(camera)
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is True
        terminal = info["terminal_observation"]
        assert terminal.shape == (obs_size(11, 8),)
        assert terminal[STEPS_LEFT] == 0.0
        assert info["steps"] == 5
        assert info["episode_metrics"]["steps"] == 5
        # The returned observation starts the next episode.
        assert obs[i, STEPS_LEFT] == 1.0
        assert venv.reset_infos[i]["steps"] == 0


def test_auto_reset_on_termination_is_not_a_time_limit():
    venv = make_vec_env(
        2, seed=0, size=(6, 6, 3), max_steps=50, scale_by_alpha=False, battery_capacity=0.5,
        wind_prob=0.0,
    )  # fmt: skip
    venv.reset()
    _, _, dones, _ = venv.step(np.array([8, 9]))  # 0.3 units each
    assert not dones.any()
    obs, _, dones, infos = venv.step(np.array([9, 8]))
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is False
        assert info["battery"] == 0.0
        assert info["terminal_observation"][BATTERY] == 0.0
        assert obs[i, BATTERY] == 1.0  # fresh battery in the next episode


def test_vec_env_is_an_sb3_vec_env():
    venv = make_vec_env(2, seed=0, size=(8, 8, 3))
    assert isinstance(venv, VecEnv) and isinstance(venv, VCPPVecEnv)
    assert venv.num_envs == 2
    assert venv.observation_space.shape == (317,)
    assert venv.action_space == gym.spaces.Discrete(12)
    assert venv.env_is_wrapped(gym.Wrapper) == [False, False]
    assert venv.get_attr("cfg") == [venv.cfg, venv.cfg]
    venv.reset()
    with pytest.raises(ValueError):
        venv.step(np.array([0, 12]))


def test_vec_monitor_records_episodes():
    # A battery that never runs out: every episode is truncated after 12 steps.
    venv = VecMonitor(make_vec_env(2, seed=0, **{**SMALL, "battery_capacity": 1e6}))
    venv.reset()
    totals = np.zeros(2)
    rng = np.random.default_rng(0)
    for _ in range(12):
        _, rewards, dones, infos = venv.step(rng.integers(0, 12, size=2))
        totals += rewards
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["episode"]["l"] == 12
        assert info["episode"]["r"] == pytest.approx(totals[i], abs=1e-4)
        assert info["TimeLimit.truncated"] is True


def test_manual_reset_continues_each_worlds_stream():
    settings = {**SMALL, "wind_prob": 0.2, "reward": "ewri"}
    venv = make_vec_env(2, seed=9, **settings)
    singles = [gym.make("pirl/VCPP-v0", **settings) for _ in range(2)]
    venv.reset()
    for i, env in enumerate(singles):
        env.reset(seed=9 + i)
    for action in (0, 2, 8):
        venv.step(np.array([action, action]))
        for env in singles:
            env.step(action)
    # A second reset without a seed draws the next scenario of each world's own stream.
    vobs = venv.reset()
    for i, env in enumerate(singles):
        obs, info = env.reset()
        assert np.array_equal(vobs[i], obs)
        assert dict(venv.reset_infos[i]) == info
    # Seeding again restarts the streams.
    venv.seed(9)
    assert np.array_equal(venv.reset()[1], singles[1].reset(seed=10)[0])


def test_wrappers_can_add_lazy_info_keys():
    venv = make_vec_env(2, seed=0, **SMALL)
    venv.reset()
    _, _, _, infos = venv.step(np.array([0, 1]))
    venv.step_snapshot.extras["advice"] = lambda e: f"world {e}"
    assert not dict.__contains__(infos[0], "advice")
    assert infos[1]["advice"] == "world 1"
    assert "advice" in infos[0]
    assert dict(infos[0])["advice"] == "world 0"
    assert infos[0]["steps"] == 1
