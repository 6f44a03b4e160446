"""The plan of ``pirl reproduce``: made once, printed from the object, run by one job runner.

The runner's order, status lines and failures are shown here with a stand-in for the job (no
training); real runs go through it in test_reproduce (process pool, resume), test_teacher_phase
(a teacher phase) and test_distributed (Ray).
"""

from __future__ import annotations

import contextlib
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from pirl.config.run import RunConfig
from pirl.evaluate.executors import ExecutorChoice
from pirl.reproduce import pipeline as reproduce_module
from pirl.reproduce import plan as plan_module
from pirl.reproduce import schedule as schedule_module
from pirl.reproduce.jobs import TEACHER, TrainJob
from pirl.reproduce.plan import Plan, check_reproduce, make_plan
from pirl.reproduce.schedule import executor_for, run_plan

ROOT = Path(__file__).resolve().parents[1]
TEST = ROOT / "configs" / "test.yaml"
RUNS = ["ppo-sr-s0", "ppo-ewri-s0", "pirl-local-s0", "il-s0"]
PHASE = "teacher-local-compact"


def _with_phase() -> RunConfig:
    """The test preset with a slow (LLM) teacher for PIRL in student mode: a teacher phase."""
    return RunConfig.from_yaml(TEST).with_overrides(
        pare={"mode": "student", "advisor": "local", "prompt_variant": "compact"},
        reproduce={"teacher_phase_answers": 24},
    )


def _plan(out: Path, workers: int | None = None) -> Plan:
    return make_plan(check_reproduce(_with_phase(), "local", workers), out)


def _stand_in(logs: list[str], fail: tuple[str, ...] = ()):
    """A job that logs that it ran (or raises when named in ``fail``) and takes 1 s."""

    def job(job: TrainJob, cfg_dict: dict, show_progress: bool) -> tuple[float, str]:
        logs.append(f"ran {job.name}")
        if job.name in fail:
            raise RuntimeError(f"{job.name} broke")
        return 1.0, (f"{job.name}: answered" if job.method == TEACHER else "")

    return job


def test_the_plan_holds_runs_dependencies_evaluation_and_estimates(tmp_path):
    plan = _plan(tmp_path, workers=2)
    assert [run.name for run in plan.runs] == RUNS
    assert [job.name for job in plan.jobs] == [PHASE, *RUNS]  # the phase first
    after = {job.name: job.after for job in plan.jobs}
    assert after == {PHASE: (), "ppo-sr-s0": (), "ppo-ewri-s0": (),
                     "pirl-local-s0": (PHASE,), "il-s0": ("ppo-ewri-s0",)}  # fmt: skip
    assert [p.name for p in plan.phases] == [PHASE]
    assert [s.source for s in plan.evaluation.builtins] == ["llm-only", "boustrophedon", "random"]
    assert plan.evaluation.sizes == ((16, 16, 3), (20, 12, 3))
    assert [Path(s).name for s in plan.evaluation.sites] == ["campus"]
    assert plan.estimate.train_min > 0 and plan.estimate.phase_min[PHASE] > 0
    assert (plan.train_workers, plan.eval_workers) == (2, 2)
    # Printed from the object: nothing says "training" before a job starts.
    lines = plan.describe() + plan.status_lines()
    assert lines[0].startswith(f"plan: teacher phase {PHASE}")
    assert "its 1 PIRL runs start after it" in lines[0]
    assert [line for line in lines if not line.startswith("plan:")] == [
        f"{PHASE}: queued (teacher phase)",
        *(f"{name}: queued" for name in RUNS),
    ]
    assert not (tmp_path / "runs").exists()  # planning writes nothing


def test_plan_runs_runs_once_per_pirl_reproduce(tmp_path, monkeypatch):
    from pirl import cli

    counted = {"plan_runs": 0, "check_reproduce": 0}
    for name in counted:
        real = getattr(plan_module, name)

        def count(*args, _real=real, _name=name):
            counted[_name] += 1
            return _real(*args)

        monkeypatch.setattr(plan_module, name, count)
        if hasattr(reproduce_module, name):  # the reproduce sequence calls it by its own name
            monkeypatch.setattr(reproduce_module, name, count)
    plans: list[Plan] = []

    def stop_before_training(plan: Plan, **_: object) -> Path:
        plans.append(plan)  # training and evaluation: test_reproduce
        return tmp_path / "report" / "report.html"

    monkeypatch.setattr(reproduce_module, "run_reproduction", stop_before_training)
    cli.reproduce(profile="test", advisor="oracle", seeds=None, workers=None,
                  out=tmp_path / "out", config=TEST, ray_address=None)  # fmt: skip
    assert counted == {"plan_runs": 1, "check_reproduce": 1}
    assert len(plans) == 1 and [j.name for j in plans[0].jobs] == [
        "ppo-sr-s0", "ppo-ewri-s0", "pirl-oracle-s0", "il-s0",
    ]  # fmt: skip


