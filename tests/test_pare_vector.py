"""PARE's Gymnasium adapter over the Gymnasium vector env, with the real oracle: the same
shaped rewards as the Stable-Baselines3 adapter for the same worlds and actions."""

from __future__ import annotations

import numpy as np
import pytest

from pirl.advice.oracle import OracleAdvisor
from pirl.config.errors import ConfigError
from pirl.config.run import PareSettings
from pirl.env import make_vec_env
from pirl.env.gym_vector import VCPPVectorEnv
from pirl.pare.bundle import AdviceBundle
from pirl.pare.gym_vector import PAREVectorWrapper
from pirl.pare.sb3_vec import PAREVecEnv

SETTINGS = {"size": (12, 10, 3), "reward": "ewri", "llm_weight": True, "wind_prob": 0.2}


def _advice() -> AdviceBundle:
    return AdviceBundle(OracleAdvisor(), None, None, 0.0, 16, "oracle")


def _pair(n: int, settings: dict, pare: PareSettings, seed: int = 5):
    sb3 = PAREVecEnv.from_settings(make_vec_env(n, seed=seed, **settings), pare, _advice())
    gym = PAREVectorWrapper.from_settings(VCPPVectorEnv(n, **settings), pare, _advice())
    sb3.reset()
    gym.reset(seed=seed)
    return sb3, gym


def test_gymnasium_adapter_shapes_as_the_sb3_adapter():
    n = 3
    sb3, gym = _pair(n, SETTINGS, PareSettings(mode="sync"))
    rng = np.random.default_rng(1)
    for _ in range(40):
        actions = rng.integers(0, 12, n)
        _, shaped, dones, infos = sb3.step(actions)
        _, rewards, terminated, truncated, info = gym.step(actions)
        assert np.array_equal(dones, terminated | truncated) and not dones.any()
        # SB3 rewards are float32, Gymnasium's float64: equal to float32 precision.
        np.testing.assert_allclose(rewards, shaped, rtol=1e-6, atol=1e-6)
        f_llm = [i["pare"]["f_llm"] for i in infos]
        assert info["pare"]["f_llm"].tolist() == f_llm
        assert info["reward_terms"]["llm"].tolist() == f_llm
        assert info["pare"]["status"].tolist() == ["fresh"] * n
        assert info["_pare"].all()
    a, b = sb3.stats.as_dict(), gym.stats.as_dict()
    for key in ("steps", "steps_fresh", "prompts_sent", "answers_ok"):
        assert a[key] == b[key] > 0, key
    assert a["steps_missing"] == b["steps_missing"] == 0
    sb3.close()
    gym.close()


def test_gymnasium_next_step_autoreset_is_neither_shaped_nor_counted():
    # Short episodes; K = 2, so each world's query phase must restart with its episode.
    settings = dict(SETTINGS, max_steps=5, scale_by_alpha=False)
    n = 2
    sb3, gym = _pair(n, settings, PareSettings(mode="sync", query_every=2))
    rng = np.random.default_rng(2)
    queues = [list(rng.integers(0, 12, 40)) for _ in range(n)]
    # SB3 resets an ended world at once; Gymnasium spends the next step on it (its action
    # ignored). Give each world the same actions and compare its own reward sequence.
    expected: list[list[tuple[float, str, int]]] = [[] for _ in range(n)]
    for t in range(30):
        _, shaped, _, infos = sb3.step(np.array([q[t] for q in queues]))
        for e in range(n):
            p = infos[e]["pare"]
            expected[e].append((float(shaped[e]), p["status"], p["staleness"]))
    got: list[list[tuple[float, str, int]]] = [[] for _ in range(n)]
    nxt = [0] * n
    ended = np.zeros(n, dtype=bool)
    restarts = 0
    while min(len(g) for g in got) < 30:
        actions = np.array([0 if ended[e] else queues[e][nxt[e]] for e in range(n)])
        _, rewards, terminated, truncated, info = gym.step(actions)
        for e in range(n):
            if ended[e]:  # the reset step: no transition
                assert not info["_pare"][e] and rewards[e] == 0.0
                restarts += 1
                continue
            assert info["_pare"][e]
            p = info["pare"]
            got[e].append((float(rewards[e]), p["status"][e], int(p["staleness"][e])))
            nxt[e] += 1
        ended = terminated | truncated
    assert restarts >= 4
    for e in range(n):
        for (r_sb3, *rest_sb3), (r_gym, *rest_gym) in zip(expected[e], got[e][:30], strict=True):
            assert r_gym == pytest.approx(r_sb3, rel=1e-6, abs=1e-6)
            assert rest_gym == rest_sb3
    # The reset steps are not steps of PARE.
    assert gym.stats.steps == sum(len(g) for g in got)
    sb3.close()
    gym.close()


def test_gymnasium_adapter_state_round_trip_and_refusals():
    sb3_settings = PareSettings(mode="sync")
    gym = PAREVectorWrapper.from_settings(VCPPVectorEnv(2, **SETTINGS), sb3_settings, _advice())
    gym.reset(seed=0)
    gym.step(np.zeros(2, dtype=np.int64))
    state = gym.state_dict()
    again = PAREVectorWrapper.from_settings(VCPPVectorEnv(2, **SETTINGS), sb3_settings, _advice())
    again.load_state_dict(state)
    assert again.stats.steps == gym.stats.steps == 2
    with pytest.raises(ConfigError, match="reset_mask"):
        gym.reset(options={"reset_mask": np.ones(2, dtype=bool)})
    with pytest.raises(ConfigError, match="llm_weight=True"):
        PAREVectorWrapper.from_settings(VCPPVectorEnv(1, size=(10, 10, 3)), sb3_settings, _advice())
    gym.close()
    again.close()
