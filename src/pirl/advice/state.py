"""What an advisor is shown about a world: its prompt, and for advisors that plan from the map
(the oracle) a frozen :class:`~pirl.world.planning.WorldView`.

PARE, the student's teacher queue, LLM-only and ``pirl advise`` all build their requests here,
so every caller shows an advisor the same thing.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from pirl.advice.prompt import PromptState, build_prompt
from pirl.world.planning import WorldView
from pirl.world.state import WorldBatch


def prompt_state(world: WorldBatch, e: int) -> PromptState:
    """The :class:`~pirl.advice.prompt.PromptState` of world ``e`` now."""
    row = world.status[e]
    cfg = world.cfg
    coverable = int(row["coverable"])
    obstacles = tuple(
        (float(cx), float(cy), float(cz), float(r)) for cx, cy, cz, r in world.obstacle_list(e)
    )
    return PromptState(
        position=world.position(e),
        tilt=int(row["tilt"]),
        pan=int(row["pan"]),
        zoom=int(row["zoom10"]) / 10.0,
        battery=world.battery(e),
        coverage=int(row["covered"]) / coverable if coverable else 1.0,
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
    indices = [int(e) for e in worlds]
    prompts = [build_prompt(prompt_state(world, e), prompt_variant, decimals) for e in indices]
    views = None
    if getattr(advisor, "wants_view", False):
        views = [WorldView.of(world, e, copy=True) for e in indices]
    return prompts, views


__all__ = ["advice_requests", "prompt_state"]
