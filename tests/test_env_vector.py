"""The Gymnasium vector env: registered as the vector entry point, and step for step the same
as Gymnasium's own SyncVectorEnv over N single envs (next-step autoreset, info of arrays)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from pirl.env import VCPPEnv, VCPPVectorEnv

# Short episodes, so that both ends (battery, step limit) happen within the test.
SMALL = {"size": (6, 6, 3), "max_steps": 12, "scale_by_alpha": False, "battery_capacity": 8.0}


def same_info(ours: dict, theirs: dict, where: str) -> None:
    """Our info against SyncVectorEnv's: same keys and masks, same values where masked in."""
    assert set(ours) == set(theirs), where
    for key, value in theirs.items():
        if isinstance(value, dict):
            same_info(ours[key], value, f"{where}, {key}")
            continue
        mine = np.asarray(ours[key])
        if value.dtype == object:  # tuples (position, camera) land in object arrays there
            value = np.array([np.asarray(v, dtype=np.float64) for v in value])
        if key.startswith("_"):
            assert np.array_equal(mine, value), f"{where}, {key}"
        else:
            mask = np.asarray(theirs["_" + key])
            assert np.array_equal(mine[mask], np.asarray(value)[mask]), f"{where}, {key}"


@pytest.mark.parametrize(
    "settings",
    [
        {"footprint": "paper", "reward": "static", "wind_prob": 0.0},
        {"footprint": "frustum", "reward": "ewri", "wind_prob": 0.3, "occlusion": True},
    ],
    ids=["paper-static", "frustum-ewri-wind-occlusion"],
)
def test_vector_env_equals_sync_vector_env_over_single_envs(settings):
    num, seed = 4, 7
    ours = gym.make_vec(
        "pirl/VCPP-v0", num_envs=num, vectorization_mode="vector_entry_point", **SMALL, **settings
    )
    assert isinstance(ours, VCPPVectorEnv)
    sync = SyncVectorEnv([lambda: VCPPEnv(**SMALL, **settings) for _ in range(num)])
    assert sync.metadata["autoreset_mode"] == ours.metadata["autoreset_mode"]
    assert ours.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    obs, info = ours.reset(seed=seed)
    sobs, sinfo = sync.reset(seed=seed)
    assert np.array_equal(obs, sobs)
    same_info(info, sinfo, "reset")
    rng = np.random.default_rng(0)
    ends = 0
    for t in range(120):
        actions = rng.integers(0, 12, size=num)
        obs, rew, term, trunc, info = ours.step(actions)
        sobs, srew, sterm, strunc, sinfo = sync.step(actions)
        where = f"step {t}"
        assert obs.dtype == np.float32 and term.dtype == np.bool_, where
        assert np.array_equal(obs, sobs), where
        assert np.array_equal(rew, srew), where
        assert np.array_equal(term, sterm) and np.array_equal(trunc, strunc), where
        same_info(info, sinfo, where)
        ends += int((term | trunc).sum())
    assert ends >= 8


def test_make_vec_uses_the_vector_entry_point_by_default():
    env = gym.make_vec("pirl/VCPP-v0", num_envs=3, size=(8, 8, 3))
    assert isinstance(env, VCPPVectorEnv) and env.num_envs == 3
    assert env.single_action_space == gym.spaces.Discrete(12)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3, 2 * 11 * 11 + 8 * 8 + 11) and env.observation_space.contains(obs)


def test_reset_mask_resets_only_the_masked_worlds():
    env = VCPPVectorEnv(3, **SMALL)
    env.reset(seed=1)
    env.step(np.array([0, 0, 0]))
    obs, info = env.reset(options={"reset_mask": np.array([False, True, False])})
    assert list(info["steps"]) == [1, 0, 1]
    assert list(info["_steps"]) == [False, True, False]  # the info is about the reset world
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": np.array([1, 0, 1])})


def test_info_is_built_only_when_read_and_copy_false_shares_the_buffer():
    env = VCPPVectorEnv(2, copy=False, **SMALL)
    obs, _ = env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([8, 9]))
    assert dict.__len__(info) == 1  # only the pending marker: nothing built yet
    assert info["steps"].tolist() == [1, 1] and "camera" in info
    obs2, *_ = env.step(np.array([8, 9]))
    assert obs2 is obs  # the one buffer, overwritten in place


def test_render_gives_one_picture_per_world():
    env = VCPPVectorEnv(2, render_mode="rgb_array", **SMALL, render_cell_px=4)
    env.reset(seed=0)
    env.step(np.array([0, 2]))
    frames = env.render()
    assert len(frames) == 2 and frames[0].ndim == 3


@pytest.mark.parametrize("parallel", [False, True])
def test_an_action_out_of_range_is_refused_before_any_world_moves(parallel):
    env = VCPPVectorEnv(4, parallel=parallel, **SMALL)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"\[0, 12\)"):
        env.step(np.array([0, 1, 12, 3]))
    assert (env.world.status["steps"] == 0).all()  # nothing was stepped
