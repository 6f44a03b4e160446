"""Advisor health: one probe call before training, so a dead server fails in one line.

The probe bypasses the answer cache and the budget (a cached answer proves nothing about the
server, and a probe is not advice): it asks the backend itself about the first state of one
scenario of the training world.
"""

from __future__ import annotations

from typing import Any

from pirl.advice.base import Advisor, Answer
from pirl.advice.state import advice_requests
from pirl.world.config import UserError


def backend_of(advisor: Any) -> Any:
    """The innermost advisor under any cache and budget layers."""
    while getattr(advisor, "inner", None) is not None:
        advisor = advisor.inner
    return advisor


def where(advisor: Any) -> str:
    """The server URL or model an advisor talks to, for error messages."""
    backend = backend_of(advisor)
    url = getattr(backend, "base_url", None)
    if backend.name == "openai":
        return f"model {backend.model} at {url or 'api.openai.com'}"
    if hasattr(backend, "model_dir"):
        return f"model {backend.model_dir}"
    return f"model {backend.model}"


def probe(advisor: Advisor, env_cfg: Any, prompt_variant: str = "paper") -> Answer:
    """Ask the backend about one state; raise :class:`UserError` (one line) if the call fails.

    An answer that does not parse is returned (the run counts such answers); only a failed call
    (unreachable server, refused key, missing model) stops here.
    """
    from pirl.env.vcpp_env import VCPPEnv

    backend = backend_of(advisor)
    env = VCPPEnv(env_cfg.replace(llm_weight=False))
    env.reset(seed=0)
    prompts, views = advice_requests(env.world, [0], backend, prompt_variant)
    try:
        answer = backend.advise(prompts, views)[0]
    except Exception as exc:  # noqa: BLE001 - an advisor must not raise; say what it did
        raise UserError(
            f"advisor {advisor.label} ({where(advisor)}) failed its probe call: "
            f"{type(exc).__name__}: {exc}"
        ) from None
    if answer.error is not None:
        first = answer.error.strip().splitlines()[0] if answer.error.strip() else "no answer"
        raise UserError(
            f"advisor {advisor.label} ({where(advisor)}) failed its probe call: {first}; "
            "check the server, the model name and the API key (pirl advise tests a set-up)"
        )
    return answer


__all__ = ["backend_of", "probe", "where"]
