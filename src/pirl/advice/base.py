"""The advisor interface: prompts in, :class:`Answer` objects out, never an exception."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from pirl.advice.recommendation import Recommendation

__all__ = ["MAX_ANSWER_CHARS", "Answer", "Advisor", "error_answer"]

MAX_ANSWER_CHARS = 1024
"""Longest reply kept: a recommendation is one short line (requests ask for at most
``advisor.max_tokens`` tokens), so anything longer is a misbehaving model or server."""


@dataclass(frozen=True)
class Answer:
    """One advisor reply.

    Attributes:
        text: the raw text the model wrote ("" when the call failed).
        recommendation: the parsed advice, or ``None`` when unparseable or failed.
        latency_s: wall time of the call that produced it (for a batch, the batch's time).
        prompt_tokens: tokens read (0 when unknown or cached).
        completion_tokens: tokens written (0 when unknown or cached).
        from_cache: whether it came from a persistent cache.
        error: why the call failed, or ``None``.
        reply_chars: the length of the whole reply when ``text`` is only its head (a reply
            longer than :data:`MAX_ANSWER_CHARS`, or a body cut at read time); 0 otherwise.

    A reply longer than :data:`MAX_ANSWER_CHARS` keeps only its head and counts as
    unparseable, whoever made it: no cache, checkpoint or console ever holds it whole.
    """

    text: str
    recommendation: Recommendation | None
    latency_s: float = 0.0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    from_cache: bool = False
    error: str | None = None
    reply_chars: int = 0

    def __post_init__(self) -> None:
        if len(self.text) > MAX_ANSWER_CHARS:
            # Frozen: the dataclass refuses plain assignment.
            object.__setattr__(self, "reply_chars", max(self.reply_chars, len(self.text)))
            object.__setattr__(self, "text", self.text[:MAX_ANSWER_CHARS])
        if self.reply_chars:
            object.__setattr__(self, "recommendation", None)

    @property
    def cut(self) -> bool:
        """Whether the reply was too long and only its head is kept."""
        return self.reply_chars > 0

    @property
    def ok(self) -> bool:
        """Whether the call succeeded and the answer parsed."""
        return self.error is None and self.recommendation is not None


NO_ANSWER = "no answer within"
"""How the error of an answer that never came (a deadline passed) starts; a teacher whose
whole batches end this way has stopped answering (PARE stops training after a few)."""


def error_answer(error: str, latency_s: float = 0.0) -> Answer:
    """A failed answer carrying ``error``."""
    return Answer(text="", recommendation=None, latency_s=latency_s, error=error)


class Advisor(ABC):
    """An LLM backend (or anything else) that answers prompts with recommendations.

    Subclasses set ``name`` (backend kind, e.g. ``"local"``), ``model`` (model identifier) and
    ``label`` (what reports print), and implement :meth:`settings_key` and :meth:`advise`.

    Every advisor takes an optional world view per prompt. An LLM reads only the prompt and
    ignores views; an advisor that plans from the map (the oracle) sets ``wants_view`` and
    answers with an error for a prompt that comes without one. Build both with
    :func:`pirl.advice.state.advice_requests`.
    """

    name: str = "advisor"
    model: str = ""
    label: str = "advisor"
    wants_view: bool = False
    """Whether answers depend on the world view (the map), not only on the prompt."""

    @abstractmethod
    def settings_key(self) -> str:
        """A stable text of every generation setting that can change an answer (cache key)."""

    @abstractmethod
    def advise(self, prompts: list[str], views: Sequence[Any] | None = None) -> list[Answer]:
        """Answers to ``prompts``, in the same order (``views``: one
        :class:`~pirl.world.planning.WorldView` per prompt, or None).

        A failed call never raises: it becomes ``Answer(error=..., recommendation=None)``.
        """

    def close(self) -> None:  # noqa: B027 - optional hook, nothing to release by default
        """Release resources (connections, files). Safe to call twice."""

    def __enter__(self) -> Advisor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
