"""What an advisor is shown about a world: its prompt, and for advisors that plan from the map
(the oracle) a frozen :class:`~pirl.world.planning.WorldView`.

PARE, the student's teacher queue, LLM-only and ``pirl advise`` all build their requests here,
so every caller shows an advisor the same thing.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from pirl.advice.prompt import PromptState, build_prompt
from pirl.world.planning import WorldView
from pirl.world.state import WorldBatch


def prompt_state(world: WorldBatch, e: int) -> PromptState:
    """The :class:`~pirl.advice.prompt.PromptState` of world ``e`` now."""
    return view_prompt_state(WorldView.of(world, e))


def view_prompt_state(view: WorldView) -> PromptState:
    """The :class:`~pirl.advice.prompt.PromptState` of a world's :class:`WorldView`."""
    cfg = view.cfg
    # Views are booked on coverable cells only, so the seen cells are the covered ones.
    coverable = int(np.count_nonzero(view.coverable))
    covered = int(np.count_nonzero(view.views))
    obstacles = tuple(
        (float(cx), float(cy), float(cz), float(r)) for cx, cy, cz, r in view.obstacles
    )
    tilt, pan, zoom10 = view.camera
    return PromptState(
        position=tuple(int(v) for v in view.position),
        tilt=int(tilt),
        pan=int(pan),
        zoom=int(zoom10) / 10.0,
        battery=max(0.0, float(view.energy) / float(cfg.capacity)),
        coverage=covered / coverable if coverable else 1.0,
        size=cfg.size,
        footprint=cfg.footprint,
        fov_deg=cfg.fov_deg,
        obstacles=obstacles,
        max_range=cfg.max_range,
    )


def advice_requests(
    world: WorldBatch,
    worlds: Iterable[int],
    advisor: Any,
    prompt_variant: str = "paper",
    decimals: int = 2,
) -> tuple[list[str], list[WorldView] | None]:
    """Prompts for ``worlds`` now, plus frozen world views when ``advisor.wants_view``.

    Pass both to ``advisor.advise(prompts, views)``.
    """
    copy = bool(getattr(advisor, "wants_view", False))
    views = [WorldView.of(world, int(e), copy=copy) for e in worlds]
    return view_requests(views, advisor, prompt_variant, decimals)


def view_requests(
    views: Sequence[WorldView], advisor: Any, prompt_variant: str = "paper", decimals: int = 2
) -> tuple[list[str], list[WorldView] | None]:
    """Prompts for worlds seen through their views, plus the views themselves when
    ``advisor.wants_view`` (then they must be frozen copies: the advisor reads them later,
    in another thread)."""
    prompts = [build_prompt(view_prompt_state(v), prompt_variant, decimals) for v in views]
    return prompts, (list(views) if getattr(advisor, "wants_view", False) else None)


__all__ = ["advice_requests", "prompt_state", "view_prompt_state", "view_requests"]
