"""Advisor health: one probe call before training, so a dead server fails in one line.

The probe bypasses the answer cache and the budget (a cached answer proves nothing about the
server, and a probe is not advice): it asks the backend itself about the first state of one
scenario of the training world.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlparse

from pirl.advice.base import Advisor, Answer
from pirl.advice.registry import advisor_kind, find_advisor_kind
from pirl.advice.state import advice_requests
from pirl.config.errors import UserError
from pirl.config.presets import load_preset
from pirl.config.run import RunConfig
from pirl.config.world import VCPPConfig


def backend_of(advisor: Any) -> Any:
    """The innermost advisor under any cache and budget layers."""
    while getattr(advisor, "inner", None) is not None:
        advisor = advisor.inner
    return advisor


def default_server(advisor: Any) -> str:
    """The server URL an advisor's registry entry names (empty: it answers in-process)."""
    kind = find_advisor_kind(str(getattr(backend_of(advisor), "name", "")))
    return kind.server if kind is not None else ""


def location(advisor: Any) -> str:
    """The server URL an advisor asks, or its model (folder) when it runs here."""
    backend = backend_of(advisor)
    if default_server(backend):
        return str(getattr(backend, "base_url", None) or default_server(backend))
    model_dir = getattr(backend, "model_dir", None)
    return str(model_dir) if model_dir else f"model {backend.model}"


def where(advisor: Any) -> str:
    """The server URL or model an advisor talks to, for error messages."""
    backend = backend_of(advisor)
    url = getattr(backend, "base_url", None)
    if default_server(backend):
        return f"model {backend.model} at {url or urlparse(default_server(backend)).netloc}"
    if hasattr(backend, "model_dir"):
        return f"model {backend.model_dir}"
    return f"model {backend.model}"


def advise_within(
    advisor: Advisor, prompts: list[str], views: Any, timeout_s: float
) -> list[Answer] | None:
    """``advisor.advise(prompts, views)``, or None when it has not answered in ``timeout_s``.

    The call runs in a daemon thread: a server that accepts the connection and never answers
    cannot hold the caller (nor, at exit, the interpreter) past the deadline.
    """
    box: dict[str, Any] = {}

    def call() -> None:
        try:
            box["answers"] = advisor.advise(prompts, views)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
            box["error"] = exc

    thread = threading.Thread(target=call, name="pirl-probe", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        return None
    if "error" in box:
        raise box["error"]
    return box["answers"]


def probe(
    advisor: Advisor,
    env_cfg: VCPPConfig,
    prompt_variant: str = "paper",
    timeout_s: float = 30.0,
    log: Callable[[str], Any] | None = None,
) -> Answer:
    """Ask the backend about one state; raise :class:`UserError` (one line) if the call fails
    or gives no answer within ``timeout_s`` (``log`` gets a "probing ..." line first).

    An answer that does not parse is returned (the run counts such answers); only a failed call
    (unreachable server, refused key, missing model, a server that never answers) stops here.
    """
    from pirl.env.vcpp_env import VCPPEnv

    backend = backend_of(advisor)
    env = VCPPEnv(env_cfg.replace(llm_weight=False))
    env.reset(seed=0)
    prompts, views = advice_requests(env.world, [0], backend, prompt_variant)
    if log is not None and default_server(backend):  # a server: the one that may hang
        log(f"probing {advisor.label} at {location(advisor)} (up to {timeout_s:g} s)...")
    try:
        answers = advise_within(backend, prompts, views, timeout_s)
    except Exception as exc:  # noqa: BLE001 - an advisor must not raise; say what it did
        raise UserError(
            f"advisor {advisor.label} ({where(advisor)}) failed its probe call: "
            f"{type(exc).__name__}: {exc}"
        ) from None
    if answers is None:
        raise UserError(
            f"advisor {advisor.label} ({where(advisor)}) gave no answer to its probe call "
            f"within {timeout_s:g} s (advisor.probe_timeout_s); check that the server is "
            "serving, or raise the timeout for a slow one"
        )
    answer = answers[0]
    if answer.error is not None:
        first = answer.error.strip().splitlines()[0] if answer.error.strip() else "no answer"
        raise UserError(
            f"advisor {advisor.label} ({where(advisor)}) failed its probe call: {first}; "
            "check the server, the model name and the API key (pirl advise tests a set-up)"
        )
    return answer


@dataclass
class AdviceCheck:
    """What ``pirl advise`` shows: the prompt, the answer and how long set-up took."""

    label: str
    """The advisor's label (with its model)."""
    prompt: str
    """The prompt of the scenario's first state."""
    answer: Answer
    """The advisor's answer (from the cache when it held one)."""
    setup_s: float
    """Seconds to build the advisor (loading a model, connecting)."""


def advise_settings(
    config: str | None, name: str, model: str | None = None, base_url: str | None = None
) -> RunConfig:
    """The settings ``pirl advise`` asks advisor ``name`` with: ``config``'s preset (none: the
    prompt variant the advisor suits), its key checked unless ``base_url`` names a server, and
    ``model`` and ``base_url`` applied."""
    kind = advisor_kind(name)
    if config:
        cfg = load_preset(config)
    else:  # no config: the prompt this advisor suits (the embedded model: compact)
        cfg = RunConfig().with_overrides(pare={"prompt_variant": kind.prompt_variant})
    if base_url is None:
        kind.check_key(cfg)
    changes: dict[str, Any] = {}
    if model is not None and kind.model_setting:
        changes[kind.model_setting] = model
    if base_url is not None:
        changes["openai_base_url"] = base_url
    return cfg.with_overrides(advisor=changes) if changes else cfg


def check_advisor(
    cfg: Any,
    name: str,
    size: tuple[int, int, int],
    seed: int = 0,
    cache: bool = True,
    show_prompt: Callable[[str], Any] | None = None,
    log: Callable[[str], Any] | None = None,
) -> AdviceCheck:
    """Ask advisor ``name`` (cache in front when ``cache``) about the first state of scenario
    ``seed`` of a ``size`` world: the check to run first on a new LLM.

    ``show_prompt`` sees the prompt before the question is asked; ``log`` gets an "asking
    ..." line for an advisor on a server. An advisor that gives no answer within
    ``advisor.probe_timeout_s`` is a :class:`UserError` (one line).
    """
    from pirl.advice.factory import make_advisor
    from pirl.env.vcpp_env import VCPPEnv

    env = VCPPEnv(cfg.env.replace(size=tuple(size)))
    env.reset(seed=seed)
    start = time.perf_counter()
    advisor = make_advisor(name, cfg, cache=cache)
    setup_s = time.perf_counter() - start
    prompts, views = advice_requests(env.world, [0], advisor, cfg.pare.prompt_variant)
    if show_prompt is not None:
        show_prompt(prompts[0])
    limit = cfg.advisor.probe_timeout_s
    if log is not None and default_server(advisor):
        log(f"asking {advisor.label} at {location(advisor)} (up to {limit:g} s)...")
    answers = advise_within(advisor, prompts, views, limit)
    if answers is None:
        # Not closed: closing may wait for the call that hangs; the daemon thread ends with us.
        raise UserError(
            f"advisor {advisor.label} ({location(advisor)}) gave no answer within "
            f"{limit:g} s (advisor.probe_timeout_s); check that the server is serving"
        )
    advisor.close()
    return AdviceCheck(advisor.label, prompts[0], answers[0], setup_s)


__all__ = [
    "AdviceCheck",
    "advise_settings",
    "advise_within",
    "backend_of",
    "check_advisor",
    "default_server",
    "location",
    "probe",
    "where",
]
