"""Build the advisor a run config names, with its cache and budget in front."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

from pirl._paths import cache_root
from pirl.advice.base import Advisor
from pirl.advice.registry import advisor_kind
from pirl.config.run import RunConfig


def default_cache_path() -> Path:
    """``advice.sqlite`` in the PIRL cache folder (:func:`pirl._paths.cache_root`)."""
    return cache_root() / "advice.sqlite"


def make_advisor(
    name: str, cfg: RunConfig, cache: bool | None = None, process: bool = False
) -> Advisor:
    """The advisor registered as ``name`` (:mod:`pirl.advice.registry`), configured by a
    RunConfig ``cfg``.

    ``process``: run it in a child process of its own where its entry says how (training: PPO
    keeps its interpreter and PyTorch threads; see :mod:`pirl.advice.process`).

    The budget (if any) and then the persistent cache go in front of an advisor whose entry
    allows them, so cached answers cost nothing.
    """
    from pirl.config.errors import ConfigError, UserError

    kind = advisor_kind(name)
    p = cfg.pare
    try:
        if process and kind.in_process is not None:
            advisor = kind.in_process(cfg, functools.partial(kind.build, cfg))
        else:
            advisor = kind.build(cfg)
    except (ValueError, OSError) as exc:
        # A missing key, model folder or model file: the user's to fix, said in one line.
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UserError(f"advisor {name}: {first}") from None
    if not callable(getattr(advisor, "advise", None)):
        raise ConfigError(f"advisor {name}: its factory returned {type(advisor).__name__}, not "
                          "an advisor (pirl.advice.base.Advisor)")  # fmt: skip
    if kind.budgeted and (p.budget_calls or p.budget_tokens):
        from pirl.advice.budget import Budget, BudgetedAdvisor

        budget = Budget(p.budget_calls or None, p.budget_tokens or None)
        advisor = BudgetedAdvisor(advisor, budget)
    if kind.cacheable and (p.cache if cache is None else cache):
        from pirl.advice.cache import CachedAdvisor

        advisor = CachedAdvisor(advisor, p.cache_path or default_cache_path())
    return advisor


def exhausted(advisor: Any) -> bool:
    """Whether any layer of an advisor stack (cache -> budget -> backend) has run dry."""
    while advisor is not None:
        if getattr(advisor, "exhausted", False) is True:
            return True
        advisor = getattr(advisor, "inner", None)
    return False
