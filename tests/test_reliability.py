"""Runs that cannot go wrong: user mistakes answered in one line with nothing
half-made, resume that continues the run in the folder (kill -9 included), results that never
mix, every setting reachable, quiet output. CLI cases run as real subprocesses."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
import torch
import yaml

from cli_checks import one_error_line as _one_clean_line
from pirl.agents import checkpoint
from pirl.agents.loading import load_model
from pirl.agents.train import train
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.evaluate import runner
from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_run
from pirl.evaluate.summary import read_summary
from pirl.progress import Progress

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"
PIRL = [sys.executable, "-m", "pirl"]


def _pirl(*args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*PIRL, *args], cwd=cwd, capture_output=True, text=True, timeout=300, env=env
    )


def _same_weights(a: Path, b: Path) -> bool:
    sa = load_model(a, device="cpu").policy.state_dict()
    sb = load_model(b, device="cpu").policy.state_dict()
    return all(torch.equal(sa[k], sb[k]) for k in sa)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """Finished PPO-SR runs of test.yaml: seed 1 and seed 2."""
    root = tmp_path_factory.mktemp("runs")
    cfg = RunConfig.from_yaml(TEST_CFG)
    out = {}
    for seed in (1, 2):
        out[f"sr{seed}"] = root / f"sr{seed}"
        train("ppo-sr", cfg, out[f"sr{seed}"], seed=seed, show_progress=False)
    return out


def _copy(run: Path, dest: Path) -> Path:
    shutil.copytree(run, dest)
    return dest


# -- user mistakes: one line, exit 2, no traceback, nothing half-made -------------------------
def test_openai_without_key_is_one_line_and_makes_no_folder(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "OPENAI_API_KEY"}
    out = tmp_path / "run"
    proc = _pirl(
        "train", "--method", "pirl", "--advisor", "openai", "--config", str(TEST_CFG),
        "--out", str(out), cwd=tmp_path, env=env,
    )  # fmt: skip
    _one_clean_line(proc, "OPENAI_API_KEY")
    assert not out.exists()
    # reproduce takes its advisor from the preset unless --advisor says otherwise
    preset = tmp_path / "openai.yaml"
    data = yaml.safe_load(TEST_CFG.read_text())
    data["pare"]["advisor"] = "openai"
    preset.write_text(yaml.safe_dump(data))
    proc = _pirl("reproduce", "--config", str(preset), "--out", str(out), cwd=tmp_path, env=env)
    _one_clean_line(proc, "OPENAI_API_KEY")
    assert not out.exists()


def test_damaged_or_missing_model_files_are_named(runs, tmp_path):
    bad = _copy(runs["sr1"], tmp_path / "bad")
    (bad / "model.zip").write_bytes((bad / "model.zip").read_bytes()[:300])
    ev = tmp_path / "eval"
    proc = _pirl("evaluate", "--runs", str(bad), "--sizes", "16", "--episodes", "1",
                 "--out", str(ev), cwd=tmp_path)  # fmt: skip
    _one_clean_line(proc, str(bad / "model.zip"), "damaged")
    assert not ev.exists()

    il = tmp_path / "il"
    il.mkdir()
    (il / "meta.json").write_text(json.dumps({"method": "il", "seed": 0, "complete": True}))
    proc = _pirl("evaluate", "--runs", str(il), "--out", str(ev), cwd=tmp_path)
    _one_clean_line(proc, "tabnet.zip")
    assert not ev.exists()


@pytest.mark.parametrize("damage", ["corrupt", "no-model", "not-a-run"])
def test_il_with_a_bad_expert_makes_no_folder(runs, tmp_path, damage):
    expert = tmp_path / "expert"
    if damage == "corrupt":
        _copy(runs["sr1"], expert)
        (expert / "model.zip").write_bytes(b"PK\x03\x04 not really a zip")
    elif damage == "no-model":
        _copy(runs["sr1"], expert)
        (expert / "model.zip").unlink()
    out = tmp_path / "il"
    proc = _pirl("train", "--method", "il", "--expert", str(expert), "--config", str(TEST_CFG),
                 "--out", str(out), cwd=tmp_path)  # fmt: skip
    _one_clean_line(proc, str(expert))
    assert not out.exists()


def test_truncated_latest_checkpoint_falls_back_to_the_previous_one(runs, tmp_path):
    run = _copy(runs["sr1"], tmp_path / "run")
    # Make it an interrupted run: no final model, and the newest checkpoint cut short.
    (run / "model.zip").unlink()
    meta = json.loads((run / "meta.json").read_text())
    (run / "meta.json").write_text(json.dumps({**meta, "complete": False}))
    ckpts = run / "checkpoints"
    latest = checkpoint.latest(ckpts)
    state = latest / "state.npz"
    state.write_bytes(state.read_bytes()[: state.stat().st_size // 2])
    found = checkpoint.load_latest(ckpts)
    assert found is not None and found[0] != latest
    proc = _pirl("train", "--method", "ppo-sr", "--out", str(run), "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "damaged" in proc.stdout and "Traceback" not in proc.stderr
    assert _same_weights(run / "model.zip", runs["sr1"] / "model.zip")


# -- resume continues the run that is in the folder ---------------------------------------------
def test_resume_refuses_a_different_method_seed_advisor_or_value(runs, tmp_path):
    run = _copy(runs["sr1"], tmp_path / "run")
    before = (run / "meta.json").read_text()
    cases = [
        (["--method", "ppo-ewri"], ["ppo-sr run", "--method ppo-ewri"]),
        (["--method", "pirl", "--advisor", "oracle"], ["ppo-sr run", "--method pirl"]),
        (["--method", "ppo-sr", "--seed", "5"], ["seed 1", "--seed 5"]),
    ]
    for args, needles in cases:
        proc = _pirl("train", *args, "--out", str(run), "--resume", cwd=tmp_path)
        _one_clean_line(proc, *needles)
    other = tmp_path / "other.yaml"
    data = yaml.safe_load(TEST_CFG.read_text())
    data["ppo"]["learning_rate"] = 0.001
    other.write_text(yaml.safe_dump(data))
    proc = _pirl("train", "--method", "ppo-sr", "--config", str(other), "--out", str(run),
                 "--resume", cwd=tmp_path)  # fmt: skip
    _one_clean_line(proc, "ppo.learning_rate=0.0003", "ppo.learning_rate=0.001")
    assert (run / "meta.json").read_text() == before  # nothing rewritten
    # PIRL: a different advisor is a different run.
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(pare={"advisor": "oracle"})
    pirl = tmp_path / "pirl"
    train("pirl", cfg, pirl, seed=0, show_progress=False)
    with pytest.raises(ConfigError, match="pare.advisor='oracle'.*pare.advisor='local'"):
        train("pirl", cfg.with_overrides(pare={"advisor": "local"}), pirl, resume=True)
    saved = RunConfig.from_yaml(pirl / "config.yaml")  # the resolved config is what is saved
    assert saved.env.reward == "ewri" and saved.env.llm_weight is True


def test_resume_extends_steps_and_a_finished_run_stays_finished(runs, tmp_path):
    run = _copy(runs["sr1"], tmp_path / "run")
    proc = _pirl("train", "--method", "ppo-sr", "--out", str(run), "--resume", cwd=tmp_path)
    assert proc.returncode == 0 and "already complete" in proc.stdout, proc.stdout + proc.stderr
    proc = _pirl("train", "--method", "ppo-sr", "--out", str(run), "--resume", "--steps", "640",
                 cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "extending" in proc.stdout and "640" in proc.stdout
    meta = json.loads((run / "meta.json").read_text())
    assert meta["complete"] and meta["timesteps"] == 640 and meta["total_steps"] == 640
    proc = _pirl("train", "--method", "ppo-sr", "--out", str(run), "--resume", "--steps", "256",
                 cwd=tmp_path)  # fmt: skip
    _one_clean_line(proc, "256")


def test_steps_off_the_rollout_grid_are_said_and_presets_resolve_by_name(tmp_path):
    out = tmp_path / "run"
    proc = _pirl("train", "--method", "ppo-ewri", "--config", "test", "--steps", "200",
                 "--out", str(out), cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "200 steps become 256" in proc.stdout
    assert json.loads((out / "meta.json").read_text())["timesteps"] == 256
    saved = RunConfig.from_yaml(out / "config.yaml")
    assert saved.env.reward == "ewri" and saved.env.llm_weight is False
    lines = [line for line in proc.stdout.splitlines() if line.startswith("[ppo-ewri]")]
    # An interval line and a final one, and never a "0 fps" line.
    assert len(lines) <= 2 and not re.search(r"(?<![\d,])0 fps", " ".join(lines))
    proc = _pirl("train", "--method", "ppo-sr", "--config", "nonesuch", "--out",
                 str(tmp_path / "x"), cwd=tmp_path)  # fmt: skip
    _one_clean_line(proc, "nonesuch", "quick")


def _wait_for(predicate, proc: subprocess.Popen, limit: float = 120) -> None:
    deadline = time.time() + limit
    while time.time() < deadline and proc.poll() is None:
        if predicate():
            return
        time.sleep(0.01)


def _latest_step(folder: Path) -> int:
    try:
        return int((folder / "checkpoints" / "LATEST").read_text().split("_")[1])
    except (OSError, IndexError, ValueError):
        return -1


def test_kill_9_at_several_points_then_resume_matches_a_straight_run(tmp_path):
    steps = "2048"
    cmd = [*PIRL, "train", "--method", "ppo-ewri", "--config", str(TEST_CFG), "--seed", "3",
           "--steps", steps]  # fmt: skip
    out = tmp_path / "killed"
    kill_points = [
        lambda: out.exists(),  # the folder is being made, before any checkpoint
        lambda: _latest_step(out) >= 512,  # mid-run, during a rollout
        lambda: (
            any((out / "checkpoints").glob(".step_*.tmp"))  # a checkpoint being written
            or _latest_step(out) >= 1536
        ),
        lambda: (out / "model.tmp.zip").exists() or (out / "model.zip").exists(),  # final save
    ]
    codes = []
    for n, point in enumerate(kill_points):
        args = [*cmd, "--out", str(out)] + (["--resume"] if n else [])
        proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _wait_for(point, proc)
        proc.send_signal(signal.SIGKILL)
        codes.append(proc.wait(timeout=60))
    assert codes[:3] == [-signal.SIGKILL] * 3, codes  # the final save may win the race
    resumed = subprocess.run([*cmd, "--out", str(out), "--resume"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    straight = tmp_path / "straight"
    subprocess.run([*cmd, "--out", str(straight)], check=True, capture_output=True)
    assert _same_weights(out / "model.zip", straight / "model.zip")
    assert (out / "episodes.csv").read_text() == (straight / "episodes.csv").read_text()
    assert json.loads((out / "meta.json").read_text())["timesteps"] == int(steps)


# -- results never mix ----------------------------------------------------------------------
def _plan(specs, env) -> EvalPlan:
    return EvalPlan(specs=specs, sizes=[(16, 16, 3)], episodes=2, env=env)


def test_runs_with_different_labels_stay_apart_and_seeds_pool(runs, tmp_path):
    env = RunConfig.from_yaml(TEST_CFG).env
    a, b = _copy(runs["sr1"], tmp_path / "a"), _copy(runs["sr2"], tmp_path / "b")
    # Same label, same config, different seeds: one row with both runs' episodes.
    summary = evaluate(_plan([spec_for_run(a), spec_for_run(b)], env), tmp_path / "pooled")
    rows = read_summary(summary)
    assert [(r["label"], r["n"]) for r in rows] == [("PPO-SR", 4.0)]
    # Different labels (as PIRL runs with two advisors or PARE weights get): two rows.
    for run, label in ((a, "PPO-SR (variant a)"), (b, "PPO-SR (variant b)")):
        meta = json.loads((run / "meta.json").read_text())
        (run / "meta.json").write_text(json.dumps({**meta, "label": label}))
    summary = evaluate(_plan([spec_for_run(a), spec_for_run(b)], env), tmp_path / "apart")
    rows = read_summary(summary)
    assert sorted((r["label"], r["n"]) for r in rows) == [
        ("PPO-SR (variant a)", 2.0),
        ("PPO-SR (variant b)", 2.0),
    ]
    assert len({r["method"] for r in rows}) == 2


def test_same_label_different_config_and_duplicates_are_refused(runs, tmp_path):
    a, b = _copy(runs["sr1"], tmp_path / "a"), _copy(runs["sr2"], tmp_path / "b")
    data = yaml.safe_load((b / "config.yaml").read_text())
    data["ppo"]["learning_rate"] = 0.001
    (b / "config.yaml").write_text(yaml.safe_dump(data))
    ev = tmp_path / "eval"
    proc = _pirl("evaluate", "--runs", str(a), "--runs", str(b), "--out", str(ev), cwd=tmp_path)
    _one_clean_line(proc, "ppo.learning_rate", "0.0003", "0.001")
    proc = _pirl("evaluate", "--runs", str(a), "--runs", str(a), "--out", str(ev), cwd=tmp_path)
    _one_clean_line(proc, "twice")
    c = _copy(runs["sr1"], tmp_path / "c")  # a copy of the same run (same seed)
    proc = _pirl("evaluate", "--runs", str(a), "--runs", str(c), "--out", str(ev), cwd=tmp_path)
    _one_clean_line(proc, "copies of one run")
    assert not ev.exists()


def test_policy_cache_sees_a_model_retrained_into_the_same_folder(runs, tmp_path):
    run = _copy(runs["sr1"], tmp_path / "run")
    spec, cfg = spec_for_run(run), RunConfig.from_yaml(TEST_CFG)
    first = runner._policy(spec, cfg)
    assert runner._policy(spec, cfg) is first
    shutil.copy(runs["sr2"] / "model.zip", run / "model.zip")  # "retrained" into the folder
    os.utime(run / "model.zip", ns=(time.time_ns(), time.time_ns() + 10**9))
    second = runner._policy(spec, cfg)
    assert second is not first
    w1, w2 = first.model.policy.state_dict(), second.model.policy.state_dict()
    assert not all(torch.equal(w1[k], w2[k]) for k in w1)


# -- every setting reachable, quiet output --------------------------------------------------
def test_physics_section_round_trips_and_is_validated(tmp_path):
    cfg = RunConfig.from_dict({"physics": {"wind_mean": [0, 2, 0], "cell_size_m": 2.0}})
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg.to_dict()))
    again = RunConfig.from_yaml(path)
    assert again == cfg and again.physics.wind_mean == (0.0, 2.0, 0.0)
    with pytest.raises(ConfigError, match="unknown setting 'wind' in section 'physics'"):
        RunConfig.from_dict({"physics": {"wind": 1}})
    with pytest.raises(ConfigError, match="physics.cell_size_m"):
        RunConfig.from_dict({"physics": {"cell_size_m": 0}})
    with pytest.raises(ConfigError, match="physics.stabilized_gimbal"):
        RunConfig.from_dict({"physics": {"stabilized_gimbal": "yes"}})
    plan = EvalPlan(
        specs=[runner.spec_for_builtin("boustrophedon")],
        sizes=[(16, 16, 3)],
        episodes=1,
        config=replace(cfg, env=cfg.env),
    )
    evaluate(plan, tmp_path / "ev")
    assert json.loads((tmp_path / "ev" / "plan.json").read_text())["physics"]["cell_size_m"] == 2


def test_progress_prints_one_line_per_interval_and_one_final_line(capsys):
    progress = Progress("ppo-sr", 100, every_s=3600, rate_unit="fps")
    for steps in range(4, 200, 4):  # the vector steps of the last rollout run past the total
        progress.update(steps, info="VCR(recent) 0.50")
    progress.close()
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1 and lines[0].startswith("[ppo-sr] 196/100 steps")


def test_progress_of_an_evaluation_says_its_total_when_it_is_reached():
    lines: list[str] = []
    progress = Progress(
        "episodes", line="{label}: {done}/{total} episodes", every_s=3600, tty=False,
        final_at_total=True, out=lines.append,
    )  # fmt: skip
    for done in (1, 2, 3, 3):
        progress(done, 3)
    progress.close()
    assert lines == ["episodes: 3/3 episodes"]


def test_small_cli_outputs(tmp_path):
    from pirl.advice.parser import parse_recommendation
    from pirl.advice.recommendation import FORMAT_EXAMPLE
    from pirl.terminal import copies_format_example as _copies_format_example
    from pirl.terminal import mean_ci as _mean_ci

    assert _mean_ci(0.5, float("nan")) == "0.500"
    assert _mean_ci(0.5, 0.1) == "0.500 ± 0.100"
    example = parse_recommendation(FORMAT_EXAMPLE)
    prompt = f"Reply with one line in exactly this format: {FORMAT_EXAMPLE}"
    assert _copies_format_example(example, prompt)
    assert not _copies_format_example(parse_recommendation(FORMAT_EXAMPLE.replace("75", "30")),
                                      prompt)  # fmt: skip
    proc = _pirl("evaluate", "--help", cwd=tmp_path, env={**os.environ, "COLUMNS": "200"})
    assert "pirl[distributed]" in proc.stdout
    proc = _pirl("evaluate", "--methods", "boustrophedon", "--sizes", "16", "--episodes", "1",
                 "--out", str(tmp_path / "ev"), cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "episodes: 1/1 episodes" in proc.stdout  # progress off a terminal
    assert "nan" not in proc.stdout and "1.000" in proc.stdout
    assert proc.stderr.strip() == ""  # no third-party noise


def test_il_resume_refuses_another_method_or_seed(tmp_path):
    from pirl.agents.imitation import train_il
    from pirl.config.errors import UserError

    cfg = RunConfig.from_yaml(TEST_CFG)
    run = tmp_path / "il"
    run.mkdir()
    (run / "meta.json").write_text(json.dumps({"method": "ppo-sr", "seed": 0}))
    with pytest.raises(UserError, match="is a ppo-sr run"):
        train_il(cfg, tmp_path / "expert", run, seed=0, resume=True)
    (run / "meta.json").write_text(json.dumps({"method": "il", "seed": 0}))
    with pytest.raises(UserError, match="trained with seed 0; this command gives --seed 3"):
        train_il(cfg, tmp_path / "expert", run, seed=3, resume=True)
