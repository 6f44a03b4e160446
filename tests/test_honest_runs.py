"""Honest runs and rows: a PIRL run that advice did not shape says so when it ends, and its
label carries ``unshaped N%`` in summary.csv, the tables and the report."""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path

import pytest

from pirl.agents.pirl_advice import build_pirl_advice, shaped_share, unshaped_warning
from pirl.agents.train import train
from pirl.config.run import RunConfig
from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_builtin, spec_for_run
from pirl.evaluate.summary import honest_label
from pirl.report.document import write_report

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"


@pytest.fixture(scope="module")
def starved(tmp_path_factory):
    """A PIRL run whose teacher is never asked (teacher rate 0): no step is shaped."""
    tmp = tmp_path_factory.mktemp("starved")
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(
        pare={
            "advisor": "oracle", "mode": "student", "teacher_rate": 0.0,
            "oracle_teacher_rate": 0.0, "student_dataset": str(tmp / "student.sqlite"),
        },
    )  # fmt: skip
    run = tmp / "pirl-starved-s0"
    return cfg, run, tmp


def test_a_starved_run_warns_and_is_labelled_unshaped_in_table_and_report(starved, capsys, caplog):
    cfg, run, tmp = starved
    train("pirl", cfg, run, seed=0, show_progress=False)
    err = capsys.readouterr().err
    warning = [line for line in err.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1 and "100% unshaped" in warning[0]
    assert "student gate never passed" in warning[0] and "in flight at the end 0" in warning[0]
    stats = json.loads((run / "advisor_stats.json").read_text())
    assert stats["steps_unshaped"] == stats["steps"] > 0
    assert "answers_in_flight" in stats and "teacher_waiting" in stats

    plan = EvalPlan(
        specs=[spec_for_run(run), spec_for_builtin("boustrophedon")],
        sizes=[(16, 16, 3)],
        episodes=1,
        env=cfg.env,
        config=cfg,
        acts=["stochastic"],
    )
    with caplog.at_level(logging.WARNING, logger="pirl.evaluate.summary"):
        summary = evaluate(plan, tmp / "eval", workers=1)
    # pirl evaluate warns once (a logged warning: one line on stderr from the command).
    assert sum("unshaped 100%" in r.getMessage() for r in caplog.records) == 1
    with open(summary, newline="") as fh:
        labels = {r["method"]: r["label"] for r in csv.DictReader(fh)}
    assert labels["pirl-oracle"].endswith("; unshaped 100%)")
    assert "unshaped" not in labels["boustrophedon"]
    stats["source"] = str(run)
    report = write_report(tmp / "report", summary, [run], advisor_stats={run.name: stats})
    table = (tmp / "report" / "table.md").read_text()
    table_rows = [line for line in table.splitlines() if line.startswith("| PIRL (")]
    assert table_rows and all("unshaped 100%" in line for line in table_rows)
    page = report.read_text()
    assert "unshaped 100%" in page
    # The summary at the top says how much of the run was shaped, before any table.
    assert page.index("Summary") < page.index("<table")
    assert f"{run.name} 0%" in page and f"{run.name} 0%" in table.split("Headline act")[0]


def test_a_row_is_labelled_when_any_of_its_runs_was_mostly_unshaped(tmp_path):
    def run(name: str, steps: int, unshaped: int, min_shaped: float = 0.5) -> str:
        folder = tmp_path / name
        folder.mkdir()
        stats = {"steps": steps, "steps_unshaped": unshaped, "label": "PIRL (x)"}
        (folder / "advisor_stats.json").write_text(json.dumps(stats))
        (folder / "config.yaml").write_text(f"pare:\n  min_shaped: {min_shaped}\n")
        return str(folder)

    shaped, starved, half = run("a", 1000, 0), run("b", 1000, 1000), run("c", 1000, 500)
    assert honest_label("PIRL (x)", [shaped]) == "PIRL (x)"
    assert honest_label("PIRL (x)", [half]) == "PIRL (x)"  # exactly half shaped is enough
    # Pooled over the row's runs: one starved seed of two labels the row.
    assert honest_label("PIRL (x)", [shaped, starved]) == "PIRL (x; unshaped 50%)"
    assert honest_label("PPO-EWRI", ["ppo-ewri-s0"]) == "PPO-EWRI"  # not a PIRL run
    strict = run("d", 1000, 200, min_shaped=0.9)  # the threshold is each run's own setting
    assert honest_label("PIRL", [strict]) == "PIRL (unshaped 20%)"


def test_the_warning_says_why():
    base = {"label": "PIRL (student of t)", "mode": "student", "steps": 1000}
    assert unshaped_warning({**base, "steps_unshaped": 400}, 0.5, 0.8) is None
    stats = {
        **base, "steps_unshaped": 900, "prompts_sent": 8, "answers_ok": 0,
        "answers_unparseable": 5, "answers_in_flight": 3, "student_heldout": 0,
        "gate_passed_at_step": -1,
    }  # fmt: skip
    assert shaped_share(stats) == pytest.approx(0.1)
    line = unshaped_warning(stats, 0.5, 0.8)
    assert line is not None and "\n" not in line
    for part in ("90% unshaped", "unparseable 5", "in flight at the end 3", "gate never passed",
                 "pirl advise"):  # fmt: skip
        assert part in line


def test_an_unparseable_probe_answer_is_one_warning_line(tmp_path):
    # The embedded model without its format constraint writes free text: the probe's answer
    # does not parse. Training may go on (the counters will say), but the user hears it now.
    from pirl.advice.local import LocalAdvisor

    advisor = LocalAdvisor(num_threads=1, constrained=False, max_new_tokens=3)
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(pare={"mode": "sync"})
    lines: list[str] = []
    build_pirl_advice(cfg, advisor, probe=True, log=lines.append)
    assert len(lines) == 1 and lines[0].startswith("warning:")
    assert "does not parse" in lines[0] and "pirl advise" in lines[0]


def test_the_summary_claims_only_what_the_intervals_show():
    from pirl.report.document import summary_lines

    def cmp(other, n_pirl, n_other, lo, hi, fixed=False, size="30x30x3"):
        return {"pirl": "PIRL (x)", "other": other, "sim": "grid", "size": size,
                "p": (lo + hi) / 2, "lo": lo, "hi": hi, "n_pirl": n_pirl, "n_other": n_other,
                "fixed": fixed}  # fmt: skip

    rows = [
        {"method": "pirl", "label": "PIRL (x)", "sim": "grid", "size": "30x30x3",
         "act": "stochastic", "seeds": 3, "vcr_iqm": 0.7, "vcr_mean": 0.7, "steps_mean": 300.0},
        {"method": "boustrophedon", "label": "planner", "sim": "grid", "size": "30x30x3",
         "act": "fixed", "seeds": 1, "vcr_iqm": 1.0, "vcr_mean": 1.0, "steps_mean": 120.0},
    ]  # fmt: skip
    found = [
        cmp("PPO-SR", 3, 3, 0.6, 0.9),
        cmp("planner", 3, 1, 0.0, 0.1, fixed=True),
        cmp("PPO-EWRI", 3, 3, 0.3, 0.8),  # includes 0.5: no claim
    ]
    stats = {"pirl-s0": {"steps": 100, "steps_unshaped": 10}}
    lines = summary_lines(rows, found, stats, "stochastic")
    text = " ".join(lines)
    assert "PIRL (x) beats PPO-SR (30x30x3: 0.75 [0.60, 0.90]) and loses to planner" in text
    assert "PPO-EWRI" not in lines[0]
    assert "PIRL (x) reaches VCR 0.70" in text and "the planner 1.00 in 120" in text
    assert "pirl-s0 90%" in text
    # One run against one: P is 0 or 1 with a point interval, never a claim.
    single = summary_lines(rows, [cmp("PPO-SR", 1, 1, 1.0, 1.0)], None, "stochastic")
    assert single[0].startswith("No PIRL variant") and "one training run per row" in single[0]
