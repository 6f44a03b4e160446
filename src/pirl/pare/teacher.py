"""The student's teacher during training: a few sampled states asked in the background.

Each step, states are sampled at ``rate`` teacher calls per env-step (a seeded draw over the
worlds); their prompts, world views and student features wait in a bounded queue. At a rollout
boundary the finished batch (if any) is collected and its answers are stored with their
features in the :class:`~pirl.advice.student.TeacherDataset`; then the queue is sent as one
batch to a background thread, so PPO never waits for the teacher (``wait=True`` collects the
batch in flight at the boundary instead, which makes a run reproducible: tests and
``pirl distill``).
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.factory import exhausted
from pirl.advice.student import encode
from pirl.advice.teacher_dataset import TeacherDataset
from pirl.env.shaping import ShapingHooks
from pirl.pare.asking import requests


@dataclass
class _Batch:
    prompts: list[str]
    views: list[Any] | None
    features: np.ndarray


class TeacherQueue:
    """Asks ``advisor`` about sampled states and stores its answers under ``key``.

    Arguments:
        advisor: the teacher (any advisor, cached and budgeted as configured).
        dataset: where answers are stored with their features.
        key: the dataset key of this teacher (:func:`pirl.advice.student.teacher_key`).
        rate: teacher calls per env-step (expected).
        max_pending: most states waiting to be sent; further samples are skipped and counted.
        batch_size: most states in one request; the rest wait for the next boundary, so a
            slow teacher's answers arrive in steady small batches.
        prompt_variant, decimals: the prompt's settings.
        seed: the sampling stream.
        source: the run's name in the dataset (what a resume forgets past its checkpoint).
    """

    def __init__(
        self,
        advisor: Advisor,
        dataset: TeacherDataset,
        key: str,
        rate: float,
        max_pending: int = 64,
        batch_size: int = 16,
        prompt_variant: str = "paper",
        decimals: int = 2,
        seed: int = 0,
        source: str = "",
    ) -> None:
        self.advisor, self.dataset, self.key, self.source = advisor, dataset, key, source
        self.rate, self.max_pending = float(rate), int(max_pending)
        self.batch_size = max(1, int(batch_size))
        self.prompt_variant, self.decimals = prompt_variant, int(decimals)
        self.rng = np.random.default_rng(seed)
        self.credit = 0.0
        self._prompts: list[str] = []
        self._views: list[Any] = []
        self._features: list[np.ndarray] = []
        self._job: tuple[_Batch, Future] | None = None
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pirl-teacher")
        self.sent = 0
        self.skipped = 0
        self.stored = 0

    @property
    def spent(self) -> bool:
        """Whether the teacher's budget is spent (no more calls)."""
        return exhausted(self.advisor)

    def sample(
        self, env: ShapingHooks, features: np.ndarray, worlds: np.ndarray | None = None
    ) -> None:
        """Draw this step's states (``features``: one row per world of ``worlds``, default
        all, their current states)."""
        if self.rate <= 0 or self.spent:
            return
        self.credit += self.rate * features.shape[0]
        k = int(self.credit)
        if not k:
            return
        self.credit -= k
        room = self.max_pending - len(self._prompts)
        take = min(k, room, features.shape[0])
        self.skipped += k - max(take, 0)
        if take <= 0:
            return
        rows = np.sort(self.rng.choice(features.shape[0], size=take, replace=False))
        asked = rows if worlds is None else worlds[rows]
        prompts, views = requests(env, asked, self.advisor, self.prompt_variant, self.decimals)
        self._prompts += prompts
        if views is not None:
            self._views += views
        self._features += [features[e].copy() for e in rows]

    def boundary(self, t: int, wait: bool = False, timeout_s: float = 600.0) -> list[Answer]:
        """At a rollout boundary (step ``t``): collect the finished batch (``wait``: wait for
        it), store its answers, send the waiting states. Returns the collected answers."""
        answers = self._collect(wait, timeout_s, t)
        if self._job is None and self._prompts and not self.spent:
            k = self.batch_size
            batch = _Batch(
                self._prompts[:k],
                self._views[:k] or None,
                np.stack(self._features[:k]).astype(np.float32),
            )
            self._prompts, self._views = self._prompts[k:], self._views[k:]
            self._features = self._features[k:]
            future = self._pool.submit(self.advisor.advise, batch.prompts, batch.views)
            self._job = (batch, future)
            self.sent += len(batch.prompts)
        return answers

    @property
    def in_flight(self) -> int:
        """Prompts sent whose answers have not been collected."""
        return len(self._job[0].prompts) if self._job is not None else 0

    @property
    def waiting(self) -> int:
        """Sampled states waiting to be sent."""
        return len(self._prompts)

    def collect_finished(self, t: int) -> list[Answer]:
        """Collect and store the batch in flight if it has finished (never waits)."""
        return self._collect(False, 0.0, t)

    def _collect(self, wait: bool, timeout_s: float, t: int) -> list[Answer]:
        if self._job is None:
            return []
        batch, future = self._job
        if not wait and not future.done():
            return []
        try:
            answers = list(future.result(timeout=timeout_s if wait else 0))
        except Exception as exc:  # noqa: BLE001 - an advisor must not raise; if one does
            answers = [error_answer(f"{type(exc).__name__}: {exc}")] * len(batch.prompts)
        self._job = None
        ok = [i for i, a in enumerate(answers) if a.recommendation is not None]
        if ok:
            labels = encode([answers[i].recommendation for i in ok])
            self.stored += self.dataset.add(self.key, batch.features[ok], labels, self.source, t)
        return answers

    def state_dict(self) -> dict[str, Any]:
        """The sampling stream, the waiting states and the batch in flight (never waits)."""
        inflight = None
        if self._job is not None:
            batch = self._job[0]
            inflight = (list(batch.prompts), batch.views, batch.features.copy())
        return {
            "rng": self.rng.bit_generator.state,
            "credit": self.credit,
            "prompts": list(self._prompts),
            "views": list(self._views),
            "features": [f.copy() for f in self._features],
            "inflight": inflight,
            "sent": self.sent,
            "skipped": self.skipped,
            "stored": self.stored,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`state_dict`; the batch that was in flight is asked again now."""
        self.rng.bit_generator.state = state["rng"]
        self.credit = state["credit"]
        self._prompts, self._views = list(state["prompts"]), list(state["views"])
        self._features = [f.copy() for f in state["features"]]
        self.sent, self.skipped, self.stored = state["sent"], state["skipped"], state["stored"]
        if self._job is not None:
            self._job[1].cancel()
            self._job = None
        if state["inflight"] is not None:
            prompts, views, features = state["inflight"]
            batch = _Batch(prompts, views, features)
            self._job = (batch, self._pool.submit(self.advisor.advise, prompts, views))

    def close(self) -> None:
        if self._job is not None:
            self._job[1].cancel()
        self._pool.shutdown(wait=True)
