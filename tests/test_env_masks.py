"""Valid-action masks: one rule in the env core, exposed the ecosystem's ways."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported
from stable_baselines3.common.vec_env import VecMonitor

from pirl.config.grid import PAN_MAX, PAN_MIN, TILT_MAX, TILT_MIN, ZOOM_MAX10, ZOOM_MIN10
from pirl.env import make_vec_env
from pirl.world import dynamics as D

SMALL = {"size": (6, 6, 3), "max_steps": 40, "scale_by_alpha": False, "battery_capacity": 30.0}


def expected_mask(world, e: int) -> np.ndarray:
    """The rule written out in Python: what each action would change."""
    (x, y, z), (tilt, pan, zoom) = world.position(e), world.camera_setting(e)
    sx, sy, sz = world.blocked.shape[1:]
    mask = np.zeros(D.N_ACTIONS, dtype=bool)
    for a, (dx, dy, dz) in enumerate(D.MOVE_DELTAS):
        nx, ny, nz = x + dx, y + dy, z + dz
        inside = 0 <= nx < sx and 0 <= ny < sy and 0 <= nz < sz
        mask[a] = inside and not world.blocked[e, nx, ny, nz]
    mask[D.TILT_PLUS], mask[D.TILT_MINUS] = tilt < TILT_MAX, tilt > TILT_MIN
    mask[D.PAN_PLUS], mask[D.PAN_MINUS] = pan < PAN_MAX, pan > PAN_MIN
    mask[D.ZOOM_PLUS], mask[D.ZOOM_MINUS] = zoom < ZOOM_MAX10, zoom > ZOOM_MIN10
    return mask


def test_single_env_mask_matches_the_rule_and_marks_what_changes_nothing():
    env = gym.make("pirl/VCPP-v0", **SMALL).unwrapped
    rng = np.random.default_rng(3)
    obs, info = env.reset(seed=5)
    invalid_seen = 0
    for _ in range(200):
        mask = env.action_masks()
        assert mask.dtype == bool and mask.shape == (D.N_ACTIONS,) and mask.any()
        assert np.array_equal(mask, expected_mask(env.world, 0))
        assert info["action_mask"] == tuple(mask.tolist())
        a = int(rng.integers(0, D.N_ACTIONS))
        before = env.world.camera_setting(0)
        obs, _, terminated, truncated, info = env.step(a)
        if not mask[a]:
            invalid_seen += 1
            # an invalid action moves nothing and steers nothing (wind may still push)
            assert env.world.camera_setting(0) == before
            if a < D.N_MOVES:
                assert info["collision"]
        if terminated or truncated:
            obs, info = env.reset()
    assert invalid_seen > 0


def test_camera_limits_are_masked():
    env = gym.make("pirl/VCPP-v0", **SMALL).unwrapped
    env.reset(seed=1)
    # the starting camera looks straight down: tilt+ is at its limit
    assert not env.action_masks()[D.TILT_PLUS] and env.action_masks()[D.TILT_MINUS]
    for _ in range(6):
        env.step(D.PAN_PLUS)
    assert not env.action_masks()[D.PAN_PLUS]
    for _ in range(10):
        env.step(D.ZOOM_MINUS)
    assert not env.action_masks()[D.ZOOM_MINUS] and env.action_masks()[D.ZOOM_PLUS]


def test_vec_env_masks_follow_auto_reset_and_match_single_envs():
    n = 5
    venv = make_vec_env(n, seed=7, **SMALL)
    singles = [gym.make("pirl/VCPP-v0", **SMALL).unwrapped for _ in range(n)]
    venv.reset()
    for i, env in enumerate(singles):
        env.reset(seed=7 + i)
    rng = np.random.default_rng(0)
    for _ in range(120):
        masks = venv.action_masks()
        assert masks.shape == (n, D.N_ACTIONS)
        for i, env in enumerate(singles):
            assert np.array_equal(masks[i], env.action_masks())
        actions = rng.integers(0, D.N_ACTIONS, size=n)
        _, _, dones, infos = venv.step(actions)
        for i, env in enumerate(singles):
            _, _, terminated, truncated, info = env.step(int(actions[i]))
            assert infos[i]["action_mask"] == info["action_mask"]
            if terminated or truncated:
                env.reset()


def test_sb3_contrib_reads_the_masks_through_wrappers():
    venv = make_vec_env(3, seed=0, **SMALL)
    wrapped = VecMonitor(venv)
    wrapped.reset()
    assert is_masking_supported(wrapped)
    masks = get_action_masks(wrapped)
    assert masks.shape == (3, D.N_ACTIONS) and np.array_equal(masks, venv.action_masks())


def test_gymnasium_vector_env_gives_masks_in_info():
    envs = gym.make_vec(
        "pirl/VCPP-v0", num_envs=3, vectorization_mode="vector_entry_point", **SMALL
    )
    _, info = envs.reset(seed=2)
    assert info["action_mask"].shape == (3, D.N_ACTIONS)
    assert np.array_equal(info["action_mask"], envs.unwrapped.action_masks())
    _, _, _, _, info = envs.step(np.array([D.TILT_PLUS] * 3))
    assert not info["action_mask"][:, D.TILT_PLUS].any()
    envs.close()
