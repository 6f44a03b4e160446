"""A spending limit on advisor calls and tokens, with a clean stop.

Put the budget behind the cache (``CachedAdvisor(BudgetedAdvisor(inner, budget), path)``) so that
only real calls are charged. Once the budget is spent, the inner advisor is not called again:
every prompt gets ``Answer(error="budget exhausted")`` (PARE then gives f_llm = 0), and one
warning is logged, the first time.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence
from typing import Any

from pirl.advice.base import Advisor, Answer, error_answer

__all__ = ["BUDGET_EXHAUSTED", "Budget", "BudgetedAdvisor"]

log = logging.getLogger(__name__)

BUDGET_EXHAUSTED = "budget exhausted"
"""The error text of answers refused by a spent budget."""


class Budget:
    """Limits on advisor calls and tokens (prompt + completion); ``None`` means no limit.

    Calls are reserved before they are made, so a call limit is never exceeded. Tokens are only
    known afterwards: the token limit is checked before each batch, and the batch that crosses
    it completes. Thread-safe; one budget may be shared by several advisors.
    """

    def __init__(self, max_calls: int | None = None, max_tokens: int | None = None) -> None:
        for name, value in (("max_calls", max_calls), ("max_tokens", max_tokens)):
            if value is not None and value < 0:
                raise ValueError(f"{name} must be >= 0 or None, got {value}")
        self.max_calls = max_calls
        self.max_tokens = max_tokens
        self.calls = 0
        self.tokens = 0
        self._lock = threading.Lock()
        self._warned = False

    @property
    def exhausted(self) -> bool:
        """Whether no further call may be made."""
        calls_spent = self.max_calls is not None and self.calls >= self.max_calls
        tokens_spent = self.max_tokens is not None and self.tokens >= self.max_tokens
        return calls_spent or tokens_spent

    @property
    def remaining_calls(self) -> int | None:
        """Calls left (``None`` without a call limit)."""
        return None if self.max_calls is None else max(0, self.max_calls - self.calls)

    def reserve(self, n: int) -> int:
        """Reserve up to ``n`` calls; returns how many may be made now (0 once exhausted)."""
        with self._lock:
            if self.exhausted:
                return 0
            granted = n if self.max_calls is None else min(n, self.max_calls - self.calls)
            self.calls += granted
            return granted

    def charge_tokens(self, tokens: int) -> None:
        """Record tokens spent by calls made."""
        with self._lock:
            self.tokens += int(tokens)

    def warn_once(self) -> None:
        """Log the exhaustion warning, the first time only."""
        with self._lock:
            if self._warned:
                return
            self._warned = True
        log.warning(
            "advice budget exhausted after %d calls and %d tokens (limits: calls %s, tokens %s); "
            "no more LLM calls: further prompts get error %r",
            self.calls,
            self.tokens,
            self.max_calls,
            self.max_tokens,
            BUDGET_EXHAUSTED,
        )

    def as_dict(self) -> dict[str, Any]:
        """Limits and use, for run records."""
        return {
            "max_calls": self.max_calls,
            "max_tokens": self.max_tokens,
            "calls": self.calls,
            "tokens": self.tokens,
            "exhausted": self.exhausted,
        }

    def __repr__(self) -> str:
        return (
            f"Budget(max_calls={self.max_calls}, max_tokens={self.max_tokens}, "
            f"calls={self.calls}, tokens={self.tokens})"
        )


class BudgetedAdvisor(Advisor):
    """``advisor`` behind ``budget``: calls it while the budget lasts, refuses cleanly after."""

    def __init__(self, advisor: Advisor, budget: Budget) -> None:
        self.inner = advisor
        self.budget = budget
        self.name = advisor.name
        self.model = advisor.model
        self.label = advisor.label
        self.wants_view = advisor.wants_view

    @property
    def exhausted(self) -> bool:
        """Whether the budget is spent."""
        return self.budget.exhausted

    @property
    def calls(self) -> int:
        """Calls charged to the budget so far."""
        return self.budget.calls

    @property
    def tokens(self) -> int:
        """Tokens charged to the budget so far."""
        return self.budget.tokens

    def settings_key(self) -> str:
        """The inner advisor's settings key (the budget does not change answers)."""
        return self.inner.settings_key()

    def advise(self, prompts: list[str], views: Sequence[Any] | None = None) -> list[Answer]:
        """Inner answers for the prompts the budget allows, refusals for the rest."""
        granted = self.budget.reserve(len(prompts))
        answers: list[Answer] = []
        if granted:
            try:
                answers = list(
                    self.inner.advise(prompts[:granted], None if views is None else views[:granted])
                )
            except Exception as exc:  # noqa: BLE001 - an advisor that broke its contract
                answers = [error_answer(f"{type(exc).__name__}: {exc}") for _ in range(granted)]
            self.budget.charge_tokens(sum(a.prompt_tokens + a.completion_tokens for a in answers))
        refused = len(prompts) - granted
        if refused:
            self.budget.warn_once()
            answers += [error_answer(BUDGET_EXHAUSTED) for _ in range(refused)]
        return answers

    def close(self) -> None:
        """Close the inner advisor."""
        self.inner.close()

    def __repr__(self) -> str:
        return f"BudgetedAdvisor({self.inner!r}, {self.budget!r})"
