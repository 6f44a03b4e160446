"""How PARE asks an advisor about worlds: their prompts, and frozen views for advisors that
plan from the map, read through the environment's public shaping hooks."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pirl.advice.state import view_requests
from pirl.env.shaping import ShapingHooks
from pirl.world.planning import WorldView


def requests(
    env: ShapingHooks,
    worlds: Sequence[int],
    advisor: Any,
    prompt_variant: str = "paper",
    decimals: int = 2,
) -> tuple[list[str], list[WorldView] | None]:
    """Prompts for ``worlds`` now, plus frozen views when ``advisor.wants_view``; pass both
    to ``advisor.advise(prompts, views)``."""
    copy = bool(getattr(advisor, "wants_view", False))
    return view_requests(env.world_views(worlds, copy=copy), advisor, prompt_variant, decimals)


__all__ = ["requests"]
