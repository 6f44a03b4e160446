"""The teacher phase: a slow teacher answers planner states into the shared dataset while the
PPO baselines train, and its PIRL runs start after it with those answers."""

from __future__ import annotations

import json
from pathlib import Path

from pirl.agents.teacher_phase import phase_of
from pirl.config.run import RunConfig
from pirl.reproduce.pipeline import train_all
from pirl.reproduce.plan import check_reproduce, make_plan, plan_runs, teacher_phases

ROOT = Path(__file__).resolve().parents[1]


def describe_plan(cfg: RunConfig, advisor: str, out: Path) -> list[str]:
    return make_plan(check_reproduce(cfg, advisor, 2), out).describe()


def test_the_plan_shows_one_phase_per_slow_teacher_with_its_minutes(tmp_path):
    quick = RunConfig.from_yaml(ROOT / "configs" / "quick.yaml")
    lines = describe_plan(quick, "local", tmp_path)
    phase = [line for line in lines if "teacher phase" in line]
    assert len(phase) == 1 and "teacher-local-compact" in phase[0] and "min" in phase[0]
    assert "its 2 PIRL runs start after it" in phase[0]
    # The oracle is fast enough during the run: no phase; nor without the setting.
    assert not any("teacher phase" in line for line in describe_plan(quick, "oracle", tmp_path))
    off = quick.with_overrides(reproduce={"teacher_phase_answers": 0})
    assert phase_of(off, {"advisor": "local"}) is None
    # Variants that differ only in PARE's weights share their teacher, so one phase.
    study = RunConfig.from_yaml(ROOT / "configs" / "study-camera.yaml")
    phases = teacher_phases(study, plan_runs(study, "local"))
    assert len({p.name for p in phases.values()}) == 1 and len(phases) == 6


def test_pirl_runs_start_after_their_teacher_phase_with_its_answers(tmp_path):
    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml").with_overrides(
        pare={
            "mode": "student", "advisor": "local", "prompt_variant": "compact",
            "teacher_rate": 0.0, "student_dataset": str(tmp_path / "student.sqlite"),
            "cache_path": str(tmp_path / "advice.sqlite"),
        },
        reproduce={"methods": ["ppo-sr", "pirl"], "pirl_variants": [{}],
                   "teacher_phase_answers": 12},
    )  # fmt: skip
    logs: list[str] = []
    runs = train_all(cfg, tmp_path / "out", "local", logs.append, False, workers=2)
    done = [line for line in logs if line.endswith(" s") and ": done in" in line]
    names = [line.split(":")[0] for line in done]
    assert "teacher-local-compact" in names
    assert names.index("teacher-local-compact") < names.index("pirl-local-s0")
    stats = json.loads((runs[-1] / "advisor_stats.json").read_text())
    # No teacher call during the run (rate 0): every answer the student saw came from the phase.
    assert stats["teacher_calls"] == 0 and stats["student_dataset_size"] >= 12
