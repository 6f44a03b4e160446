"""A reproduction's training jobs: a run to train or resume, or a teacher phase, and the one
function that runs a job wherever an executor (:mod:`pirl.evaluate.executors`) put it."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pirl.agents.teacher_phase import TeacherPhase

TEACHER = "teacher"
"""The method name of a teacher phase among the training jobs (it has no run folder)."""


@dataclass(frozen=True)
class TrainJob:
    """One job of a reproduction's training: a run to train or resume, or a teacher phase."""

    name: str
    """The run folder's name under ``runs/``, or the teacher phase's name."""
    method: str
    """The trained method, or :data:`TEACHER` for a teacher phase."""
    advisor: str
    """An advised run's advisor (empty keeps the config's), or the phase's teacher."""
    seed: int
    """The training seed (0 for a teacher phase)."""
    run: Path | None = None
    """The run folder; None for a teacher phase."""
    state: str = "absent"
    """The run folder when planned: ``absent``, ``resumable`` (it resumes from its last
    checkpoint) or ``broken`` (there, with nothing to resume: it starts again)."""
    pare: tuple[tuple[str, Any], ...] = ()
    """PARE overrides of an advised run, or of the PIRL variant a teacher phase serves."""
    expert: str = ""
    """An imitation run: the job of the expert run it learns from (it waits for that one and
    is not trained when that one fails)."""
    phase: str = ""
    """A PIRL run: the teacher phase it waits for (when that fails, the run still trains,
    without the head start)."""

    @property
    def resume(self) -> bool:
        """Whether the run resumes from its last checkpoint."""
        return self.state == "resumable"

    @property
    def after(self) -> tuple[str, ...]:
        """The jobs that must end before this one starts."""
        return tuple(name for name in (self.expert, self.phase) if name)


def phase_line(phase: TeacherPhase, done: dict[str, Any]) -> str:
    """What a finished teacher phase did (``run_teacher_phase``'s answer), in one line."""
    return (
        f"{phase.name}: {done['teacher']} answered {done['asked']} planner states, "
        f"{done['stored']} stored (the dataset had {done['had']}; wanted {phase.answers}) "
        f"in {done['seconds']:.0f} s"
    )


def train_job(job: TrainJob, cfg_dict: dict[str, Any], show_progress: bool) -> tuple[float, str]:
    """Run one job wherever it landed (this process, a pool worker, a Ray worker): the same
    call each way, so a run trains the same model whichever executor ran it. Returns its
    seconds and, for a teacher phase, the line saying what it did (the caller logs it)."""
    from pirl.agents.runs import train_one
    from pirl.agents.teacher_phase import TeacherPhase, run_teacher_phase
    from pirl.config.run import RunConfig

    start = time.perf_counter()
    cfg = RunConfig.from_dict(cfg_dict)
    if job.method == TEACHER:
        phase = TeacherPhase(job.advisor, job.pare, cfg.reproduce.teacher_phase_answers)
        note = phase_line(phase, run_teacher_phase(cfg, phase))
        return time.perf_counter() - start, note
    if job.run is None:
        raise ValueError(f"training job {job.name} has no run folder")
    train_one(job.method, job.advisor, job.seed, cfg, job.run, job.resume, show_progress,
              dict(job.pare))  # fmt: skip
    return time.perf_counter() - start, ""


__all__ = ["TEACHER", "TrainJob", "phase_line", "train_job"]
