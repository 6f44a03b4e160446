"""Evaluation: scenario sets, summaries with confidence intervals, reproducible runs."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from pirl.config.errors import ConfigError
from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_builtin
from pirl.evaluate.scenarios import parse_size, scenario_seeds
from pirl.evaluate.summary import mean_ci95, read_summary, summarize


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


def test_longest_tasks_are_handed_out_first():
    """Physics episodes (seconds each) go to the workers before grid chunks, larger worlds
    first, so no long task starts last while the other workers idle."""
    from pirl.evaluate.runner import _tasks

    plan = EvalPlan(
        [spec_for_builtin("boustrophedon"), spec_for_builtin("random")],
        [(10, 10, 3), (30, 30, 3), (20, 20, 3)], 2, sims=["grid", "physics"],
        sim_sizes={"physics": [(10, 10, 3)]},
    )  # fmt: skip
    tasks = _tasks(plan, 2)
    sims = [t[2] for t in tasks]
    assert sims == ["physics"] * sims.count("physics") + ["grid"] * sims.count("grid")
    assert sims.count("physics") == 4  # 2 methods x 2 episodes, one per task
    areas = [t[1][0] * t[1][1] for t in tasks if t[2] == "grid"]
    assert areas == sorted(areas, reverse=True) and areas[0] == 900


def test_a_batched_group_is_one_task_unless_too_few_keep_the_workers_busy():
    """A trained policy's scenarios of one world and act mode play in one batch (one policy
    forward per step for all of them); with fewer such groups than twice the workers, each
    is split so that every worker has work. Built-ins play episode by episode."""
    from pirl.evaluate.runner import MethodSpec, _tasks

    run = MethodSpec("ppo-ewri", "PPO-EWRI", "runs/ppo-ewri-s0", train_seed=0)
    builtin = spec_for_builtin("boustrophedon")

    def chunks(plan, workers=2):
        return sorted((t[0].key, t[4], len(t[3])) for t in _tasks(plan, workers))

    many = EvalPlan([run, builtin], [(10, 10, 3), (20, 20, 3)], 4, acts=["stochastic", "greedy"])
    assert chunks(many) == sorted(
        [("ppo-ewri", act, 4) for act in ("stochastic", "greedy") for _ in range(2)]
        + [("boustrophedon", "fixed", 1)] * 8
    )
    few = EvalPlan([run], [(10, 10, 3)], 4, acts=["stochastic"])
    assert chunks(few) == [("ppo-ewri", "stochastic", 2)] * 2
    assert chunks(few, workers=1) == [("ppo-ewri", "stochastic", 4)]


# -- act modes, batching, seeds as the unit -------------------------------------------------
@pytest.fixture(scope="module")
def trained_runs(tmp_path_factory):
    """Two tiny PPO-EWRI runs (seeds 0 and 1) on the test preset."""
    from pathlib import Path

    from pirl.agents.runs import train_one
    from pirl.config.run import RunConfig

    root = tmp_path_factory.mktemp("runs")
    cfg = RunConfig.from_yaml(Path(__file__).resolve().parents[1] / "configs" / "test.yaml")
    runs = []
    for seed in (0, 1):
        run = root / f"ppo-ewri-s{seed}"
        train_one("ppo-ewri", "", seed, cfg, run, False, False)
        runs.append(run)
    return cfg, runs


def _episodes(folder):
    return [json.loads(line) for line in (folder / "episodes.jsonl").open()]


def test_stochastic_evaluation_is_seeded_per_scenario_and_differs_from_greedy(
    trained_runs, tmp_path
):
    from pirl.evaluate.runner import spec_for_run

    cfg, runs = trained_runs
    plan = EvalPlan(
        specs=[spec_for_run(runs[0]), spec_for_builtin("boustrophedon")], sizes=[(12, 12, 3)],
        episodes=3, env=cfg.env, config=cfg, acts=["stochastic", "greedy"],
    )  # fmt: skip
    first = evaluate(plan, tmp_path / "a", workers=1)
    again = evaluate(plan, tmp_path / "b", workers=2)
    assert first.read_text() == again.read_text()
    records = _episodes(tmp_path / "a")
    assert records == _episodes(tmp_path / "b")
    acts = {(r["method"], r["act"]) for r in records}
    assert acts == {("ppo-ewri", "stochastic"), ("ppo-ewri", "greedy"), ("boustrophedon", "fixed")}
    by_act = {
        act: [(r["seed"], r["steps"], r["vcr"], r["camera_share"]) for r in records
              if r["method"] == "ppo-ewri" and r["act"] == act]
        for act in ("stochastic", "greedy")
    }  # fmt: skip
    assert [s[0] for s in by_act["stochastic"]] == [s[0] for s in by_act["greedy"]]
    assert by_act["stochastic"] != by_act["greedy"]
    rows = read_summary(first)
    assert {r["act"] for r in rows} == {"stochastic", "greedy", "fixed"}
    with pytest.raises(ConfigError, match="stochastic, greedy, both"):
        evaluate(replace_acts(plan, ["sampled"]), tmp_path / "c")


def replace_acts(plan, acts):
    from dataclasses import replace

    return replace(plan, acts=acts)


def test_batched_evaluation_equals_per_episode(trained_runs, tmp_path):
    from pirl.evaluate.runner import spec_for_run

    cfg, runs = trained_runs
    out = {}
    for batched in (True, False):
        plan = EvalPlan(
            specs=[spec_for_run(r) for r in runs], sizes=[(14, 14, 3), (20, 12, 3)], episodes=4,
            env=cfg.env, config=cfg, acts=["stochastic", "greedy"], batched=batched,
        )  # fmt: skip
        out[batched] = evaluate(plan, tmp_path / str(batched), workers=1)
    assert _episodes(tmp_path / "True") == _episodes(tmp_path / "False")
    assert out[True].read_text() == out[False].read_text()


def test_seeds_are_the_unit_on_a_hand_made_table():
    import numpy as np
    from scipy import stats

    from pirl.evaluate.summary import interval_estimates, probability_of_improvement, seed_scores

    seeds = {0: [0.5, 0.7], 1: [0.8, 0.8], 2: [0.2, 0.4], 3: [0.9, 0.7]}
    records = [
        {"method": "pirl", "sim": "grid", "size": "30x30x3", "act": "stochastic",
         "train_seed": s, "vcr": v, "be": v / 2, "rvc": 1 - v}
        for s, values in seeds.items() for v in values
    ]  # fmt: skip
    (row,) = summarize(records)
    per_seed = np.array([0.6, 0.8, 0.3, 0.8])
    assert row["seeds"] == 4 and row["n"] == 8
    assert row["vcr_mean"] == pytest.approx(per_seed.mean())
    # IQM of 4 runs: the middle two (scipy's 25% trimmed mean, as rliable computes it).
    assert row["vcr_iqm"] == pytest.approx(stats.trim_mean(per_seed, 0.25))
    assert row["vcr_iqm"] == pytest.approx((0.6 + 0.8) / 2)
    assert per_seed.min() <= row["vcr_iqm_lo"] <= row["vcr_iqm"] <= row["vcr_iqm_hi"] <= 0.8
    assert per_seed.min() <= row["vcr_mean_lo"] < row["vcr_mean"] < row["vcr_mean_hi"] <= 0.8
    # The per-episode interval is the secondary spread, over 8 episodes.
    assert row["vcr_ci95"] == pytest.approx(mean_ci95([v for r in seeds.values() for v in r])[1])
    assert seed_scores(records, "vcr").ravel().tolist() == pytest.approx(per_seed.tolist())
    # A single run has no spread over runs.
    one = interval_estimates(np.array([[0.4]]))
    assert one["iqm_lo"] == one["iqm_hi"] == 0.4
    # Every run of x above every run of y: P(improvement) = 1; equal runs: 0.5.
    x, y = np.array([[0.9], [0.8], [0.85]]), np.array([[0.5], [0.6], [0.4]])
    assert probability_of_improvement(x, y)[0] == pytest.approx(1.0)
    assert probability_of_improvement(y, y)[0] == pytest.approx(0.5)


def test_camera_table_gives_steps_relative_to_the_planner():
    from pirl.report.document import camera_table

    def row(method: str, label: str, steps: float, vcr: float, **more) -> dict:
        return {
            "sim": "grid", "method": method, "label": label, "act": "greedy", "size": "30x30x3",
            "vcr_iqm": vcr, "vcr_iqm_lo": vcr, "vcr_iqm_hi": vcr, "vcr_mean": vcr,
            "steps_mean": steps, "n": 8, **more,
        }  # fmt: skip

    table = camera_table(
        [
            row("boustrophedon", "planner", 200.0, 1.0),  # a summary from before loops counted
            row("ppo-ewri", "PPO-EWRI", 300.0, 0.9, loop_episodes=3.0),
        ]
    )
    assert "steps / planner's" in table.header
    ewri = next(row for row in table.rows if row[0] == "PPO-EWRI")
    assert ewri[-3] == "1.50" and ewri[-2] == "0.30" and ewri[-1] == "3 of 8"
    planner = next(row for row in table.rows if row[0] == "planner")
    assert planner[-1] == "—"
    assert "steps chosen by the stall guard" not in table.header  # no guard, no column
    guarded = camera_table([row("ppo-ewri", "PPO-EWRI", 300.0, 0.9, guarded_share_mean=0.031)])
    assert guarded.header[-1] == "steps chosen by the stall guard"
    assert guarded.rows[0][-1] == "3.1%"


def test_summary_counts_the_episodes_that_ended_in_a_loop():
    from pirl.evaluate.summary import loop_episodes

    group = [{"tail_cells": 2}, {"tail_cells": 9}, {"tail_cells": 10}, {"tail_cells": 55}, {}]
    assert loop_episodes(group) == 2


def test_report_settings_line_says_masked_or_not():
    from pathlib import Path

    from pirl.config.run import RunConfig
    from pirl.reproduce.pipeline import settings_line

    root = Path(__file__).resolve().parents[1] / "configs"
    quick = settings_line(RunConfig.from_yaml(root / "quick.yaml"))
    paper = settings_line(RunConfig.from_yaml(root / "paper.yaml"))
    assert "valid-action masks" in quick and "visit counts" in quick
    assert "no action masks" in paper and "the paper's observation" in paper
    assert "camera poses" not in quick and "camera poses" not in paper  # fixed starts
    starts = RunConfig.from_yaml(root / "quick.yaml").with_overrides(
        train={"camera_start": "random"}
    )
    assert "random camera poses" in settings_line(starts)
    assert "stall guard" not in paper
    guard = RunConfig.from_yaml(root / "paper.yaml").with_overrides(env={"stall_guard": 32})
    assert "stall guard on: after 32 steps" in settings_line(guard)


def test_a_run_is_evaluated_only_with_its_own_observation(trained_runs, tmp_path):
    """A run trained with the straight-line target, evaluated where the env finds the way round
    obstacles (same observation length, other meaning): refused in one line that says what to
    do, before any episode."""
    from pirl.evaluate.runner import spec_for_run

    cfg, runs = trained_runs
    plan = EvalPlan(
        specs=[spec_for_run(runs[0])], sizes=[(12, 12, 3)], episodes=1,
        env=cfg.env.replace(obs_target_path=True), config=cfg,
    )  # fmt: skip
    with pytest.raises(ConfigError, match="obs_target_path=False.*train it again"):
        evaluate(plan, tmp_path / "eval")
    assert not (tmp_path / "eval" / "episodes.jsonl").exists()


@pytest.mark.filterwarnings("ignore:random_state is deprecated:FutureWarning")
def test_pairwise_improvement_is_rliables_probability_of_improvement():
    """The metric the report bootstraps equals rliable's own on random and tied scores, and
    so do the point estimate and interval of a bootstrap with either."""
    import numpy as np
    from rliable import library, metrics

    from pirl.evaluate.summary import (
        interval_estimates,
        pairwise_improvement,
        probability_of_improvement,
    )

    rng = np.random.default_rng(0)
    for runs_x, runs_y, tasks in ((3, 3, 1), (2, 5, 4), (6, 4, 3)):
        x = rng.integers(0, 4, (runs_x, tasks)) / 4  # few values: many ties
        y = rng.integers(0, 4, (runs_y, tasks)) / 4
        for a, b in ((x, y), (y, x), (x, x), (x + 0.3, y)):
            assert pairwise_improvement(a, b) == pytest.approx(
                metrics.probability_of_improvement(a, b), abs=1e-12
            )
    # rliable resamples with NumPy's global generator whatever random_state it is given:
    # seeded alike, its bootstrap and ours give the same interval, and ours gives it on
    # every call, whatever the global generator did in between.
    np.random.seed(0)
    point, ci = library.get_interval_estimates(
        {"xy": (x, y)}, metrics.probability_of_improvement, reps=200,
        random_state=np.random.RandomState(0),
    )  # fmt: skip
    ours = probability_of_improvement(x, y, reps=200)
    assert ours == pytest.approx((point["xy"], *np.ravel(ci["xy"])[:2]), abs=1e-12)
    np.random.seed(123)
    assert probability_of_improvement(x, y, reps=200) == ours
    assert interval_estimates(x) == interval_estimates(x)


def test_steps_to_near_complete_coverage_against_the_planner():
    from pirl.agents.loading import load_policy
    from pirl.config.world import VCPPConfig
    from pirl.env.vcpp_env import VCPPEnv
    from pirl.evaluate.rollout import run_episode
    from pirl.report.document import camera_table

    env = VCPPEnv(VCPPConfig(size=(12, 12, 3)))
    m = run_episode(env, load_policy("boustrophedon"), 3).metrics
    # The planner covers the world: it passes 0.99 of the coverable cells at or before its end.
    assert m["vcr"] >= 0.99 and 0 < m["steps_to_99"] <= m["steps"]
    stuck = run_episode(env, load_policy("random", seed=0), 3).metrics
    assert stuck["vcr"] < 0.99 and stuck["steps_to_99"] is None
    rows = summarize(
        [{"method": "boustrophedon", "sim": "grid", "size": "12x12x3", "act": "fixed",
          "vcr": 1.0, "be": 0.5, "rvc": 0.0, "run": "planner", "steps_to_99": 100},
         {"method": "ppo-ewri", "sim": "grid", "size": "12x12x3", "act": "fixed",
          "vcr": 0.99, "be": 0.5, "rvc": 0.0, "run": "a", "steps_to_99": 150, "label": "PPO-EWRI"},
         {"method": "ppo-ewri", "sim": "grid", "size": "12x12x3", "act": "fixed",
          "vcr": 0.5, "be": 0.5, "rvc": 0.0, "run": "a", "steps_to_99": None, "label": "PPO-EWRI"}]
    )  # fmt: skip
    ewri = next(r for r in rows if r["method"] == "ppo-ewri")
    assert ewri["steps_to_99_mean"] == 150 and ewri["reached_99"] == 1
    table = camera_table(rows)
    col = table.header.index("steps to 0.99 / planner's")
    cells = {row[0]: row[col] for row in table.rows}
    assert cells["PPO-EWRI"] == "1.50 (1 of 2 got there)"


# -- fleets ---------------------------------------------------------------------------------
def test_fleet_evaluation_k1_plays_as_one_uav_and_larger_fleets_cover_sooner(
    trained_runs, tmp_path
):
    """``--uavs 1,2``: every size is played as a fleet; the fleet of one plays exactly as the
    single UAV (the same steps and coverage, for the shared learned policy in both act modes
    and for the planner), and the fleet of two has its makespans, speed-up and no collision."""
    from pirl.evaluate.runner import spec_for_run

    cfg, runs = trained_runs
    specs = [spec_for_run(runs[0]), spec_for_builtin("boustrophedon")]
    common = dict(sizes=[(12, 12, 3)], episodes=3, env=cfg.env, config=cfg)
    acts = ["stochastic", "greedy"]
    evaluate(EvalPlan(specs=specs, acts=acts, **common), tmp_path / "one")
    evaluate(EvalPlan(specs=specs, acts=acts, uavs=[1, 2], **common), tmp_path / "fleet")
    single = {(r["method"], r["act"], r["seed"]): r for r in _episodes(tmp_path / "one")}
    fleet = _episodes(tmp_path / "fleet")
    assert {r["uavs"] for r in fleet} == {1, 2}
    for r in fleet:
        assert r["collisions"] == 0
        assert r["makespan_99"] is not None or r["method"] != "boustrophedon"
        assert len(r["coverage_steps"]) == 20 and len(r["credit"]) == r["uavs"]
        if r["uavs"] == 1:
            alone = single[(r["method"], r["act"], r["seed"])]
            assert (r["steps"], r["covered"]) == (alone["steps"], alone["covered"])
            assert r["makespan_99"] == alone["steps_to_99"]
    rows = read_summary(tmp_path / "fleet" / "summary.csv")
    two = [r for r in rows if r["uavs"] == 2 and r["method"] == "boustrophedon"]
    assert len(two) == 1 and 0 < two[0]["speed_up_mean"] < 1
    # Undefined (nan) where a run never reached 0.99: the tiny runs here do not.
    ones = [r["speed_up_mean"] for r in rows if r["uavs"] == 1]
    assert all(s == 1 or math.isnan(s) for s in ones)
    assert [
        r["speed_up_mean"] for r in rows if r["uavs"] == 1 and r["method"] == "boustrophedon"
    ] == [1]


def test_fleet_evaluation_refuses_what_cannot_fly_in_a_fleet(tmp_path, monkeypatch):
    from pirl.agents.methods import METHODS

    plan = EvalPlan([spec_for_builtin("boustrophedon")], [(10, 10, 3)], 1, uavs=[1, 2])
    with pytest.raises(ConfigError, match="grid only"):
        evaluate(replace(plan, sims=["grid", "physics"]), tmp_path / "a")
    with pytest.raises(ConfigError, match="uavs"):
        evaluate(replace(plan, uavs=[0, 2]), tmp_path / "b")
    llm = spec_for_builtin("llm-only", "oracle")
    # A method registered as flying alone (every built-in one flies in a fleet).
    monkeypatch.setitem(METHODS, "llm-only", replace(METHODS["llm-only"], fleet=False))
    with pytest.raises(ConfigError, match="flies one UAV"):
        evaluate(replace(plan, specs=[llm]), tmp_path / "c")
    assert not (tmp_path / "a").exists() and not (tmp_path / "c").exists()
