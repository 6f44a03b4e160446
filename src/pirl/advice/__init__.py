"""The LLM side of PIRL: prompt builder, answer parser, advisors, persistent cache and budget.

Importing this package is cheap: the advisors that need torch/transformers (``LocalAdvisor``)
or ``openai`` (``OpenAIAdvisor``) are imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.budget import BUDGET_EXHAUSTED, Budget, BudgetedAdvisor
from pirl.advice.cache import CachedAdvisor, cache_key
from pirl.advice.parser import parse_recommendation
from pirl.advice.prompt import VARIANTS, PromptState, build_prompt
from pirl.advice.recommendation import FORMAT_EXAMPLE, Recommendation

if TYPE_CHECKING:  # pragma: no cover
    from pirl.advice.local import LocalAdvisor
    from pirl.advice.openai_advisor import OpenAIAdvisor

__all__ = [
    "BUDGET_EXHAUSTED",
    "FORMAT_EXAMPLE",
    "VARIANTS",
    "Advisor",
    "Answer",
    "Budget",
    "BudgetedAdvisor",
    "CachedAdvisor",
    "LocalAdvisor",
    "OpenAIAdvisor",
    "PromptState",
    "Recommendation",
    "build_prompt",
    "cache_key",
    "error_answer",
    "parse_recommendation",
]

_LAZY = {
    "LocalAdvisor": "pirl.advice.local",
    "OpenAIAdvisor": "pirl.advice.openai_advisor",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'pirl.advice' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module), name)


def __dir__() -> list[str]:
    return sorted(__all__)
