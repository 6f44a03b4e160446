"""PARE during training: a VecEnv wrapper that adds ``w_llm * f_llm`` to every world's reward.

The advice about state ``s_t`` shapes the reward ``r_{t+1}``: after the action, the move
``p_t -> p_{t+1}`` and the new camera are compared with the advice (DESIGN.md section 5).
Three modes decide where that advice comes from; none of them ever passes one state's advice
off as another's:

``student`` (the default for slow or paid advisors)
    A distilled advisor (:class:`~pirl.advice.student.Student`) answers for the current state
    of every world at every step (staleness 0). The teacher advisor is asked in the background
    about sampled states at ``teacher_rate`` calls per env-step (:class:`TeacherQueue`); its
    answers train the student, refit at rollout boundaries. Until the student's agreement with
    held-out teacher answers reaches ``gate``, steps are left unshaped and counted. When the
    teacher's budget is spent, the student goes on alone.

``sync`` (the paper's timing)
    The prompts for ``s_t`` go to the advisor as soon as ``s_t`` exists (one batch for the
    worlds due a query); ``step_wait`` waits (up to ``timeout_s``) for the answers. An answer
    about an episode that has ended is never used.

``async``
    Never waits: each world uses the freshest answer about its current episode (its staleness
    in steps is reported); an answer about an episode that has ended is dropped and counted.

Between queries (``query_every`` K > 1, teacher modes) the last advice is reused: its move is
read as a direction from the current position, its camera as a target. A failed, late or
unparseable answer leaves the step unshaped (``f_llm = 0``) and is not replaced by older
advice. A spent budget stops teacher shaping at once. When more than ``max_failure_rate`` of
the last ``failure_window`` teacher answers failed, :class:`AdvisorFailing` stops training.

Per step, ``info["pare"]`` holds ``f_llm``, ``dir_align``, ``pos_align``, ``move``, ``cam``,
``status`` (fresh, cached, stale, student or missing) and ``staleness`` (steps); the LLM term
also appears in ``info["reward_terms"]["llm"]``.
"""

from __future__ import annotations

import contextlib
import copy
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnvWrapper

from pirl.advice.base import NO_ANSWER, Advisor, Answer
from pirl.advice.budget import BUDGET_EXHAUSTED
from pirl.advice.factory import exhausted
from pirl.advice.state import advice_requests
from pirl.advice.student import Student, TeacherDataset, student_features
from pirl.env.vec_env import VCPPVecEnv
from pirl.pare.alignment import _align_one
from pirl.pare.teacher import TeacherQueue
from pirl.world import dynamics as D
from pirl.world.config import ConfigError

MODES = ("student", "sync", "async")
STATUSES = ("missing", "fresh", "cached", "stale", "student")
_MISSING, _FRESH, _CACHED, _STALE, _STUDENT = range(5)
# Advice rows: where the advice of a world came from.
KIND_TEACHER, KIND_CACHED, KIND_STUDENT = 0, 1, 2
# Columns of the advice metadata array.
HAS, STEP, KIND = 0, 1, 2


SILENT_BATCHES = 3
"""Teacher batches in a row without a single answer by their deadline that stop training."""


class AdvisorFailing(RuntimeError):
    """Too many recent teacher answers failed; training stops (resumable)."""


