"""The advice side of one PIRL run, as PARE consumes it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the student pulls in torch; a run without one never needs it
    from pirl.advice.base import Advisor
    from pirl.advice.student import Student
    from pirl.advice.teacher_dataset import TeacherDataset


@dataclass
class AdviceBundle:
    """What PARE shapes a run's reward from: built by the trainer
    (:func:`pirl.agents.pirl_advice.build_pirl_advice`), read by the advice sources."""

    advisor: Advisor
    """The teacher (cache and budget in front, as configured)."""
    student: Student | None
    """Student mode: the distilled advisor (from ``--student`` or new)."""
    dataset: TeacherDataset | None
    """Student mode: the teacher answers, shared across runs and processes."""
    teacher_rate: float
    """Student mode: teacher calls per env-step."""
    teacher_batch: int
    """Student mode: most prompts per teacher request (the backend's own batch size)."""
    label: str
    """e.g. ``PIRL (student of local:SmolLM2-135M-Instruct; lam_cam 1, lam_move 1)``."""

    def drop_own_answers(self) -> int:
        """Delete the stored answers under this run's own dataset key (a fresh start of a run
        whose answers are its own); returns how many."""
        if self.student is None or self.dataset is None:
            return 0
        return self.dataset.drop(self.student.teacher)


__all__ = ["AdviceBundle"]
