"""Advice from the teacher itself, one batch in flight: the common part of the sync and async
sources.

The prompts of ``s_t`` go to the advisor as soon as ``s_t`` exists (one batch for the worlds
due a query, every ``query_every`` steps of each world); worlds due while a batch is in flight
wait for the next one. Between queries the last advice is reused: its move is read as a
direction from the current position, its camera as a target. An answer about an episode that
has ended is never used; a failed, late or unparseable answer leaves the world without advice
(it is not replaced by older advice); a spent budget stops teacher shaping at once.
"""

from __future__ import annotations

import contextlib
import time
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pirl.advice.base import Advisor, Answer
from pirl.env.shaping import ShapingHooks
from pirl.pare.asking import requests
from pirl.pare.board import AdviceBoard
from pirl.pare.core import HAS, KIND_CACHED, KIND_TEACHER
from pirl.pare.sources.base import SourceSetup
from pirl.pare.stats import AdvisorFailing, Health


@dataclass
class Job:
    """One batch of teacher prompts in flight."""

    worlds: np.ndarray
    episodes: np.ndarray
    step: int
    prompts: list[str]
    views: list[Any] | None
    future: Future
    sent: float = field(default_factory=time.perf_counter)


class BatchSource:
    """Asks the teacher about the worlds due a query, one batch at a time.

    Subclasses say whether a step waits for the batch in flight (:attr:`wait`) and what of
    it a checkpoint keeps (:meth:`_kept_answers`).
    """

    mode = ""
    wait = False

    def __init__(
        self,
        board: AdviceBoard,
        health: Health,
        advisor: Advisor,
        query_every: int = 1,
        timeout_s: float = 120.0,
        prompt_variant: str = "paper",
        decimals: int = 2,
    ) -> None:
        self.board, self.health, self.stats = board, health, health.stats
        self.advisor = advisor
        self.query_every, self.timeout_s = int(query_every), float(timeout_s)
        self.prompt_variant, self.decimals = prompt_variant, int(decimals)
        self.want = np.zeros(board.n, dtype=bool)  # due a query, not yet sent
        self.job: Job | None = None
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pare-advisor")

    @classmethod
    def build(cls, setup: SourceSetup) -> BatchSource:
        p = setup.settings
        return cls(
            setup.board, setup.health, setup.advisor, p.query_every, p.timeout_s,
            p.prompt_variant,
        )  # fmt: skip

    # -- AdviceSource ---------------------------------------------------------------------
    def reset(self) -> None:
        self._drain()
        self.want[:] = False

    def collect(self) -> None:
        self._collect(self.wait)
        self._check_budget()

    def end(self, worlds: np.ndarray) -> None:
        self.want[worlds] = False

    def tick(self) -> None:
        return None

    def request(self, env: ShapingHooks, obs: np.ndarray, live: np.ndarray | None) -> None:
        """Mark the worlds due a query; send all waiting ones if nothing is in flight."""
        due = self.board.episode_step % self.query_every == 0
        self.want |= due if live is None else due & live
        if self.job is None:
            worlds = np.flatnonzero(self.want)
            self.want[:] = False
            self._submit(env, worlds)

    def settle(self) -> None:
        with contextlib.suppress(AdvisorFailing):  # the run is over: count, do not stop
            self._collect(wait=False)
        st = self.stats
        st.answers_in_flight = len(self.job.prompts) if self.job is not None else 0
        st.teacher_waiting = int(self.want.sum())

    def state_dict(self) -> dict[str, Any]:
        pending = None
        job = self.job
        if job is not None:
            answers = self._kept_answers(job)
            pending = (job.worlds, job.episodes, job.step, job.prompts, job.views, answers)
        return {"want": self.want.copy(), "pending": pending}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.want[...] = state["want"]
        self.job = None
        if state["pending"] is not None:
            worlds, episodes, step, prompts, views, answers = state["pending"]
            future: Future
            if answers is not None:
                future = Future()
                future.set_result(answers)
            else:
                future = self._pool.submit(self.advisor.advise, prompts, views)
            self.job = Job(worlds, episodes, step, prompts, views, future)

    def close(self) -> None:
        self._drain()
        self._pool.shutdown(wait=True)

    # -- the batch in flight --------------------------------------------------------------
    def _kept_answers(self, job: Job) -> list[Answer] | None:
        """What a checkpoint keeps of the batch in flight: its answers, or None to ask its
        prompts again on resume."""
        return None

    def _check_budget(self) -> None:
        """A spent budget stops teacher shaping at once."""
        if self.health.budget_spent_now():
            self.board.meta[:, HAS] = 0
            self.want[:] = False

    def _submit(self, env: ShapingHooks, worlds: np.ndarray) -> None:
        """Send the prompts of ``worlds`` (their current state) as one batch."""
        self._check_budget()
        if not worlds.size or self.stats.budget_exhausted:
            return
        prompts, views = requests(env, worlds, self.advisor, self.prompt_variant, self.decimals)
        future = self._pool.submit(self.advisor.advise, prompts, views)
        board = self.board
        self.job = Job(worlds, board.episode[worlds].copy(), board.t, prompts, views, future)
        self.stats.prompts_sent += len(prompts)
        self.stats.batches_sent += 1

    def _collect(self, wait: bool) -> None:
        """Take the in-flight batch's answers if there (``wait``: wait for them)."""
        job = self.job
        if job is None or (not wait and not job.future.done()):
            return
        st, board = self.stats, self.board
        start = time.perf_counter()
        try:
            answers: list[Answer] = job.future.result(timeout=self.timeout_s if wait else 0)
        except FutureTimeout:
            # Late: those worlds go on without advice until their next answer.
            st.answers_late += len(job.worlds)
            st.wait_s += time.perf_counter() - start
            self.job = None
            board.meta[job.worlds, HAS] = 0
            return
        except Exception as exc:  # an advisor must not raise; if one does, count it as failed
            answers = [Answer("", None, error=f"{type(exc).__name__}: {exc}")] * len(job.worlds)
        st.wait_s += time.perf_counter() - start
        self.job = None
        if st.budget_exhausted:
            # Reserved before the budget was found spent, answered after: shaping stopped at
            # once when it was found, so these answers are counted, not used.
            self.health.account(answers)
            return
        for e, episode, answer in zip(job.worlds, job.episodes, answers, strict=True):
            if episode != board.episode[e]:
                # That episode is over: its advice is about a state that no longer exists.
                st.answers_dropped_ended += 1
                continue
            rec = answer.recommendation
            if rec is None:
                board.meta[e, HAS] = 0
                continue
            board.rec[e] = (rec.pan, rec.tilt, rec.zoom, rec.dx, rec.dy, rec.dz)
            board.meta[e] = (1, job.step, KIND_CACHED if answer.from_cache else KIND_TEACHER)
        self.health.account(answers)

    def _drain(self) -> None:
        if self.job is not None:
            # An unfinished batch is dropped; its outcome no longer matters.
            with contextlib.suppress(Exception):
                self.job.future.result(timeout=self.timeout_s)
            self.job = None


__all__ = ["BatchSource", "Job"]
