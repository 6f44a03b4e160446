"""Every advisor PIRL can ask, by name: the built-ins and those installed packages declare.

An entry (:class:`AdvisorKind`) holds what the rest of the code needs to know about one kind
of advisor: how to build it from a run config, whether its answers may be cached and
budgeted, how many prompts a teacher request holds, how often PARE's student asks it, whether
it needs an API key, whether it talks to a server, and the rates a reproduction plan
estimates with. The command line, the config checks, ``pirl reproduce``'s plan, the reports'
labels and the health probe all read these entries; nothing else compares advisor names.

A package adds an advisor with an entry point in group ``pirl.advisors``: the name is what
``--advisor`` takes, the object is either a factory ``f(cfg) -> Advisor`` (an LLM-like
advisor with the defaults below) or a whole :class:`AdvisorKind`. docs/architecture.md shows
one.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from pirl.advice.base import Advisor
from pirl.config.errors import ConfigError, UserError
from pirl.config.run import RunConfig

ENTRY_POINT_GROUP = "pirl.advisors"
"""The entry-point group a package declares its advisors in."""


def _default_batch(cfg: RunConfig) -> int:
    return 16


def _pare_teacher_rate(cfg: RunConfig) -> float:
    return cfg.pare.teacher_rate


def _no_key(cfg: RunConfig) -> None:
    return None


@dataclass(frozen=True)
class AdvisorKind:
    """One kind of advisor and the facts the rest of PIRL reads about it."""

    name: str
    """What ``--advisor`` and ``pare.advisor`` say."""
    build: Callable[[RunConfig], Advisor]
    """Run config -> the backend advisor (no cache, no budget in front)."""
    label: str = ""
    """What help texts and reports call it before one is built (e.g. ``oracle (not an
    LLM)``); a built advisor's own ``label`` also names its model."""
    llm: bool = True
    """An LLM answering from the prompt alone. False: reports say "not an LLM", and it is fast
    enough that PIRL needs no teacher head start."""
    cacheable: bool = True
    """Its answers depend on the prompt only, so the persistent answer cache may keep them."""
    budgeted: bool = True
    """Its calls count against ``pare.budget_calls`` and ``pare.budget_tokens``."""
    server: str = ""
    """The server it asks when none is configured (a URL); empty: it answers in-process."""
    batch_size: Callable[[RunConfig], int] = _default_batch
    """Run config -> most prompts per teacher request (student mode)."""
    teacher_rate: Callable[[RunConfig], float] = _pare_teacher_rate
    """Run config -> teacher calls per env-step (student mode)."""
    check_key: Callable[[RunConfig], None] = _no_key
    """Run config -> None, or :class:`UserError` when a key it needs is missing (before
    anything is built or written)."""
    in_process: Callable[[Any, Callable[[], Advisor]], Advisor] | None = None
    """Training: run the advisor in a child process of its own (``(cfg, build) ->
    advisor``), so PPO keeps its interpreter; None: it runs in the training process."""
    model_setting: str = ""
    """The ``advisor.*`` setting ``pirl advise --model`` sets (empty: none)."""
    train_cost: float = 2.8
    """Plan estimate: a PIRL run's time against PPO's in student mode."""
    answers_per_s: float = 1.0
    """Plan estimate: teacher answers per second in a teacher phase."""
    sync_batch_s: float = 0.0
    """Plan estimate: seconds per batch of answers that sync or async PARE waits for."""
    prompt_variant: str = "paper"
    """The prompt it suits, which ``pirl advise`` uses when no config says otherwise."""


def _local(cfg: RunConfig) -> Advisor:
    from pirl.advice.local import LocalAdvisor

    a = cfg.advisor
    return LocalAdvisor(
        a.local_model or None, num_threads=a.local_threads, batch_size=a.local_batch_size
    )


def _local_in_process(cfg: RunConfig, build: Callable[[], Advisor]) -> Advisor:
    from pirl.advice.process import ProcessAdvisor

    return ProcessAdvisor(build, threads=cfg.advisor.local_threads)


def _openai(cfg: RunConfig) -> Advisor:
    from pirl.advice.openai_advisor import OpenAIAdvisor

    a = cfg.advisor
    return OpenAIAdvisor(
        a.openai_model,
        base_url=a.openai_base_url or None,
        api_key_env=a.openai_api_key_env,
        timeout_s=a.openai_timeout_s,
        deadline_s=a.openai_deadline_s,
        max_retries=a.openai_max_retries,
        concurrency=a.openai_concurrency,
    )


