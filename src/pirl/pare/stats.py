"""PARE's counters and the teacher's health: answers counted, a rolling failure rate that
stops training (resumable) when an advisor keeps failing, and the budget watch."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pirl.advice.base import NO_ANSWER, Advisor, Answer
from pirl.advice.budget import BUDGET_EXHAUSTED
from pirl.advice.factory import exhausted

SILENT_BATCHES = 3
"""Teacher batches in a row without a single answer by their deadline that stop training."""


class AdvisorFailing(RuntimeError):
    """Too many recent teacher answers failed; training stops (resumable)."""


@dataclass
class PareStats:
    """Counters of one PARE run (all cumulative). :meth:`as_dict` adds the derived figures."""

    label: str = ""
    mode: str = ""
    steps: int = 0
    steps_fresh: int = 0
    steps_cached: int = 0
    steps_stale: int = 0
    steps_student: int = 0
    steps_missing: int = 0
    staleness_sum: int = 0
    prompts_sent: int = 0
    batches_sent: int = 0
    answers_ok: int = 0
    answers_failed: int = 0
    answers_unparseable: int = 0
    answers_late: int = 0
    answers_cached: int = 0
    answers_dropped_ended: int = 0
    answers_in_flight: int = 0
    teacher_waiting: int = 0
    teacher_skipped: int = 0
    student_agreement: float = 0.0
    student_majority: float = 0.0
    student_heldout: int = 0
    student_per_field: dict[str, float] = field(default_factory=dict)
    student_kappa: float = 0.0
    """Student mode: Cohen's kappa against the teacher over the fields it varies."""
    student_informative: list[str] = field(default_factory=list)
    """Student mode: the fields the teacher varies (none: it carries no state information)."""
    student_dataset_size: int = 0
    student_refits: int = 0
    student_refits_deferred: int = 0
    gate_passed_at_step: int = -1
    gate_closings: int = 0
    """Student mode: times an open gate closed again (its measure fell below
    pare.student_gate_close of the threshold)."""
    budget_exhausted: bool = False
    budget_exhausted_at_step: int = -1
    failure_rate: float = 0.0
    wait_s: float = 0.0
    student_s: float = 0.0
    """Student mode, seconds in the training loop: features and the student's advice."""
    teacher_s: float = 0.0
    """Student mode: sampling states for the teacher, storing its answers, sending batches."""
    refit_s: float = 0.0
    """Student mode: pulling new answers and refitting the student."""

    def as_dict(self) -> dict[str, Any]:
        out = dict(self.__dict__)
        teacher = self.steps_fresh + self.steps_cached + self.steps_stale
        shaped = teacher + self.steps_student
        out["steps_teacher"] = teacher
        out["steps_unshaped"] = self.steps_missing
        out["teacher_calls"] = self.prompts_sent
        out["teacher_calls_per_step"] = self.prompts_sent / self.steps if self.steps else 0.0
        out["mean_staleness"] = self.staleness_sum / shaped if shaped else 0.0
        answered = self.answers_ok + self.answers_unparseable
        out["parse_rate"] = self.answers_ok / answered if answered else 0.0
        return out

    def count_steps(self, counts: np.ndarray) -> None:
        """Set the step counters from cumulative ``counts`` (one per status, then the
        staleness sum) of steps that held advice or could have."""
        self.steps_missing, self.steps_fresh, self.steps_cached = (
            int(counts[0]), int(counts[1]), int(counts[2])
        )  # fmt: skip
        self.steps_stale, self.steps_student = int(counts[3]), int(counts[4])
        self.staleness_sum = int(counts[5])