@numba.njit(cache=True)
def _shape(p_t, after, rec, meta, t, consts, weights, llm_col, rewards, terms, table, status,
           staleness, counts):  # fmt: skip
    """One step of PARE for every world: alignment, f_llm, status, the shaped reward.

    Reads ``p_t`` (positions before the step), ``after`` (the worlds' integer state after it),
    ``rec`` (advice rows: pan, tilt, zoom, dx, dy, dz) and ``meta`` (has advice, step it was
    asked at, kind), ``consts`` = (d_max, alpha, lam_cam, lam_move). Writes ``table`` rows
    (f_llm, dir_align, pos_align, move, cam; 0 without advice), the LLM column of ``terms``,
    ``rewards += w_llm * f_llm``, ``status``, ``staleness`` and accumulates ``counts``
    (missing, fresh, cached, stale, student, staleness sum).
    """
    n = p_t.shape[0]
    p_next = np.empty((n, 3))
    cam_next = np.empty((n, 3))
    d_max, alpha, lam_cam, lam_move = consts[0], consts[1], consts[2], consts[3]
    for e in range(n):
        st = after[e]
        p_next[e, 0], p_next[e, 1], p_next[e, 2] = st["x"], st["y"], st["z"]
        cam_next[e, 0], cam_next[e, 1] = st["tilt"], st["pan"]
        cam_next[e, 2] = st["zoom10"] / 10.0
        if meta[e, HAS] == 0:
            for k in range(5):
                table[e, k] = 0.0
            status[e], staleness[e] = _MISSING, 0
            terms[e, llm_col] = 0.0
            counts[_MISSING] += 1
            continue
        _align_one(e, p_t, p_next, cam_next, rec, d_max, alpha, table[:, 1:])
        f = lam_cam * table[e, 4] + lam_move * table[e, 3]
        table[e, 0] = f
        terms[e, llm_col] = f
        rewards[e] += np.float32(weights[e, llm_col] * f)
        staleness[e] = t - meta[e, STEP]
        if meta[e, KIND] == KIND_STUDENT:
            status[e] = _STUDENT
        elif staleness[e] > 0:
            status[e] = _STALE
        elif meta[e, KIND] == KIND_CACHED:
            status[e] = _CACHED
        else:
            status[e] = _FRESH
        counts[status[e]] += 1
        counts[5] += staleness[e]


@dataclass
class _Job:
    """One batch of teacher prompts in flight (sync and async modes)."""

    worlds: np.ndarray
    episodes: np.ndarray
    step: int
    prompts: list[str]
    views: list[Any] | None
    future: Future
    sent: float = field(default_factory=time.perf_counter)


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
    student_dataset_size: int = 0
    student_refits: int = 0
    student_refits_deferred: int = 0
    gate_passed_at_step: int = -1
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