def _openai_key(cfg: RunConfig) -> None:
    import os

    a = cfg.advisor
    # OPENAI_BASE_URL names a server as the openai SDK reads it; such a server may need no key.
    server = a.openai_base_url or os.environ.get("OPENAI_BASE_URL")
    if not server and not os.environ.get(a.openai_api_key_env):
        raise UserError(
            f"the openai advisor needs an API key: set the {a.openai_api_key_env} environment "
            "variable (or advisor.openai_base_url or OPENAI_BASE_URL for a server that needs "
            "none)"
        )


def _oracle(cfg: RunConfig) -> Advisor:
    from pirl.advice.oracle import OracleAdvisor

    return OracleAdvisor(cfg.advisor.oracle_accuracy)


# Rates: the demo's measurement (student mode: oracle 60 s, embedded LLM 127 s beside PPO's 45 s;
# a teacher phase of the embedded model 160 answers in 94 s) and an estimated 20 s per batch
# of embedded-LLM answers in sync PARE (docs/deviations.md).
BUILTIN: dict[str, AdvisorKind] = {
    kind.name: kind
    for kind in (
        AdvisorKind(
            "local",
            _local,
            label="embedded model (SmolLM2-135M-Instruct or advisor.local_model)",
            batch_size=lambda cfg: cfg.advisor.local_batch_size,
            in_process=_local_in_process,
            model_setting="local_model",
            answers_per_s=1.2,
            sync_batch_s=20.0,
            prompt_variant="compact",  # the 135M model copies the paper prompt's example
        ),
        AdvisorKind(
            "openai",
            _openai,
            label="any OpenAI-compatible server",
            server="https://api.openai.com/v1",
            batch_size=lambda cfg: 4 * cfg.advisor.openai_concurrency,
            check_key=_openai_key,
            model_setting="openai_model",
        ),
        AdvisorKind(
            "oracle",
            _oracle,
            label="oracle (not an LLM)",
            llm=False,
            # Its answer depends on the map, which the prompt does not hold; it costs nothing.
            cacheable=False,
            budgeted=False,
            batch_size=lambda cfg: 256,
            teacher_rate=lambda cfg: cfg.pare.oracle_teacher_rate,
            train_cost=1.3,
        ),
    )
}
"""The advisors this package brings."""

DEFAULT_ADVISOR = next(iter(BUILTIN))
"""The advisor commands ask when none is named: the embedded model (no key, no server)."""


def builtin_of_label(text: str) -> AdvisorKind | None:
    """The built-in advisor a recorded name or label (``oracle (not an LLM)``) names."""
    return next((k for k in BUILTIN.values() if text in (k.name, k.label)), None)


def _plugin_points() -> dict[str, EntryPoint]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def advisor_names() -> list[str]:
    """Every advisor name: the built-ins, then the installed plugins' (not imported)."""
    return [*BUILTIN, *sorted(set(_plugin_points()) - set(BUILTIN))]


@functools.cache
def _load_plugin(name: str) -> AdvisorKind:
    point = _plugin_points()[name]
    try:
        obj = point.load()
    except Exception as exc:  # noqa: BLE001 - any failure of a plugin's import is its own
        raise ConfigError(
            f"advisor plugin {name!r} ({point.value}) cannot be loaded: {type(exc).__name__}: {exc}"
        ) from None
    if isinstance(obj, AdvisorKind):
        return replace(obj, name=name)
    if not callable(obj):
        raise ConfigError(
            f"advisor plugin {name!r} ({point.value}) is neither a factory nor an AdvisorKind"
        )
    return AdvisorKind(name, obj, label=f"{name} (plugin {point.value})")


def find_advisor_kind(name: str) -> AdvisorKind | None:
    """The entry named ``name``, or None (a built-in shadows a plugin of the same name)."""
    if name in BUILTIN:
        return BUILTIN[name]
    if name in _plugin_points():
        return _load_plugin(name)
    return None


def advisor_kind(name: str) -> AdvisorKind:
    """The entry named ``name``; :class:`ConfigError` (one line, the known names) if none."""
    kind = find_advisor_kind(str(name))
    if kind is None:
        raise ConfigError(f"unknown advisor {name!r} (known: {', '.join(advisor_names())})")
    return kind


__all__ = [
    "BUILTIN",
    "DEFAULT_ADVISOR",
    "ENTRY_POINT_GROUP",
    "AdvisorKind",
    "advisor_kind",
    "advisor_names",
    "builtin_of_label",
    "find_advisor_kind",
]
