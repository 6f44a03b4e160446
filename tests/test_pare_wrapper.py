"""The PARE VecEnv wrapper: shaped rewards, timing modes, failures, K > 1."""

from __future__ import annotations

import time

import numpy as np
import pytest

from pirl.advice.base import Advisor, Answer
from pirl.advice.oracle import OracleAdvisor
from pirl.advice.recommendation import Recommendation
from pirl.config.errors import ConfigError
from pirl.config.run import PareSettings
from pirl.env import make_vec_env
from pirl.env.rewards import LLM_INDEX
from pirl.pare import alignment, f_llm
from pirl.pare.bundle import AdviceBundle
from pirl.pare.sb3_vec import PAREVecEnv

SETTINGS = {"size": (12, 10, 3), "reward": "ewri", "llm_weight": True, "wind_prob": 0.2}


class SlowOracle(OracleAdvisor):
    """The real oracle, answering only after ``delay`` seconds (an LLM's latency)."""

    def __init__(self, delay: float) -> None:
        self.delay = delay

    def advise(self, prompts, views=None):
        time.sleep(self.delay)
        return super().advise(prompts, views)


class Unreadable(Advisor):
    """Answers that no parser can read (what a small model writes unconstrained)."""

    name, model, label = "unreadable", "none", "unreadable"

    def settings_key(self) -> str:
        return "-"

    def advise(self, prompts, views=None):
        return [Answer("I think the drone should fly somewhere nice.", None) for _ in prompts]


def make_pare(
    venv,
    advisor,
    mode: str = "sync",
    query_every: int = 1,
    timeout_s: float = 120.0,
    student=None,
    dataset=None,
    teacher_rate: float = 0.002,
    gate: float = 0.8,
    refit_every: int = 256,
    fit_steps: int = 100,
    refit_growth: float = 0.0,
    wait_teacher: bool = False,
    teacher_batch: int = 16,
    max_failure_rate: float = 0.5,
    failure_window: int = 200,
    closed_rate: float = 1.0,
) -> PAREVecEnv:
    """PARE over ``venv`` as training builds it, from a pare settings section."""
    settings = PareSettings(
        mode=mode, query_every=query_every, timeout_s=timeout_s, student_gate=gate,
        student_fit_steps=fit_steps, student_refit_growth=refit_growth,
        student_wait_teacher=wait_teacher, max_failure_rate=max_failure_rate,
        failure_window=failure_window, student_closed_rate=closed_rate,
    )  # fmt: skip
    advice = AdviceBundle(advisor, student, dataset, teacher_rate, teacher_batch, "")
    return PAREVecEnv.from_settings(venv, settings, advice, refit_every=refit_every)


def _rollout(pare: PAREVecEnv, steps: int, seed: int = 0, pause: float = 0.0):
    rng = np.random.default_rng(seed)
    pare.reset()
    out = []
    for _ in range(steps):
        time.sleep(pause)  # the policy's own time per step
        world = pare.venv.world
        p_t = world.positions()
        obs, rewards, dones, infos = pare.step(rng.integers(0, 12, pare.num_envs))
        out.append((p_t, rewards, dones, infos))
    return out


def test_sync_reward_is_base_reward_plus_weighted_alignment():
    n = 3
    plain = make_vec_env(n, seed=5, **SETTINGS)
    pare = make_pare(make_vec_env(n, seed=5, **SETTINGS), OracleAdvisor(), mode="sync")
    rng = np.random.default_rng(1)
    plain.reset()
    pare.reset()
    recs = [None] * n
    for _ in range(60):
        # The advice for s_t, computed independently from the same state.
        from pirl.advice.oracle import oracle_recommendation
        from pirl.world.planning import WorldView

        recs = [oracle_recommendation(WorldView.of(plain.world, e, copy=True)) for e in range(n)]
        p_t = plain.world.positions()
        actions = rng.integers(0, 12, n)
        _, base, dones, base_infos = plain.step(actions)
        _, shaped, pdones, infos = pare.step(actions)
        assert np.array_equal(dones, pdones)
        for e in range(n):
            info = infos[e]
            assert info["pare"]["status"] == "fresh"
            terms = alignment(
                p_t[e], info["position"], info["camera"], recs[e], SETTINGS["size"], alpha=0.5
            )
            expected = f_llm(terms)
            assert info["pare"]["f_llm"] == pytest.approx(expected)
            assert info["reward_terms"]["llm"] == pytest.approx(expected)
            weight = info["reward_weights"]["llm"]
            assert 0.2 <= weight <= 0.6
            assert shaped[e] == pytest.approx(base[e] + weight * expected, abs=1e-5)
            # The reward is recomputable from the info alone.
            recomputed = sum(
                info["reward_terms"][k] * info["reward_weights"][k] for k in info["reward_terms"]
            )
            assert shaped[e] == pytest.approx(recomputed, abs=1e-5)
    assert pare.stats.steps_fresh == 60 * n
    assert pare.stats.as_dict()["parse_rate"] == 1.0