class PAREVecEnv(VecEnvWrapper):
    """Adds the PARE reward term to a :class:`~pirl.env.vec_env.VCPPVecEnv`.

    Arguments:
        venv: the batched environment, made with ``llm_weight=True`` so that each episode
            draws (EWRI) or sets (static) the weight of the LLM term.
        advisor: the teacher, any :class:`~pirl.advice.base.Advisor` (cached and budgeted).
        query_every: K, teacher modes: ask every K steps of each world (paper: 1).
        mode: ``"student"``, ``"sync"`` or ``"async"`` (see the module docstring).
        lam_cam, lam_move, alpha: the weights of DESIGN.md section 5.
        timeout_s: sync mode: longest wait for a batch; later answers count as late.
        prompt_variant, decimals: passed to :func:`pirl.advice.prompt.build_prompt`.
        student: student mode: the distilled advisor (fitted or not).
        dataset: student mode: where teacher answers are stored and read.
        teacher_rate: student mode: teacher calls per env-step.
        gate: student mode: held-out agreement the student needs before it shapes.
        refit_every: student mode: vector steps between refits (PPO's ``n_steps``).
        fit_steps: student mode: Adam steps per refit.
        refit_growth: student mode: once the student has passed its gate, refit only when
            the answers have grown by this share since the last fit (0: at every boundary
            with new answers).
        wait_teacher: student mode: collect the teacher's batch at each boundary (reproducible
            runs; PPO then waits for a slow teacher).
        teacher_batch: student mode: most prompts per teacher request.
        max_failure_rate, failure_window: stop when more than this share of the last
            ``failure_window`` teacher answers failed or did not parse (0 disables).
        label: what this PIRL configuration is called in reports.
        seed: the teacher's sampling stream.
        source: student mode: the run's name in the teacher dataset. A resumed run deletes
            the answers it stored there after its checkpoint, then stores them again.
    """

    def __init__(
        self,
        venv: VCPPVecEnv,
        advisor: Advisor,
        query_every: int = 1,
        mode: str = "sync",
        lam_cam: float = 1.0,
        lam_move: float = 1.0,
        alpha: float = 0.5,
        timeout_s: float = 120.0,
        prompt_variant: str = "paper",
        decimals: int = 2,
        student: Student | None = None,
        dataset: TeacherDataset | None = None,
        teacher_rate: float = 0.002,
        gate: float = 0.8,
        refit_every: int = 256,
        fit_steps: int = 100,
        refit_growth: float = 0.0,
        wait_teacher: bool = False,
        teacher_batch: int = 16,
        max_failure_rate: float = 0.5,
        failure_window: int = 200,
        label: str = "",
        seed: int = 0,
        source: str = "",
    ) -> None:
        if not isinstance(venv, VCPPVecEnv):
            raise ConfigError("PARE wraps the VCPPVecEnv itself (put VecMonitor outside it)")
        if not venv.cfg.llm_weight:
            raise ConfigError("PARE needs an environment made with llm_weight=True")
        if mode not in MODES:
            raise ConfigError(f"mode={mode!r}: allowed values are {', '.join(MODES)}")
        if query_every < 1:
            raise ConfigError(f"query_every={query_every!r}: must be >= 1")
        if mode == "student" and (student is None or dataset is None):
            raise ConfigError("student mode needs a student and its teacher dataset")
        super().__init__(venv)
        self.advisor = advisor
        self.query_every = int(query_every)
        self.mode = mode
        self.lam_cam, self.lam_move, self.alpha = float(lam_cam), float(lam_move), float(alpha)
        self.timeout_s = float(timeout_s)
        self.prompt_variant, self.decimals = prompt_variant, int(decimals)
        self.student, self.dataset = student, dataset
        self.gate, self.refit_every = float(gate), int(refit_every)
        self.fit_steps, self.wait_teacher = int(fit_steps), bool(wait_teacher)
        self.refit_growth = float(refit_growth)
        self.max_failure_rate, self.failure_window = float(max_failure_rate), int(failure_window)
        self.stats = PareStats(label=label, mode=mode)

        n = venv.num_envs
        self._world = venv.world
        self._rec = np.zeros((n, 6), dtype=np.float64)  # pan, tilt, zoom, dx, dy, dz
        self._meta = np.zeros((n, 3), dtype=np.int64)  # has advice, step asked, kind
        self._episode = np.zeros(n, dtype=np.int64)
        self._episode_step = np.zeros(n, dtype=np.int64)
        self._want = np.zeros(n, dtype=bool)  # due a query, not yet sent
        self._p_t = np.zeros((n, 3), dtype=np.float64)
        self._table = np.zeros((n, 5), dtype=np.float64)
        self._status = np.zeros(n, dtype=np.int64)
        self._staleness = np.zeros(n, dtype=np.int64)
        self._counts = np.zeros(6, dtype=np.int64)
        d_max = float(np.linalg.norm(np.asarray(venv.cfg.size, dtype=np.float64) - 1.0))
        self._consts = np.array([d_max, self.alpha, self.lam_cam, self.lam_move])
        self._failures: deque[bool] = deque(maxlen=max(1, self.failure_window))
        self._silent = 0  # teacher batches in a row that got no answer at all by the deadline
        self._t = 0
        self._job: _Job | None = None
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pare-advisor")
        self.teacher: TeacherQueue | None = None
        if mode == "student":
            assert student is not None and dataset is not None
            self.teacher = TeacherQueue(
                advisor, dataset, student.teacher, teacher_rate,
                max_pending=max(64, int(2 * teacher_rate * n * self.refit_every) + 1),
                batch_size=teacher_batch,
                prompt_variant=prompt_variant, decimals=decimals, seed=seed, source=source,
            )  # fmt: skip
            self._update_student_stats()

    # -- advice sources ---------------------------------------------------------------------
    def _advise_current(self, obs: np.ndarray) -> None:
        """Student mode: the student's advice about every world's current state."""
        assert self.student is not None and self.teacher is not None
        start = time.perf_counter()
        features = student_features(obs, self._world, range(self.num_envs))
        sampled = time.perf_counter()
        self.teacher.sample(self._world, features)
        asked = time.perf_counter()
        if self.student.passes(self.gate):
            self._rec[:] = self.student.predict(features)
            self._meta[:, HAS] = 1
            self._meta[:, STEP] = self._t
            self._meta[:, KIND] = KIND_STUDENT
        else:
            self._meta[:, HAS] = 0
        self.stats.teacher_s += asked - sampled
        self.stats.student_s += (sampled - start) + (time.perf_counter() - asked)

    def _boundary(self) -> None:
        """Student mode, at a rollout boundary: store teacher answers, refit the student."""
        assert self.student is not None and self.teacher is not None
        start = time.perf_counter()
        answers = self.teacher.boundary(self._t, wait=self.wait_teacher, timeout_s=self.timeout_s)
        self.stats.teacher_s += time.perf_counter() - start
        self._account(answers)
        self.stats.prompts_sent = self.teacher.sent
        self.stats.teacher_skipped = self.teacher.skipped
        assert self.dataset is not None
        start = time.perf_counter()
        student = self.student
        student.pull(self.dataset)
        new = student.dataset_size - student.fitted_rows
        # Refit at every boundary with new answers until the gate passes; after that only
        # once the data has grown by refit_growth since the last fit: as the student
        # converges, refits (the largest cost PIRL adds to PPO) become rarer.
        if new > 0 and (
            not student.passes(self.gate) or new >= self.refit_growth * student.fitted_rows
        ):
            student.fit(self.fit_steps)
            self.stats.student_refits += 1
        elif new > 0:
            self.stats.student_refits_deferred += 1
        self.stats.refit_s += time.perf_counter() - start
        self._update_student_stats()
        self._check_budget()

    def _update_student_stats(self) -> None:
        assert self.student is not None
        score, st = self.student.score, self.stats
        st.student_agreement, st.student_majority = score.agreement, score.majority
        st.student_heldout, st.student_dataset_size = score.heldout, self.student.dataset_size
        st.student_per_field = dict(score.per_field)
        if st.gate_passed_at_step < 0 and self.student.passes(self.gate):
            st.gate_passed_at_step = st.steps

    def _check_budget(self) -> None:
        """A spent budget stops teacher shaping at once (the student goes on)."""
        if self.stats.budget_exhausted or not exhausted(self.advisor):
            return
        self.stats.budget_exhausted = True
        self.stats.budget_exhausted_at_step = self.stats.steps
        if self.mode != "student":
            self._meta[:, HAS] = 0
            self._want[:] = False

    def _account(self, answers: list[Answer]) -> None:
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
            self._failures.append(not answer.ok)
        if self._failures:
            st.failure_rate = float(np.mean(self._failures))
        self._watch_silence(answers)
        evidence = min(self.failure_window, 50)
        if (
            self.max_failure_rate > 0
            and len(self._failures) >= evidence
            and st.failure_rate > self.max_failure_rate
        ):
            last = next((a.error for a in reversed(answers) if a.error), "answers did not parse")
            raise AdvisorFailing(
                f"advisor {self.advisor.label}: {st.failure_rate:.0%} of the last "
                f"{len(self._failures)} answers failed (pare.max_failure_rate "
                f"{self.max_failure_rate:g}); last error: {last}"
            )

    def _watch_silence(self, answers: list[Answer]) -> None:
        """A teacher that accepts requests but answers none of them: whole batches that end at
        the deadline. After SILENT_BATCHES such batches in a row training stops (resumable) at
        once, without waiting for a window of answers that would take many deadlines."""
        if not answers or self.max_failure_rate <= 0:
            return
        if all((a.error or "").startswith(NO_ANSWER) for a in answers):
            self._silent += 1
        else:
            self._silent = 0
        if self._silent >= SILENT_BATCHES:
            raise AdvisorFailing(
                f"advisor {self.advisor.label} answered none of its last {self._silent} "
                f"batches by their deadline; last error: {answers[-1].error}"
            )

    def _submit(self, worlds: np.ndarray) -> None:
        """Teacher modes: send the prompts of ``worlds`` (their current state) as one batch."""
        self._check_budget()
        if not worlds.size or self.stats.budget_exhausted:
            return
        prompts, views = advice_requests(
            self._world, worlds, self.advisor, self.prompt_variant, self.decimals
        )
        future = self._pool.submit(self.advisor.advise, prompts, views)
        self._job = _Job(worlds, self._episode[worlds].copy(), self._t, prompts, views, future)
        self.stats.prompts_sent += len(prompts)
        self.stats.batches_sent += 1

    def _send_due(self) -> None:
        """Mark the worlds due a query this step; send all waiting ones if nothing is in flight."""
        self._want |= self._episode_step % self.query_every == 0
        if self._job is None:
            worlds = np.flatnonzero(self._want)
            self._want[:] = False
            self._submit(worlds)

    def _collect(self, wait: bool) -> None:
        """Teacher modes: take the in-flight batch's answers if there (sync: wait for them)."""
        job = self._job
        if job is None or (not wait and not job.future.done()):
            return
        start = time.perf_counter()
        try:
            answers: list[Answer] = job.future.result(timeout=self.timeout_s if wait else 0)
        except FutureTimeout:
            # Late: those worlds go on without advice until their next answer.
            self.stats.answers_late += len(job.worlds)
            self.stats.wait_s += time.perf_counter() - start
            self._job = None
            self._meta[job.worlds, HAS] = 0
            return
        except Exception as exc:  # an advisor must not raise; if one does, count it as failed
            answers = [Answer("", None, error=f"{type(exc).__name__}: {exc}")] * len(job.worlds)
        self.stats.wait_s += time.perf_counter() - start
        self._job = None
        for e, episode, answer in zip(job.worlds, job.episodes, answers, strict=True):
            if episode != self._episode[e]:
                # That episode is over: its advice is about a state that no longer exists.
                self.stats.answers_dropped_ended += 1
                continue
            rec = answer.recommendation
            if rec is None:
                self._meta[e, HAS] = 0
                continue
            self._rec[e] = (rec.pan, rec.tilt, rec.zoom, rec.dx, rec.dy, rec.dz)
            self._meta[e] = (1, job.step, KIND_CACHED if answer.from_cache else KIND_TEACHER)
        self._account(answers)

    # -- VecEnv ---------------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        obs = self.venv.reset()
        self._drain()
        self._meta[:, HAS] = 0
        self._episode += 1
        self._episode_step[:] = 0
        self._want[:] = False
        if self.mode == "student":
            self._advise_current(obs)
        else:
            self._send_due()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._p_t[:] = self._world.positions()
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        if self.mode != "student":
            self._collect(wait=self.mode == "sync")
            self._check_budget()
        # The snapshot was taken before auto-reset: it holds p_{t+1}, the camera after the
        # action and the ended episodes' weights.
        snap = self.venv.step_snapshot
        table, status, staleness = self._table, self._status, self._staleness
        _shape(
            self._p_t, snap.status, self._rec, self._meta, self._t, self._consts, snap.weights,
            D.T_LLM, rewards, snap.terms, table, status, staleness, self._counts,
        )  # fmt: skip
        # Copies: the lazy infos read them later, after these buffers moved on.
        table, status, staleness = table.copy(), status.copy(), staleness.copy()
        snap.extras["pare"] = lambda e: {
            "f_llm": float(table[e, 0]),
            "dir_align": float(table[e, 1]),
            "pos_align": float(table[e, 2]),
            "move": float(table[e, 3]),
            "cam": float(table[e, 4]),
            "status": STATUSES[status[e]],
            "staleness": int(staleness[e]),
        }
        st, counts = self.stats, self._counts
        st.steps += self.num_envs
        st.steps_missing, st.steps_fresh, st.steps_cached = (
            int(counts[_MISSING]),
            int(counts[_FRESH]),
            int(counts[_CACHED]),
        )
        st.steps_stale, st.steps_student = int(counts[_STALE]), int(counts[_STUDENT])
        st.staleness_sum = int(counts[5])
        self._t += 1
        self._episode_step += 1
        if dones.any():
            ended = np.flatnonzero(dones)
            self._episode[ended] += 1
            self._episode_step[ended] = 0
            self._meta[ended, HAS] = 0  # advice is about one episode only
            self._want[ended] = False
        if self.mode == "student":
            if self._t % self.refit_every == 0:
                self._boundary()
            self._advise_current(obs)
        else:
            self._send_due()
        return obs, rewards, dones, infos

    # -- state ------------------------------------------------------------------------------
    _ARRAYS = ("_rec", "_meta", "_episode", "_episode_step", "_want", "_p_t", "_counts")

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume (at a rollout boundary).

        Sync mode waits for the batch in flight (it would anyway), so its resume is exact;
        async mode keeps the batch's prompts and asks them again on resume (its answers arrive
        at other steps than they would have). Student mode keeps the student, the teacher's
        queue and its batch in flight (asked again on resume).
        """
        pending = None
        job = self._job
        if job is not None:
            answers = job.future.result() if self.mode == "sync" else None
            pending = (job.worlds, job.episodes, job.step, job.prompts, job.views, answers)
        return {
            "arrays": {name: getattr(self, name).copy() for name in self._ARRAYS},
            "t": self._t,
            "stats": copy.deepcopy(self.stats),
            "failures": list(self._failures),
            "pending": pending,
            "student": self.student.state_dict() if self.student is not None else None,
            "teacher": self.teacher.state_dict() if self.teacher is not None else None,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`state_dict` into a freshly built wrapper."""
        for name, value in state["arrays"].items():
            getattr(self, name)[...] = value
        self._t = state["t"]
        label = self.stats.label
        self.stats = copy.deepcopy(state["stats"])
        self.stats.label = label or self.stats.label
        # A resumed run starts a fresh failure window: it was stopped by failures the user has
        # since fixed, and old failures must not stop it again before the advisor is heard.
        self._failures.clear()
        self._job = None
        if state["pending"] is not None:
            worlds, episodes, step, prompts, views, answers = state["pending"]
            future: Future
            if answers is not None:
                future = Future()
                future.set_result(answers)
            else:
                future = self._pool.submit(self.advisor.advise, prompts, views)
            self._job = _Job(worlds, episodes, step, prompts, views, future)
        if self.student is not None and state["student"] is not None:
            assert self.dataset is not None and self.teacher is not None
            # What this run stored after the checkpoint is stored again as it replays.
            self.dataset.forget(self.teacher.source, after=self._t)
            self.student.load_state_dict(state["student"], self.dataset)
        if self.teacher is not None and state["teacher"] is not None:
            self.teacher.load_state_dict(state["teacher"])

    def settle(self) -> PareStats:
        """At the end of a run, without waiting: count a teacher batch that has finished, and
        the prompts still in flight or waiting to be sent (``answers_in_flight``,
        ``teacher_waiting``), so that no prompt sent goes uncounted."""
        st = self.stats
        if self.teacher is not None:
            teacher = self.teacher
            with contextlib.suppress(AdvisorFailing):  # the run is over: count, do not stop
                self._account(teacher.collect_finished(self._t))
            st.answers_in_flight = teacher.in_flight
            st.teacher_waiting = len(teacher._prompts)
            st.prompts_sent = teacher.sent
        else:
            with contextlib.suppress(AdvisorFailing):
                self._collect(wait=False)
            st.answers_in_flight = len(self._job.prompts) if self._job is not None else 0
            st.teacher_waiting = int(self._want.sum())
        return st

    def _drain(self) -> None:
        if self._job is not None:
            # An unfinished batch is dropped at reset; its outcome no longer matters.
            with contextlib.suppress(Exception):
                self._job.future.result(timeout=self.timeout_s)
            self._job = None

    def close(self) -> None:
        self._drain()
        self._pool.shutdown(wait=True)
        if self.teacher is not None:
            self.teacher.close()
        self.advisor.close()
        self.venv.close()
