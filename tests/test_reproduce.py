"""The main job end to end on the tiny preset: train all, evaluate, report, resume."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from pirl.config.run import RunConfig
from pirl.reproduce.pipeline import reproduce, train_all
from report_view import check_first_screen, render

ROOT = Path(__file__).resolve().parents[1]
SECRET = "sk-test-do-not-leak-4242"


@pytest.fixture(scope="module")
def reproduced(tmp_path_factory):
    out = tmp_path_factory.mktemp("repro")
    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml")
    logs: list[str] = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("OPENAI_API_KEY", SECRET)
        report = reproduce(cfg, out, advisor="oracle", log=logs.append, show_progress=False)
    return cfg, out, report, logs


def test_every_method_is_trained_evaluated_and_reported(reproduced):
    _, out, report, _ = reproduced
    runs = sorted(p.name for p in (out / "runs").iterdir())
    assert runs == ["il-s0", "pirl-oracle-s0", "ppo-ewri-s0", "ppo-sr-s0"]
    summary = (out / "eval" / "summary.csv").read_text().splitlines()
    methods = {line.split(",")[0] for line in summary[1:]}
    assert methods == {
        "ppo-sr", "ppo-ewri", "pirl-oracle", "il", "llm-only", "boustrophedon", "random",
    }  # fmt: skip
    table = (report.parent / "table.md").read_text()
    assert "Table 1: grid simulator" in table
    assert "site:campus VCR" in table  # reproduce.sites: every method on the site too
    # Rows carry each run's full label (meta.json's, when the run records one).
    meta = json.loads((out / "runs" / "pirl-oracle-s0" / "meta.json").read_text())
    label = meta.get("label") or "PIRL (oracle advisor, not an LLM)"
    assert label in table and "not an LLM" in label
    assert "LLM-only (oracle, not an LLM)" in table
    assert "(0.64)" not in table  # sizes without a paper column carry no paper numbers
    # reproduce.uavs: the planner, PPO-EWRI and PIRL (every variant: fleet_methods names the
    # method) flown as fleets of 1 and 2 on the campus.
    fleets = table.split("### Fleets")[1].split("###")[0]
    flown = {(line.split("|")[3].strip(), line.split("|")[4].strip())
             for line in fleets.splitlines() if line.startswith("| site:campus")}  # fmt: skip
    assert {k for _, k in flown} == {"1", "2"} and len(flown) == 6
    cells = [tuple(c.strip() for c in line.split("|")[1:5])
             for line in fleets.splitlines() if line.startswith("| site:campus")]  # fmt: skip
    assert len(cells) == len(set(cells))  # one row per world, act, method and fleet size
    assert label in fleets
    assert (report.parent / "fleet_coverage.png").stat().st_size > 10_000
    for name in ("figure.png", "learning_curves.png"):
        assert (report.parent / name).stat().st_size > 10_000
    gifs = sorted(p.name for p in (report.parent / "gifs").iterdir())
    assert "boustrophedon.gif" in gifs and "ppo-ewri.gif" in gifs and "llm-only.gif" in gifs
    html = report.read_text()
    assert html.count("data:image/") >= 2 + len(gifs)
    for path in out.rglob("*"):
        if path.is_file() and path.suffix in (".html", ".yaml", ".json", ".csv", ".jsonl", ".md"):
            assert SECRET not in path.read_text(errors="ignore"), path


def test_report_renders_in_headless_chromium(reproduced, tmp_path):
    _, _, report, _ = reproduced
    # At 1280x800, with a script that measures the first screen (a copy of the page).
    dom = render(report, tmp_path, measure=True)
    match = re.search(r'data-images="(\d+)/(\d+)"', dom)
    assert match, "the page's load script did not run"
    loaded, total = map(int, match.groups())
    assert total >= 8 and loaded == total
    # Read at a glance: the rendered page opens with the generated summary (the headline
    # table, then the findings), then the interval figure, then the tables of results.
    first_h2 = re.search(r"<h2[^>]*>([^<]*)</h2>", dom)
    assert first_h2 and first_h2.group(1) == "Summary"
    summary = dom[dom.index("Summary") : dom.index("<h2", dom.index("Summary"))]
    assert summary.count("<li>") >= 2 and "planner" in summary and "shaped" in summary
    assert (
        dom.index("Summary")
        < dom.index('id="headline-table"')
        < dom.index('alt="intervals')
        < dom.index("<h2>Results</h2>")
    )
    # The first screen at 1280 px holds the headline table and the findings; no finding
    # runs past 30 words; no figure is shrunk below its drawn size.
    check_first_screen(dom)


def test_a_second_run_reuses_training_and_gives_the_same_numbers(reproduced, monkeypatch):
    from pirl.reproduce import plan

    cfg, out, report, _ = reproduced
    before = (out / "eval" / "summary.csv").read_text()
    logs: list[str] = []
    calls: list[object] = []
    real = plan.plan_runs
    monkeypatch.setattr(plan, "plan_runs", lambda *args: calls.append(args) or real(*args))
    reproduce(cfg, out, advisor="oracle", log=logs.append, show_progress=False)
    assert len(calls) == 1  # the plan is made once, and everything reads it
    assert sum("already trained" in line for line in logs) == 4
    assert (out / "eval" / "summary.csv").read_text() == before


def test_an_interrupted_run_resumes_from_its_checkpoint(reproduced):
    cfg, out, _, _ = reproduced
    run = out / "runs" / "ppo-sr-s0"
    meta = json.loads((run / "meta.json").read_text())
    meta["complete"] = False
    (run / "meta.json").write_text(json.dumps(meta))
    (run / "model.zip").unlink()
    logs: list[str] = []
    # The reproduction's training stage (check, lock, plan, run), without evaluating again.
    train_all(cfg, out, "oracle", logs.append, show_progress=False)
    assert "ppo-sr-s0: resuming" in logs
    assert json.loads((run / "meta.json").read_text())["complete"]


def _probabilities(run: Path):
    import numpy as np

    from pirl.agents.loading import load_policy
    from pirl.env.sb3_vec import make_vec_env

    cfg = RunConfig.from_yaml(run / "config.yaml")
    obs = make_vec_env(8, seed=123, config=cfg.env).reset()
    return np.asarray(load_policy(run).probabilities(obs))


def test_parallel_training_gives_the_same_models_as_sequential(tmp_path):
    import numpy as np

    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml").with_overrides(
        reproduce={"methods": ["ppo-sr", "ppo-ewri", "il"], "seeds": [0]}
    )
    seq_logs: list[str] = []
    par_logs: list[str] = []
    seq = train_all(cfg, tmp_path / "seq", "oracle", seq_logs.append, False, workers=1)
    par = train_all(cfg, tmp_path / "par", "oracle", par_logs.append, False, workers=2)
    assert any("in 2 worker processes" in line for line in par_logs)
    for logs in (seq_logs, par_logs):  # queued before a run starts, training when it starts
        for name in ("ppo-sr-s0", "ppo-ewri-s0", "il-s0"):
            queued, training = logs.index(f"{name}: queued"), logs.index(f"{name}: training")
            assert queued < training
        assert logs.index("il-s0: training") > next(
            i for i, line in enumerate(logs) if line.startswith("ppo-ewri-s0: done in")
        )
    assert [p.name for p in seq] == [p.name for p in par] == ["ppo-sr-s0", "ppo-ewri-s0", "il-s0"]
    for a, b in zip(seq, par, strict=True):
        np.testing.assert_array_equal(_probabilities(a), _probabilities(b))


def test_the_camera_study_profile_loads_and_runs_at_test_size(tmp_path):
    import yaml

    study = yaml.safe_load((ROOT / "configs" / "study-camera.yaml").read_text())
    tiny = yaml.safe_load((ROOT / "configs" / "test.yaml").read_text())
    rp = study["reproduce"]
    assert len(rp["seeds"]) >= 3 and rp["sizes"] == ["15", "30", "60"]
    assert set(rp["acts"]) == {"stochastic", "greedy"}
    for section in ("env", "ppo", "train", "il"):  # the study's design at the test's budgets
        study[section] = tiny[section]
    # No teacher phase here (tests/test_teacher_phase.py runs one): 200 LLM answers take minutes.
    # Evaluation in this process (workers 1): a pool's two fresh interpreters would import
    # torch and the env again for 24 small episodes; test_evaluate checks pools give the same.
    study["reproduce"].update(
        seeds=[0], sizes=["12"], episodes=2, teacher_phase_answers=0, workers=1
    )
    cfg = RunConfig.from_dict(study)
    logs: list[str] = []
    report = reproduce(cfg, tmp_path, advisor="local", log=logs.append, show_progress=False)
    assert logs[0].startswith("plan: 6 training runs")
    runs = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert len(runs) == 6 and "pirl-local-lamcam1.0-lammove1.0-s0" in runs
    rows = list(csv_rows(tmp_path / "eval" / "summary.csv"))
    labels = {r["label"] for r in rows if r["method"].startswith("pirl")}
    assert len(labels) == 4  # each PIRL variant its own row, named by advisor and weights
    assert all("lam_cam" in label for label in labels), labels
    assert {r["act"] for r in rows} == {"stochastic", "greedy", "fixed"}
    table = (report.parent / "table.md").read_text()
    assert "Camera use" in table and "Probability of improvement" in table
    assert (report.parent / "intervals_stochastic.png").stat().st_size > 10_000


def csv_rows(path: Path):
    import csv

    with open(path, newline="") as fh:
        yield from csv.DictReader(fh)


def test_report_says_how_much_advice_shaped_each_pirl_run(reproduced):
    _, out, report, _ = reproduced
    table = (report.parent / "table.md").read_text()
    assert "How much advice shaped each PIRL run" in table
    stats = json.loads((out / "runs" / "pirl-oracle-s0" / "advisor_stats.json").read_text())
    row = next(line for line in table.splitlines() if line.startswith("| pirl-oracle-s0 |"))
    assert stats["label"] in row
    shaped = (stats["steps_student"] + stats["steps_teacher"]) / stats["steps"]
    assert f"{1 - shaped:.0%}" in row  # the unshaped share is printed
