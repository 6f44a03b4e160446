"""The sync source, the paper's timing: each step waits (up to ``timeout_s``) for the answers
about the state it started from, so the advice about ``s_t`` shapes ``r_{t+1}``."""

from __future__ import annotations

from pirl.advice.base import Answer
from pirl.pare.sources.batches import BatchSource, Job


class SyncSource(BatchSource):
    """Waits for every batch; a checkpoint keeps the batch's answers, so resume is exact."""

    mode = "sync"
    wait = True

    def _kept_answers(self, job: Job) -> list[Answer] | None:
        return job.future.result()  # it would wait for them at the next step anyway


__all__ = ["SyncSource"]
