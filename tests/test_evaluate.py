"""Evaluation: scenario sets, summaries with confidence intervals, reproducible runs."""

from __future__ import annotations

import json
import math

import pytest

from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_builtin
from pirl.evaluate.scenarios import parse_size, scenario_seeds
from pirl.evaluate.summary import mean_ci95, read_summary, summarize
from pirl.world.config import ConfigError


def test_parse_size():
    assert parse_size("30") == (30, 30, 3)
    assert parse_size("40x25x4") == (40, 25, 4)
    assert parse_size("40x25") == (40, 25, 3)
    with pytest.raises(ConfigError, match="impossible"):
        parse_size("2x30x3")
    with pytest.raises(ConfigError, match="XxYxZ"):
        parse_size("big")


def test_scenario_seeds_are_shared_disjoint_and_far_from_training():
    a = scenario_seeds((30, 30, 3), 100)
    assert a == scenario_seeds((30, 30, 3), 100)
    assert a[:10] == scenario_seeds((30, 30, 3), 10)
    assert not set(a) & set(scenario_seeds((45, 45, 3), 100))
    assert not set(a) & set(scenario_seeds((30, 30, 4), 100))
    assert min(a) >= 1_000_000_000  # training worlds are seeded 1000 * seed + i


def test_mean_ci95_by_hand():
    mean, half = mean_ci95([0.5, 0.7, 0.9])
    # sd = 0.2, t(0.975, 2) = 4.302653
    assert mean == pytest.approx(0.7)
    assert half == pytest.approx(4.302653 * 0.2 / math.sqrt(3), rel=1e-6)
    assert math.isnan(mean_ci95([0.4])[1])


def test_summary_groups_by_method_sim_size():
    records = [
        {"method": "a", "sim": "grid", "size": "30x30x3", "vcr": v, "be": 0.5, "rvc": 0.1}
        for v in (0.2, 0.4)
    ] + [{"method": "a", "sim": "grid", "size": "45x45x3", "vcr": 1.0, "be": 1.0, "rvc": 0.0}]
    rows = summarize(records)
    assert [(r["size"], r["n"]) for r in rows] == [("30x30x3", 2), ("45x45x3", 1)]
    assert rows[0]["vcr_mean"] == pytest.approx(0.3)


def test_evaluation_is_reproducible_and_independent_of_workers(tmp_path):
    plan = EvalPlan(
        specs=[spec_for_builtin("boustrophedon"), spec_for_builtin("random")],
        sizes=[(20, 20, 3), (25, 15, 4)],
        episodes=3,
    )
    one = evaluate(plan, tmp_path / "one", workers=1)
    again = evaluate(plan, tmp_path / "again", workers=1)
    two = evaluate(plan, tmp_path / "two", workers=2)
    assert one.read_text() == again.read_text() == two.read_text()
    records = [json.loads(line) for line in (tmp_path / "one" / "episodes.jsonl").open()]
    assert len(records) == 2 * 2 * 3
    # Every method saw the same scenarios.
    seeds = {
        m: [r["seed"] for r in records if r["method"] == m] for m in ("boustrophedon", "random")
    }
    assert seeds["boustrophedon"] == seeds["random"]
    rows = {(r["method"], r["size"]): r for r in read_summary(one)}
    assert rows[("boustrophedon", "20x20x3")]["vcr_mean"] >= 0.95
    assert rows[("boustrophedon", "20x20x3")]["vcr_mean"] > rows[("random", "20x20x3")]["vcr_mean"]
    header = one.read_text().splitlines()[0]
    assert header.startswith(
        "method,sim,size,n,vcr_mean,vcr_ci95,be_mean,be_ci95,rvc_mean,rvc_ci95"
    )


def test_bad_plans_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="built-in methods"):
        spec_for_builtin("ppo")
    with pytest.raises(ConfigError, match="simulators"):
        evaluate(
            EvalPlan([spec_for_builtin("random")], [(10, 10, 3)], 1, sims=["webots"]), tmp_path
        )
    with pytest.raises(ConfigError, match="nothing to evaluate"):
        evaluate(EvalPlan([], [(10, 10, 3)], 1), tmp_path)
