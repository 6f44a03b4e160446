"""Build the advisor a run config names, with its cache and budget in front."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

from pirl._paths import cache_root
from pirl.advice.base import Advisor
from pirl.config.run import RunConfig


def default_cache_path() -> Path:
    """``advice.sqlite`` in the PIRL cache folder (:func:`pirl._paths.cache_root`)."""
    return cache_root() / "advice.sqlite"


def make_advisor(
    name: str, cfg: RunConfig, cache: bool | None = None, process: bool = False
) -> Advisor:
    """``local``, ``openai`` or ``oracle`` as configured by a RunConfig ``cfg``.

    ``process``: run the local model in a child process of its own (training: PPO keeps its
    interpreter and PyTorch threads; see :mod:`pirl.advice.process`).

    LLM advisors get the budget (if any) and then the persistent cache in front, so cached
    answers cost nothing. The oracle is not an LLM: it is neither cached nor budgeted (its
    answer depends on the map, which the prompt does not hold).
    """
    from pirl.config.errors import ConfigError, UserError

    p = cfg.pare
    if name == "oracle":
        from pirl.advice.oracle import OracleAdvisor

        return OracleAdvisor()
    if name not in ("local", "openai"):
        raise ConfigError(f"advisor {name!r}: allowed values are local, openai, oracle")
    try:
        if process and name == "local":
            from pirl.advice.process import ProcessAdvisor

            advisor = ProcessAdvisor(
                functools.partial(_backend, name, cfg), threads=cfg.advisor.local_threads
            )
        else:
            advisor = _backend(name, cfg)
    except (ValueError, OSError) as exc:
        # A missing key, model folder or model file: the user's to fix, said in one line.
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UserError(f"advisor {name}: {first}") from None
    if p.budget_calls or p.budget_tokens:
        from pirl.advice.budget import Budget, BudgetedAdvisor

        budget = Budget(p.budget_calls or None, p.budget_tokens or None)
        advisor = BudgetedAdvisor(advisor, budget)
    if p.cache if cache is None else cache:
        from pirl.advice.cache import CachedAdvisor

        advisor = CachedAdvisor(advisor, p.cache_path or default_cache_path())
    return advisor


def _backend(name: str, cfg: RunConfig) -> Advisor:
    a = cfg.advisor
    if name == "local":
        from pirl.advice.local import LocalAdvisor

        return LocalAdvisor(
            a.local_model or None, num_threads=a.local_threads, batch_size=a.local_batch_size
        )
    from pirl.advice.openai_advisor import OpenAIAdvisor

    return OpenAIAdvisor(
        a.openai_model,
        base_url=a.openai_base_url or None,
        api_key_env=a.openai_api_key_env,
        timeout_s=a.openai_timeout_s,
        deadline_s=a.openai_deadline_s,
        max_retries=a.openai_max_retries,
        concurrency=a.openai_concurrency,
    )


def exhausted(advisor: Any) -> bool:
    """Whether any layer of an advisor stack (cache -> budget -> backend) has run dry."""
    while advisor is not None:
        if getattr(advisor, "exhausted", False) is True:
            return True
        advisor = getattr(advisor, "inner", None)
    return False