def test_query_every_k_reuses_advice_as_stale():
    pare = make_pare(make_vec_env(2, seed=1, **SETTINGS), OracleAdvisor(), query_every=4)
    statuses = [
        (infos[0]["pare"]["status"], infos[0]["pare"]["staleness"])
        for _, _, _, infos in _rollout(pare, 12)
    ]
    assert statuses[:8] == [("fresh", 0), ("stale", 1), ("stale", 2), ("stale", 3)] * 2
    assert pare.stats.prompts_sent == 2 * 3 + 2  # steps 0, 4, 8 and the one for step 12


def test_async_never_waits_and_reports_staleness():
    delay, pause = 0.25, 0.03
    # Load the compiled kernels first, so the timing below is the steps' alone.
    warm = make_pare(make_vec_env(2, seed=2, **SETTINGS), OracleAdvisor(), mode="sync")
    _rollout(warm, 2)
    warm.close()
    pare = make_pare(make_vec_env(2, seed=2, **SETTINGS), SlowOracle(delay), mode="async")
    start = time.perf_counter()
    steps = _rollout(pare, 40, pause=pause)
    elapsed = time.perf_counter() - start
    # Sync steps would wait 40 * delay = 10 s; async only spends the policy's own time.
    assert elapsed < 40 * pause + 3 * delay
    statuses = [infos[0]["pare"]["status"] for _, _, _, infos in steps]
    assert statuses[0] == "missing"
    assert "stale" in statuses
    assert pare.stats.as_dict()["mean_staleness"] > 1
    pare.close()


def test_sync_timeout_counts_late_and_goes_on():
    pare = make_pare(
        make_vec_env(2, seed=3, **SETTINGS), SlowOracle(0.5), mode="sync", timeout_s=0.05
    )
    steps = _rollout(pare, 3)
    for _, _, _, infos in steps:
        assert infos[0]["pare"]["status"] == "missing"
        assert infos[0]["pare"]["f_llm"] == 0.0
    assert pare.stats.answers_late >= 2
    pare.close()


def test_unparseable_answers_give_zero_and_are_counted():
    plain = make_vec_env(2, seed=4, **SETTINGS)
    pare = make_pare(make_vec_env(2, seed=4, **SETTINGS), Unreadable(), mode="sync")
    plain.reset()
    pare.reset()
    rng = np.random.default_rng(0)
    for _ in range(10):
        actions = rng.integers(0, 12, 2)
        _, base, _, _ = plain.step(actions)
        _, shaped, _, infos = pare.step(actions)
        assert np.array_equal(base, shaped)
        assert infos[1]["pare"]["status"] == "missing"
    assert pare.stats.answers_unparseable == 20
    assert pare.stats.as_dict()["parse_rate"] == 0.0


def test_advice_from_an_ended_episode_is_not_used():
    settings = dict(SETTINGS, max_steps=5, scale_by_alpha=False)
    pare = make_pare(make_vec_env(1, seed=6, **settings), OracleAdvisor(), query_every=3)
    for _, _, dones, infos in _rollout(pare, 12):
        if infos[0]["steps"] == 1:  # first step of an episode uses that episode's advice
            assert infos[0]["pare"]["status"] == "fresh"
        if dones[0]:
            assert "terminal_observation" in infos[0]


def test_wrapper_refuses_wrong_set_up():
    with pytest.raises(ConfigError, match="llm_weight=True"):
        make_pare(make_vec_env(1, size=(10, 10, 3)), OracleAdvisor())
    with pytest.raises(ConfigError, match="mode"):
        make_pare(make_vec_env(1, **SETTINGS), OracleAdvisor(), mode="later")
    with pytest.raises(ConfigError, match="query_every"):
        make_pare(make_vec_env(1, **SETTINGS), OracleAdvisor(), query_every=0)


def test_weights_of_the_llm_term():
    venv = make_vec_env(4, seed=0, **SETTINGS)
    venv.reset()
    assert np.all(
        (venv.core.weights[:, LLM_INDEX] >= 0.2) & (venv.core.weights[:, LLM_INDEX] <= 0.6)
    )
    off = make_vec_env(4, seed=0, **dict(SETTINGS, llm_weight=False))
    off.reset()
    assert np.all(off.core.weights[:, LLM_INDEX] == 0.0)
    # The rest of the EWRI draw does not depend on whether PARE is on.
    mask = np.arange(8) != LLM_INDEX
    assert np.array_equal(venv.core.weights[:, mask], off.core.weights[:, mask])


def test_oracle_advice_points_to_uncovered_ground():
    from pirl.advice.oracle import oracle_recommendation
    from pirl.world.planning import WorldView

    venv = make_vec_env(1, seed=0, size=(15, 15, 3), wind_prob=0.0)
    venv.reset()
    rec = oracle_recommendation(WorldView.of(venv.world, 0, copy=True))
    assert isinstance(rec, Recommendation)
    # The largest paper footprint (9x9, half-width 4) at the cheapest setting: tilt 75 is the
    # first below 80, zoom 1.8 the first with floor(2 * zoom + 0.5) = 4.
    assert (rec.tilt, rec.zoom) == (75, 1.8)
    assert abs(rec.dx) + abs(rec.dy) + abs(rec.dz) == 1
