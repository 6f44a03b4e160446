"""PARE's three modes (student, sync, async), budgets, advisor health and exact resume."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.budget import Budget, BudgetedAdvisor
from pirl.advice.oracle import OracleAdvisor
from pirl.advice.recommendation import Recommendation
from pirl.advice.student import (
    N_EXTRA,
    Student,
    TeacherDataset,
    decode,
    encode,
    student_features,
    teacher_key,
)
from pirl.agents.loading import load_model
from pirl.agents.pirl_advice import build_pirl_advice, pirl_label
from pirl.agents.stops import TrainingStopped
from pirl.agents.train import train
from pirl.config.errors import UserError
from pirl.config.run import RunConfig
from pirl.env import make_vec_env
from pirl.env.observation import obs_size
from pirl.pare.stats import AdvisorFailing
from test_pare_wrapper import SlowOracle, make_pare  # the oracle with an LLM's latency

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"
SETTINGS = {"size": (12, 10, 3), "reward": "ewri", "llm_weight": True, "wind_prob": 0.0}


class Compass(Advisor):
    """A synthetic teacher that reads the map: head for the world's centre, look straight
    down when low and forward when high. Its answers are a function of what the student sees
    (position and size), so a student can learn them."""

    name, model, label = "compass", "rule-v1", "compass (synthetic)"
    wants_view = True

    def settings_key(self) -> str:
        return "compass-v1"

    def advise(self, prompts, views=None):
        if views is None:
            return [error_answer("compass needs views") for _ in prompts]
        out = []
        for view in views:
            x, y, z = view.position
            sx, sy, _ = view.cfg.size
            rec = Recommendation(
                pan=0.0,
                tilt=90.0 if z == 0 else 45.0,
                zoom=1.0,
                dx=int(np.sign(sx // 2 - x)),
                dy=int(np.sign(sy // 2 - y)),
                dz=0,
            )
            out.append(Answer(rec.to_text(), rec))
        return out


class Flaky(OracleAdvisor):
    """The oracle for its first ``good`` calls, then a server that refuses every call."""

    name, model, label = "flaky", "oracle-then-down", "flaky (oracle, then down)"

    def __init__(self, good: int) -> None:
        self.good = good

    def advise(self, prompts, views=None):
        self.good -= 1
        if self.good >= 0:
            return super().advise(prompts, views)
        return [error_answer("APIConnectionError: Connection refused") for _ in prompts]


def _features(venv, obs):
    return student_features(obs, venv.world, range(venv.num_envs))


def _student(venv, teacher, dataset_path):
    dataset = TeacherDataset(dataset_path)
    key = teacher_key(teacher, "paper", venv.cfg)
    n = obs_size(venv.cfg.obs_window, venv.cfg.obs_global) + N_EXTRA
    return Student(key, n, label=teacher.label), dataset


def test_encode_decode_snap_to_the_camera_grid():
    recs = [Recommendation(pan=-88, tilt=47.4, zoom=1.04, dx=1, dy=0, dz=-1)]
    assert decode(encode(recs)).tolist() == [[-90.0, 45.0, 1.0, 1.0, 0.0, -1.0]]


def test_student_learns_a_synthetic_teacher_above_chance(tmp_path):
    venv = make_vec_env(16, seed=3, **SETTINGS)
    teacher = Compass()
    student, dataset = _student(venv, teacher, tmp_path / "ds.sqlite")
    obs = venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(60):
        from pirl.advice.state import advice_requests

        prompts, views = advice_requests(venv.world, range(16), teacher)
        answers = teacher.advise(prompts, views)
        dataset.add(
            student.teacher, _features(venv, obs), encode([a.recommendation for a in answers])
        )
        obs, _, _, _ = venv.step(rng.integers(0, 12, 16))
    assert student.pull(dataset) == 960
    before = student.evaluate().agreement
    score = student.fit(600)
    assert 120 < score.heldout < 280  # about one answer in five
    assert score.agreement > max(before, score.majority) + 0.1
    assert score.agreement > 0.9
    assert score.per_field["dx"] > 0.8 and score.per_field["dy"] > 0.8


def test_dataset_is_shared_across_processes(tmp_path):
    path = tmp_path / "ds.sqlite"
    code = (
        "import numpy as np, sys; from pirl.advice.student import TeacherDataset; "
        f"TeacherDataset({str(path)!r}).add('t', np.ones((5, 3), np.float32), "
        "np.zeros((5, 6), np.int64))"
    )
    for _ in range(2):
        subprocess.run([sys.executable, "-c", code], check=True)
    ids, x, y = TeacherDataset(path).load("t")
    assert len(ids) == 10 and x.shape == (10, 3) and y.shape == (10, 6)
    assert TeacherDataset(path).load("t", after=int(ids[4]))[0].tolist() == ids[5:].tolist()


def _student_pare(tmp_path, teacher, n=4, **kw):
    venv = make_vec_env(n, seed=1, **SETTINGS)
    student, dataset = _student(venv, teacher, tmp_path / "ds.sqlite")
    args = dict(teacher_rate=0.5, gate=0.0, refit_every=8, fit_steps=50, wait_teacher=True)
    args.update(kw)
    return make_pare(venv, teacher, mode="student", student=student, dataset=dataset, **args)


def test_student_mode_shapes_every_step_with_advice_about_the_current_state(tmp_path):
    pare = _student_pare(tmp_path, OracleAdvisor())
    pare.reset()
    rng = np.random.default_rng(0)
    statuses = []
    for _ in range(120):
        _, _, _, infos = pare.step(rng.integers(0, 12, pare.num_envs))
        statuses += [(i["pare"]["status"], i["pare"]["staleness"]) for i in infos]
    stats = pare.stats.as_dict()
    assert stats["gate_passed_at_step"] > 0  # unshaped before the student had enough answers
    after = statuses[stats["gate_passed_at_step"] + 4 * 8 :]
    assert after and all(s == ("student", 0) for s in after)
    assert stats["mean_staleness"] == 0.0
    assert stats["steps_student"] + stats["steps_unshaped"] == stats["steps"] == 480
    assert stats["steps_teacher"] == 0
    assert 0 < stats["teacher_calls_per_step"] <= 0.5
    assert stats["student_dataset_size"] > 100 and stats["student_agreement"] > 0
    pare.close()


@pytest.mark.parametrize("growth", [0.0, 0.5])
def test_refits_become_rarer_once_the_student_has_passed_its_gate(tmp_path, growth):
    pare = _student_pare(tmp_path, OracleAdvisor(), refit_growth=growth)
    pare.reset()
    rng = np.random.default_rng(0)
    for _ in range(160):  # 20 boundaries, new answers at each
        pare.step(rng.integers(0, 12, pare.num_envs))
    st = pare.stats.as_dict()
    assert st["gate_passed_at_step"] > 0
    assert st["student_refits"] + st["student_refits_deferred"] >= 18
    if growth == 0:
        assert st["student_refits_deferred"] == 0
    else:  # each refit waits for 50% more answers: a handful of refits, not one per rollout
        assert st["student_refits"] <= 10 and st["student_refits_deferred"] >= 8
    assert st["refit_s"] > 0 and st["student_s"] > 0 and st["teacher_s"] > 0
    pare.close()


def test_a_closed_gate_asks_the_teacher_more_often_until_it_opens(tmp_path):
    sent = {}
    for closed_rate in (1.0, 4.0):  # too few answers for the gate to open in 40 steps
        pare = _student_pare(tmp_path / str(closed_rate), OracleAdvisor(), teacher_rate=0.02,
                             closed_rate=closed_rate)  # fmt: skip
        pare.reset()
        for _ in range(40):
            pare.step(np.zeros(pare.num_envs, dtype=np.int64))
        st = pare.stats.as_dict()
        assert st["gate_passed_at_step"] < 0
        sent[closed_rate] = st["prompts_sent"] + st["answers_in_flight"] + st["teacher_waiting"]
        pare.close()
    assert sent[4.0] == pytest.approx(4 * sent[1.0], abs=2) and sent[1.0] >= 3
    # Once the gate opens, the teacher is back to its own rate.
    pare = _student_pare(tmp_path / "opens", OracleAdvisor(), closed_rate=4.0)
    source = pare.pare.source
    assert source.teacher.rate == pytest.approx(2.0)
    pare.reset()
    rng = np.random.default_rng(0)
    for _ in range(160):
        pare.step(rng.integers(0, 12, pare.num_envs))
    assert pare.stats.as_dict()["gate_passed_at_step"] > 0 and source.open
    assert source.teacher.rate == pytest.approx(0.5)
    pare.close()


def test_student_gate_keeps_steps_unshaped_until_agreement(tmp_path):
    # Too few held-out answers (a teacher call every ~100 steps) for any gate to pass.
    pare = _student_pare(tmp_path, OracleAdvisor(), gate=1.0, teacher_rate=0.01)
    pare.reset()
    for _ in range(40):
        _, rewards, _, infos = pare.step(np.zeros(pare.num_envs, dtype=np.int64))
        assert all(i["pare"]["status"] == "missing" and i["pare"]["f_llm"] == 0 for i in infos)
    assert pare.stats.as_dict()["steps_unshaped"] == 160
    pare.close()


def test_async_drops_answers_about_ended_episodes():
    settings = dict(SETTINGS, max_steps=4, scale_by_alpha=False)
    pare = make_pare(make_vec_env(2, seed=7, **settings), SlowOracle(0.15), mode="async")
    pare.reset()
    rng = np.random.default_rng(0)
    for _ in range(40):
        time.sleep(0.02)
        _, _, _, infos = pare.step(rng.integers(0, 12, 2))
        for info in infos:
            # Whatever shapes a step was asked in this episode: never more than 3 steps ago.
            assert info["pare"]["staleness"] < 4
    assert pare.stats.answers_dropped_ended > 0
    pare.close()


@pytest.mark.parametrize("mode", ["sync", "async", "student"])
def test_budget_exhaustion_stops_teacher_shaping_at_once(tmp_path, mode):
    calls = 150 if mode == "student" else 24  # the student needs enough answers to pass
    budget = Budget(max_calls=calls)
    teacher = BudgetedAdvisor(OracleAdvisor(), budget)
    if mode == "student":
        pare = _student_pare(tmp_path, teacher, teacher_rate=1.0, refit_every=4)
    else:
        pare = make_pare(make_vec_env(4, seed=1, **SETTINGS), teacher, mode=mode)
    pare.reset()
    rng = np.random.default_rng(1)
    shaped_after = []
    # Async answers arrive when the advisor thread gets the CPU: on a loaded machine that can
    # take more steps, so step until 20 steps after the budget ran out (or give up).
    for _ in range(2000):
        time.sleep(0.002 if mode == "async" else 0)
        _, _, _, infos = pare.step(rng.integers(0, 12, 4))
        if pare.stats.budget_exhausted:
            shaped_after += [i["pare"]["status"] for i in infos]
        if len(shaped_after) >= 80:
            break
    stats = pare.stats.as_dict()
    assert stats["budget_exhausted"] and stats["budget_exhausted_at_step"] > 0
    assert budget.calls == calls
    if mode == "student":
        assert shaped_after and set(shaped_after) == {"student"}  # the student goes on alone
    else:
        assert shaped_after and set(shaped_after) == {"missing"}
    pare.close()


def test_failure_rate_stops_training_with_a_checkpoint(tmp_path):
    pare = make_pare(
        make_vec_env(4, seed=1, **SETTINGS), Flaky(good=3), mode="sync", failure_window=40,
        max_failure_rate=0.5,
    )  # fmt: skip
    pare.reset()
    with pytest.raises(AdvisorFailing, match="Connection refused"):
        for _ in range(100):
            pare.step(np.zeros(4, dtype=np.int64))
    pare.close()

    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(
        pare={"mode": "sync", "query_every": 1, "failure_window": 60},
        train={"total_steps": 2048, "checkpoint_every": 128},
    )
    out = tmp_path / "run"
    with pytest.raises(TrainingStopped) as stop:
        train("pirl", cfg, out, advisor=Flaky(good=50), show_progress=False)
    assert "failed" in stop.value.reason and stop.value.checkpoint is not None
    stats = json.loads((out / "advisor_stats.json").read_text())
    assert stats["failure_rate"] > 0.5 and stats["answers_failed"] > 0
    assert not json.loads((out / "meta.json").read_text())["complete"]


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_probe_fails_fast_against_a_closed_port_and_makes_no_folder(tmp_path):
    port = _closed_port()
    cfg_path = tmp_path / "cfg.yaml"
    data = RunConfig.from_yaml(TEST_CFG).to_dict()
    data["advisor"].update(
        openai_base_url=f"http://127.0.0.1:{port}/v1", openai_max_retries=0, openai_timeout_s=5
    )
    data["pare"].update(advisor="openai", cache=False)
    import yaml

    cfg_path.write_text(yaml.safe_dump(data))
    out = tmp_path / "run"
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "pirl", "train", "--method", "pirl", "--config", str(cfg_path),
         "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert time.perf_counter() - start < 60
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert "Traceback" not in proc.stderr
    text = " ".join(lines)
    assert "probe" in text and f"127.0.0.1:{port}" in text
    assert not out.exists()


def test_labels_say_what_ran():
    cfg = RunConfig.from_yaml(TEST_CFG)
    student = cfg.with_overrides(pare={"mode": "student", "lam_cam": 4})
    assert pirl_label(student, "local:SmolLM2") == (
        "PIRL (student of local:SmolLM2; lam_cam 4, lam_move 1)"
    )
    assert pirl_label(cfg, "oracle (not an LLM)") == (
        "PIRL (sync oracle (not an LLM), K 4; lam_cam 1, lam_move 1)"
    )


def test_build_pirl_advice_refuses_a_student_of_another_teacher(tmp_path):
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(
        pare={"mode": "student", "advisor": "oracle", "student_dataset": str(tmp_path / "d")}
    )
    advice = build_pirl_advice(cfg)
    advice.student.teacher = "someone:else:0000"
    advice.student.save(tmp_path / "student.npz")
    with pytest.raises(UserError, match="imitates someone:else"):
        build_pirl_advice(cfg, student_path=tmp_path)


def _weights(path: Path) -> dict:
    return load_model(path, device="cpu").policy.state_dict()


@pytest.mark.parametrize("mode", ["student", "sync"])
def test_resume_is_exact(tmp_path, mode):
    def cfg_for(name: str, steps: int) -> RunConfig:
        return RunConfig.from_yaml(TEST_CFG).with_overrides(
            pare={
                "advisor": "oracle", "mode": mode, "oracle_teacher_rate": 0.25,
                "student_gate": 0.0, "student_wait_teacher": True, "student_fit_steps": 20,
                "student_dataset": str(tmp_path / f"{name}.sqlite"),
            },
            train={"total_steps": steps, "checkpoint_every": 128},
        )  # fmt: skip

    straight = train("pirl", cfg_for("a", 1024), tmp_path / "a", seed=5, show_progress=False)
    first = tmp_path / "b"
    train("pirl", cfg_for("b", 512), first, seed=5, show_progress=False)
    resumed = train("pirl", cfg_for("b", 1024), first, seed=5, resume=True, show_progress=False)
    a, b = _weights(straight), _weights(resumed)
    assert all(torch.equal(a[k], b[k]) for k in a)
    sa = json.loads((tmp_path / "a" / "advisor_stats.json").read_text())
    sb = json.loads((first / "advisor_stats.json").read_text())
    for key in ("steps", "steps_student", "steps_fresh", "steps_unshaped", "teacher_calls"):
        assert sa[key] == sb[key], key


def test_distill_then_train_from_the_student(tmp_path):
    env = {**__import__("os").environ, "PIRL_CACHE_DIR": str(tmp_path / "cache")}
    student = tmp_path / "students" / "oracle"
    cmd = [sys.executable, "-m", "pirl"]
    made = subprocess.run(
        [*cmd, "distill", "--teacher", "oracle", "--states", "150", "--config", "test",
         "--fit-steps", "200", "--out", str(student)],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    record = json.loads((student / "student.json").read_text())
    assert record["states_asked"] == 150 and record["dataset_size"] == 150
    assert record["label"] == "student of oracle (not an LLM)"
    assert 0 < record["majority"] <= 1 and record["agreement"] > 0
    again = subprocess.run(
        [*cmd, "distill", "--teacher", "oracle", "--states", "10", "--config", "test", "--out",
         str(student)],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert again.returncode == 2 and "already exists" in again.stderr

    cfg = tmp_path / "student.yaml"
    data = RunConfig.from_yaml(TEST_CFG).to_dict()
    data["pare"].update(advisor="oracle", mode="student", student_gate=0.0)
    import yaml

    cfg.write_text(yaml.safe_dump(data))
    out = tmp_path / "run"
    trained = subprocess.run(
        [*cmd, "train", "--method", "pirl", "--config", str(cfg), "--student", str(student),
         "--out", str(out)],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert trained.returncode == 0, trained.stderr
    stats = json.loads((out / "advisor_stats.json").read_text())
    # A student with enough held-out answers shapes from the first step.
    assert stats["steps_unshaped"] == 0 and stats["steps_student"] == stats["steps"]
    assert json.loads((out / "meta.json").read_text())["student_from"] == str(student)


def test_run_scope_keeps_each_runs_answers_its_own(tmp_path):
    import shutil

    from pirl.advice.student import TeacherDataset

    data = tmp_path / "d.sqlite"
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(
        pare={"advisor": "oracle", "mode": "student", "oracle_teacher_rate": 0.25,
              "student_dataset": str(data), "student_dataset_scope": "run",
              "student_wait_teacher": True},
        train={"total_steps": 256},
    )  # fmt: skip

    def per_key() -> list[int]:
        conn = TeacherDataset(data)._connection()
        rows = conn.execute("SELECT teacher, COUNT(*) FROM samples GROUP BY teacher").fetchall()
        return sorted(n for _, n in rows)

    train("pirl", cfg, tmp_path / "a", seed=0, show_progress=False)
    train("pirl", cfg, tmp_path / "b", seed=0, show_progress=False)
    first = per_key()
    assert len(first) == 2 and first[0] == first[1] > 0  # b never saw a's answers
    shutil.rmtree(tmp_path / "a")  # a fresh run in a's folder drops a's stale answers
    train("pirl", cfg, tmp_path / "a", seed=0, show_progress=False)
    assert per_key() == first