def test_the_runner_starts_each_job_after_what_it_waits_for(tmp_path, monkeypatch):
    plan = _plan(tmp_path)
    logs: list[str] = []
    monkeypatch.setattr(schedule_module, "train_job", _stand_in(logs))
    run_plan(plan, ExecutorChoice("serial"), logs.append)
    assert (tmp_path / "runs").is_dir()
    assert [line[4:] for line in logs if line.startswith("ran ")] == [PHASE, *RUNS]
    for name in RUNS:  # "training" when it starts, "done" when it ends
        at = logs.index(f"ran {name}")
        assert logs[at - 1] == f"{name}: training"
        assert logs[at + 1] == f"{name}: done in 1 s"
    assert logs[:4] == [f"{PHASE}: asking the local teacher", f"ran {PHASE}",
                        f"{PHASE}: answered", f"{PHASE}: done in 1 s"]  # fmt: skip


def test_the_same_runner_keeps_the_order_with_jobs_running_at_once(tmp_path, monkeypatch):
    # A thread pool stands in for the process pool and Ray: the runner only needs futures.
    plan = _plan(tmp_path)
    logs: list[str] = []
    lock = threading.Lock()
    running, most = [0], [0]
    seconds = {PHASE: 0.3, "ppo-sr-s0": 0.05, "ppo-ewri-s0": 0.2}

    def job(job: TrainJob, cfg_dict: dict, show_progress: bool) -> tuple[float, str]:
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        time.sleep(seconds.get(job.name, 0.05))
        with lock:
            running[0] -= 1
        return 1.0, ""

    @contextlib.contextmanager
    def two_threads(choice: ExecutorChoice):
        with ThreadPoolExecutor(2) as pool:
            yield pool, 2

    monkeypatch.setattr(schedule_module, "train_job", job)
    monkeypatch.setattr(schedule_module, "open_executor", two_threads)
    run_plan(plan, ExecutorChoice("processes", 2), logs.append)
    assert most[0] == 2  # two at once, never more than the executor runs
    for name, waits_for in (("pirl-local-s0", PHASE), ("il-s0", "ppo-ewri-s0")):
        assert logs.index(f"{name}: training") > logs.index(f"{waits_for}: done in 1 s")
    assert sorted(line.split(":")[0] for line in logs if "done in" in line) == sorted(
        [PHASE, *RUNS]
    )
    assert logs[0] == "training 4 runs in 2 worker processes (1 torch + 1 numba thread each)"


def test_a_failed_expert_stops_its_student_and_a_failed_phase_does_not(tmp_path, monkeypatch):
    plan = _plan(tmp_path)
    logs: list[str] = []
    monkeypatch.setattr(schedule_module, "train_job", _stand_in(logs, fail=(PHASE, "ppo-ewri-s0")))
    with pytest.raises(RuntimeError, match="ppo-ewri-s0 broke"):  # raised once all have ended
        run_plan(plan, ExecutorChoice("serial"), logs.append)
    assert f"{PHASE}: failed (RuntimeError: {PHASE} broke)" in logs
    assert "pirl-local-s0: done in 1 s" in logs  # without its head start it still trains
    assert "il-s0: not trained (its expert failed)" in logs
    assert "ran il-s0" not in logs and "ppo-sr-s0: done in 1 s" in logs


def test_a_resumable_or_broken_run_says_so_and_a_broken_one_starts_again(tmp_path, monkeypatch):
    broken = tmp_path / "runs" / "ppo-sr-s0"
    broken.mkdir(parents=True)
    (broken / "episodes.csv").write_text("half a run\n")
    plan = _plan(tmp_path)
    assert plan.states["ppo-sr-s0"] == "broken"
    assert "ppo-sr-s0: queued (incomplete with no checkpoint; starts again)" in (
        plan.status_lines()
    )
    assert broken.is_dir()  # removed when its job starts, not by the plan
    logs: list[str] = []
    seen: list[bool] = []
    stand_in = _stand_in(logs)

    def job(job: TrainJob, cfg_dict: dict, show_progress: bool) -> tuple[float, str]:
        seen.append(job.name != "ppo-sr-s0" or not broken.exists())
        return stand_in(job, cfg_dict, show_progress)

    monkeypatch.setattr(schedule_module, "train_job", job)
    run_plan(plan, ExecutorChoice("serial"), logs.append)
    assert all(seen)
    at = logs.index("ppo-sr-s0: incomplete with no checkpoint; starting again")
    assert logs[at + 1] == "ppo-sr-s0: training"


def test_the_executor_follows_the_workers_and_the_ray_address(tmp_path):
    assert executor_for(_plan(tmp_path, workers=1)) == ExecutorChoice("serial")
    assert executor_for(_plan(tmp_path, workers=3)) == ExecutorChoice("processes", 3)
    assert executor_for(_plan(tmp_path, workers=8)) == ExecutorChoice("processes", 5)  # 5 jobs
    assert executor_for(_plan(tmp_path, workers=2), "local") == ExecutorChoice(
        "ray", ray_address="local"
    )


def test_the_plan_counts_a_choosers_budget_in_choices():
    from pirl.reproduce.plan import steps_text

    quick = RunConfig.from_yaml(ROOT / "configs" / "quick.yaml")
    assert steps_text(quick) == (
        "262,144 steps (PPO-EWRI 409,600, PIRL 409,600, PPO-views 262,144 choices)"
    )
    views = quick.with_overrides(reproduce={"methods": ["ppo-sr", "ppo-views"]},
                                 train={"steps_by_method": {"ppo-views": 1024}})  # fmt: skip
    assert steps_text(views) == "262,144 steps (PPO-views 1,024 choices)"