@dataclass(frozen=True)
class RunStats:
    """How a finished PIRL run's steps were shaped, read from its recorded statistics (the
    :meth:`PareStats.as_dict` a run writes to ``advisor_stats.json``). Runs recorded before
    ``steps_unshaped`` was written call it ``steps_missing``."""

    steps: int
    unshaped: int
    teacher: int
    student: int

    @classmethod
    def of(cls, record: dict[str, Any]) -> RunStats:
        teacher = record.get("steps_teacher")
        if teacher is None:
            teacher = record.get("steps_fresh", 0) + record.get("steps_stale", 0)
        return cls(
            steps=int(record.get("steps") or 0),
            unshaped=int(record.get("steps_unshaped", record.get("steps_missing", 0))),
            teacher=int(teacher),
            student=int(record.get("steps_student", 0)),
        )

    def share(self, count: int) -> float:
        """``count`` steps as a share of the run's (0 for a run of no steps)."""
        return count / self.steps if self.steps > 0 else 0.0

    @property
    def shaped_share(self) -> float:
        """Share of steps shaped by advice (student or teacher); 0 for a run of no steps."""
        return max(0.0, 1.0 - self.share(self.unshaped)) if self.steps > 0 else 0.0


class Health:
    """Counts the teacher's answers into ``stats`` and stops training when it keeps failing.

    Arguments:
        advisor: the teacher.
        stats: where answers are counted.
        max_failure_rate, failure_window: stop when more than this share of the last
            ``failure_window`` answers failed or did not parse (0 disables).
    """

    def __init__(
        self, advisor: Advisor, stats: PareStats, max_failure_rate: float, failure_window: int
    ) -> None:
        self.advisor, self.stats = advisor, stats
        self.max_failure_rate, self.failure_window = float(max_failure_rate), int(failure_window)
        self.failures: deque[bool] = deque(maxlen=max(1, self.failure_window))
        self.silent = 0  # teacher batches in a row that got no answer at all by the deadline

    def account(self, answers: list[Answer]) -> None:
        """Count teacher answers and watch the rolling failure rate."""
        st = self.stats
        for answer in answers:
            if answer.error == BUDGET_EXHAUSTED:
                continue
            if answer.error is not None:
                st.answers_failed += 1
            elif answer.recommendation is None:
                st.answers_unparseable += 1
            else:
                st.answers_ok += 1
                st.answers_cached += int(answer.from_cache)
            self.failures.append(not answer.ok)
        if self.failures:
            st.failure_rate = float(np.mean(self.failures))
        self._watch_silence(answers)
        evidence = min(self.failure_window, 50)
        if (
            self.max_failure_rate > 0
            and len(self.failures) >= evidence
            and st.failure_rate > self.max_failure_rate
        ):
            last = next((a.error for a in reversed(answers) if a.error), "answers did not parse")
            raise AdvisorFailing(
                f"advisor {self.advisor.label}: {st.failure_rate:.0%} of the last "
                f"{len(self.failures)} answers failed (pare.max_failure_rate "
                f"{self.max_failure_rate:g}); last error: {last}"
            )

    def _watch_silence(self, answers: list[Answer]) -> None:
        """A teacher that accepts requests but answers none of them: whole batches that end at
        the deadline. After SILENT_BATCHES such batches in a row training stops (resumable) at
        once, without waiting for a window of answers that would take many deadlines."""
        if not answers or self.max_failure_rate <= 0:
            return
        if all((a.error or "").startswith(NO_ANSWER) for a in answers):
            self.silent += 1
        else:
            self.silent = 0
        if self.silent >= SILENT_BATCHES:
            raise AdvisorFailing(
                f"advisor {self.advisor.label} answered none of its last {self.silent} "
                f"batches by their deadline; last error: {answers[-1].error}"
            )

    def budget_spent_now(self) -> bool:
        """Whether the teacher's budget was found spent just now (the first time only)."""
        if self.stats.budget_exhausted or not exhausted(self.advisor):
            return False
        self.stats.budget_exhausted = True
        self.stats.budget_exhausted_at_step = self.stats.steps
        return True

    def restart(self) -> None:
        """A resumed run starts a fresh failure window: it was stopped by failures the user
        has since fixed, and old failures must not stop it again before the advisor is
        heard."""
        self.failures.clear()


__all__ = ["SILENT_BATCHES", "AdvisorFailing", "Health", "PareStats"]
