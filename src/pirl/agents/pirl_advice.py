"""What PIRL's reward shaping needs before a run starts: the teacher advisor (probed), the
student and its dataset in student mode, and the label that says what ran.

Everything here happens before a run folder exists, so a wrong key, a dead server or a
student of another teacher stops with one line and leaves nothing behind.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pirl.agents.config import RunConfig
from pirl.world.config import UserError


@dataclass
class PirlAdvice:
    """The advice side of one PIRL run."""

    advisor: Any
    """The teacher (cache and budget in front, as configured)."""
    student: Any | None
    """Student mode: the distilled advisor (from ``--student`` or new)."""
    dataset: Any | None
    """Student mode: the teacher answers, shared across runs and processes."""
    teacher_rate: float
    """Student mode: teacher calls per env-step."""
    teacher_batch: int
    """Student mode: most prompts per teacher request (the backend's own batch size)."""
    label: str
    """e.g. ``PIRL (student of local:SmolLM2-135M-Instruct; lam_cam 1, lam_move 1)``."""


def _num(value: float) -> str:
    return f"{value:g}"


def pirl_label(cfg: RunConfig, advisor_label: str) -> str:
    """The label of a PIRL configuration: advisor and model, mode, K, lam_cam and lam_move."""
    p = cfg.pare
    weights = f"lam_cam {_num(p.lam_cam)}, lam_move {_num(p.lam_move)}"
    if p.mode == "student":
        return f"PIRL (student of {advisor_label}; {weights})"
    return f"PIRL ({p.mode} {advisor_label}, K {p.query_every}; {weights})"


def dataset_path(cfg: RunConfig) -> Path:
    """Where the teacher answers live (``pare.student_dataset`` or beside the answer cache)."""
    from pirl.advice.student import default_dataset_path

    return (
        Path(cfg.pare.student_dataset).expanduser()
        if cfg.pare.student_dataset
        else (default_dataset_path())
    )


def build_pirl_advice(
    cfg: RunConfig,
    advisor: Any | None = None,
    student_path: Path | None = None,
    probe: bool = True,
    seed: int = 0,
) -> PirlAdvice:
    """Build (and probe) the teacher, and in student mode the student and its dataset.

    ``student_path``: a student written by ``pirl distill`` to start from; its teacher must be
    the configured one.
    """
    from pirl.advice.factory import make_advisor
    from pirl.advice.health import probe as probe_call

    env_cfg = cfg.env.replace(reward="ewri", llm_weight=True)
    if advisor is None:
        advisor = make_advisor(cfg.pare.advisor, cfg, process=cfg.advisor.local_process)
    if probe:
        try:
            probe_call(advisor, env_cfg, cfg.pare.prompt_variant)
        except UserError:
            advisor.close()
            raise
    label = pirl_label(cfg, advisor.label)
    rate = cfg.pare.oracle_teacher_rate if advisor.name == "oracle" else cfg.pare.teacher_rate
    batch = {"oracle": 256, "local": cfg.advisor.local_batch_size}.get(
        advisor.name, 4 * cfg.advisor.openai_concurrency
    )
    if cfg.pare.mode != "student":
        return PirlAdvice(advisor, None, None, rate, batch, label)
    student, dataset = make_student(cfg, advisor, env_cfg, student_path, seed)
    return PirlAdvice(advisor, student, dataset, rate, batch, label)


def make_student(
    cfg: RunConfig, advisor: Any, env_cfg: Any, student_path: Path | None, seed: int = 0
) -> tuple[Any, Any]:
    """A new student of ``advisor`` (or the one saved at ``student_path``) and its dataset."""
    from pirl.advice.student import N_EXTRA, Student, TeacherDataset, teacher_key
    from pirl.env.observation import obs_size

    dataset = TeacherDataset(dataset_path(cfg))
    key = teacher_key(advisor, cfg.pare.prompt_variant, env_cfg)
    if student_path is not None:
        path = Path(student_path)
        file = path / "student.pt" if path.is_dir() else path
        if not file.is_file():
            raise UserError(f"--student {path}: no student.pt (make one with pirl distill)")
        try:
            student = Student.load(file, dataset)
        except (ValueError, OSError, RuntimeError, KeyError) as exc:
            raise UserError(f"--student {file} cannot be loaded: {exc}") from None
        if student.teacher != key:
            raise UserError(
                f"--student {path} imitates {student.teacher}, but this run's teacher is {key} "
                "(advisor, model, prompt variant and world settings must match)"
            )
        return student, dataset
    n_features = obs_size(env_cfg.obs_window, env_cfg.obs_global) + N_EXTRA
    student = Student(
        key, n_features, label=advisor.label, hidden=cfg.pare.student_hidden, seed=seed
    )
    return student, dataset


__all__ = ["PirlAdvice", "build_pirl_advice", "dataset_path", "make_student", "pirl_label"]
