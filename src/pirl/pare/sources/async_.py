"""The async source: never waits. Each world uses the freshest answer about its current
episode (its staleness in steps is reported); an answer about an episode that has ended is
dropped and counted."""

from __future__ import annotations

from pirl.pare.sources.batches import BatchSource


class AsyncSource(BatchSource):
    """Takes a batch's answers at the first step after they arrive. A checkpoint keeps the
    batch's prompts and asks them again on resume (its answers then arrive at other steps
    than they would have)."""

    mode = "async"
    wait = False


__all__ = ["AsyncSource"]
