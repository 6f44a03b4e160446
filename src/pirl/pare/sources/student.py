"""The student source (the default for slow or paid advisors).

A distilled advisor (:class:`~pirl.advice.student.Student`) answers for the current state of
every world at every step (staleness 0). The teacher is asked in the background about sampled
states at ``teacher_rate`` calls per env-step (:class:`~pirl.pare.teacher.TeacherQueue`); its
answers train the student, refit at rollout boundaries. Until the student's agreement with
held-out teacher answers reaches ``gate``, steps are left unshaped and counted. When the
teacher's budget is spent, the student goes on alone.
"""

from __future__ import annotations

import contextlib
import time
from typing import Any

import numpy as np

from pirl.advice.student import Student, pose_features
from pirl.advice.teacher_dataset import TeacherDataset
from pirl.config.choices import PareMode
from pirl.config.errors import ConfigError
from pirl.env.shaping import ShapingHooks
from pirl.pare.board import AdviceBoard
from pirl.pare.core import HAS, KIND, KIND_STUDENT, STEP
from pirl.pare.sources.base import SourceSetup
from pirl.pare.stats import AdvisorFailing, Health
from pirl.pare.teacher import TeacherQueue


class StudentSource:
    """The student's advice about every world now; the teacher's answers refit it.

    Arguments:
        board, health: the shared advice board and the teacher's health.
        student: the distilled advisor (fitted or not).
        dataset: where teacher answers are stored and read.
        teacher: the queue that asks the teacher about sampled states.
        gate: what the student needs before it shapes: ``(threshold, "kappa")`` or
            ``(threshold, "agreement")`` (a bare number is an agreement threshold).
        refit_every: vector steps between refits (PPO's ``n_steps``).
        fit_steps: Adam steps per refit.
        refit_growth: once the student has passed its gate, refit only when the answers
            have grown by this share since the last fit (0: at every boundary with new
            answers).
        closed_rate: the teacher's rate is this multiple of its own while the gate is
            closed (``pare.student_closed_rate``).
        wait_teacher: collect the teacher's batch at each boundary (reproducible runs; PPO
            then waits for a slow teacher).
        timeout_s: the longest such wait.
    """

    mode = PareMode.STUDENT

    def __init__(
        self,
        board: AdviceBoard,
        health: Health,
        student: Student,
        dataset: TeacherDataset,
        teacher: TeacherQueue,
        gate: float | tuple[float, str] = 0.8,
        gate_close: float | None = None,
        refit_every: int = 256,
        fit_steps: int = 100,
        refit_growth: float = 0.0,
        wait_teacher: bool = False,
        timeout_s: float = 120.0,
        closed_rate: float = 1.0,
    ) -> None:
        self.board, self.health, self.stats = board, health, health.stats
        self.student, self.dataset, self.teacher = student, dataset, teacher
        # (threshold, what it applies to): see PareSettings.student_gate_on.
        self.gate = gate if isinstance(gate, tuple) else (float(gate), "agreement")
        # Hysteresis: once open, the gate closes only below gate_close (PareSettings).
        self.gate_close = self.gate[0] if gate_close is None else float(gate_close)
        self.open = student.passes(*self.gate)
        self.refit_every = int(refit_every)
        self.fit_steps, self.refit_growth = int(fit_steps), float(refit_growth)
        self.wait_teacher, self.timeout_s = bool(wait_teacher), float(timeout_s)
        self.rate, self.closed_rate = teacher.rate, float(closed_rate)
        self._set_rate()
        self._update_student_stats()

    def _set_rate(self) -> None:
        """The teacher's rate for the gate's state: more answers while the student is short."""
        self.teacher.rate = self.rate * (1.0 if self.open else self.closed_rate)

    @classmethod
    def build(cls, setup: SourceSetup) -> StudentSource:
        p, advice = setup.settings, setup.advice
        if advice.student is None or advice.dataset is None:
            raise ConfigError("student mode needs a student and its teacher dataset")
        rate = advice.teacher_rate
        most = rate * p.student_closed_rate  # the rate while the gate is closed
        teacher = TeacherQueue(
            setup.advisor, advice.dataset, advice.student.teacher, rate,
            max_pending=max(64, int(2 * most * setup.board.n * setup.refit_every) + 1),
            batch_size=advice.teacher_batch, prompt_variant=p.prompt_variant,
            seed=setup.seed, source=setup.source,
        )  # fmt: skip
        return cls(
            setup.board, setup.health, advice.student, advice.dataset, teacher, p.gate(),
            p.gate_close(), setup.refit_every, p.student_fit_steps, p.student_refit_growth,
            p.student_wait_teacher, p.timeout_s, p.student_closed_rate,
        )  # fmt: skip

    # -- AdviceSource ---------------------------------------------------------------------
    def reset(self) -> None:
        return None  # the student answers about any state; the teacher's samples stay valid

    def collect(self) -> None:
        return None  # the student answered when the state began

    def end(self, worlds: np.ndarray) -> None:
        return None

    def tick(self) -> None:
        if self.board.t % self.refit_every == 0:
            self._boundary()

    def request(self, env: ShapingHooks, obs: np.ndarray, live: np.ndarray | None) -> None:
        """The student's advice about the live worlds' current states; the teacher samples
        some of them."""
        board = self.board
        start = time.perf_counter()
        positions = env.poses()[:, :3]
        if live is None:
            rows: Any = slice(None)
            features = pose_features(obs, env.cfg.size, positions)
            worlds = None
        else:
            rows = worlds = np.flatnonzero(live)
            features = pose_features(obs[rows], env.cfg.size, positions[rows])
        sampled = time.perf_counter()
        self.teacher.sample(env, features, worlds)
        asked = time.perf_counter()
        if self.open:
            board.rec[rows] = self.student.predict(features)
            board.meta[rows, HAS] = 1
            board.meta[rows, STEP] = board.t
            board.meta[rows, KIND] = KIND_STUDENT
        else:
            board.meta[:, HAS] = 0
        self.stats.teacher_s += asked - sampled
        self.stats.student_s += (sampled - start) + (time.perf_counter() - asked)

    def settle(self) -> None:
        st, teacher = self.stats, self.teacher
        with contextlib.suppress(AdvisorFailing):  # the run is over: count, do not stop
            self.health.account(teacher.collect_finished(self.board.t))
        st.answers_in_flight = teacher.in_flight
        st.teacher_waiting = teacher.waiting
        st.prompts_sent = teacher.sent

    def state_dict(self) -> dict[str, Any]:
        """The student, whether its gate is open, the teacher's queue and its batch in flight
        (asked again on resume)."""
        return {
            "student": self.student.state_dict(),
            "teacher": self.teacher.state_dict(),
            "gate_open": self.open,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        # What this run stored after the checkpoint is stored again as it replays.
        self.dataset.forget(self.teacher.source, after=self.board.t)
        self.student.load_state_dict(state["student"], self.dataset)
        self.teacher.load_state_dict(state["teacher"])
        self.open = bool(state.get("gate_open", self.student.passes(*self.gate)))
        self._set_rate()

    def close(self) -> None:
        self.teacher.close()

    # -- rollout boundaries ---------------------------------------------------------------
    def _boundary(self) -> None:
        """Store the teacher's answers, refit the student."""
        st, board = self.stats, self.board
        start = time.perf_counter()
        answers = self.teacher.boundary(board.t, wait=self.wait_teacher, timeout_s=self.timeout_s)
        st.teacher_s += time.perf_counter() - start
        self.health.account(answers)
        st.prompts_sent = self.teacher.sent
        st.teacher_skipped = self.teacher.skipped
        start = time.perf_counter()
        student = self.student
        student.pull(self.dataset)
        new = student.dataset_size - student.fitted_rows
        # Refit at every boundary with new answers until the gate passes; after that only
        # once the data has grown by refit_growth since the last fit: as the student
        # converges, refits (the largest cost PIRL adds to PPO) become rarer.
        # Until the gate passes, a refit tries warm and fresh weights (Student.fit_closed).
        if new > 0 and not self.open:
            student.fit_closed(self.fit_steps, self.gate[1])
            st.student_refits += 1
        elif new > 0 and new >= self.refit_growth * student.fitted_rows:
            student.fit(self.fit_steps)
            st.student_refits += 1
        elif new > 0:
            st.student_refits_deferred += 1
        st.refit_s += time.perf_counter() - start
        was_open = self.open
        self.open = student.gate_after_fit(was_open, self.gate[0], self.gate_close, self.gate[1])
        st.gate_closings += int(was_open and not self.open)
        self._set_rate()
        self._update_student_stats()
        self.health.budget_spent_now()  # the student goes on alone

    def _update_student_stats(self) -> None:
        score, st = self.student.score, self.stats
        st.student_agreement, st.student_majority = score.agreement, score.majority
        st.student_heldout, st.student_dataset_size = score.heldout, self.student.dataset_size
        st.student_per_field = dict(score.per_field)
        st.student_kappa, st.student_informative = score.kappa, list(score.informative)
        if st.gate_passed_at_step < 0 and self.open:
            st.gate_passed_at_step = st.steps


__all__ = ["StudentSource"]
