"""What an advisor is shown about a world: its prompt, and for advisors that plan from the map
(the oracle) a frozen :class:`~pirl.world.planning.WorldView`.

PARE, the student's teacher queue, LLM-only and ``pirl advise`` all build their requests here,
so every caller shows an advisor the same thing.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from pirl.advice.prompt import TEMPLATE_PREFIX, PromptState, build_prompt
from pirl.world.planning import WorldView
from pirl.world.state import WorldBatch


def prompt_state(world: WorldBatch, e: int) -> PromptState:
    """The :class:`~pirl.advice.prompt.PromptState` of world ``e`` now."""
    return view_prompt_state(WorldView.of(world, e))


def view_prompt_state(view: WorldView, maps: bool = False) -> PromptState:
    """The :class:`~pirl.advice.prompt.PromptState` of a world's :class:`WorldView`; with
    ``maps``, its text maps too (:func:`text_maps`: only templates show them)."""
    cfg = view.cfg
    # Views are booked on coverable cells only, so the seen cells are the covered ones.
    coverable = int(np.count_nonzero(view.coverable))
    covered = int(np.count_nonzero(view.views))
    obstacles = tuple(
        (float(cx), float(cy), float(cz), float(r)) for cx, cy, cz, r in view.obstacles
    )
    tilt, pan, zoom10 = view.camera
    local, coarse = text_maps(view) if maps else ("", "")
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
        local_map=local,
        coarse_map=coarse,
        buildings=buildings_near(view) if cfg.site else "",
        teammates=tuple((int(x), int(y), int(z), float(b)) for x, y, z, b in view.teammates),
    )


BUILDINGS_RADIUS = 4
"""Cells round the UAV whose blocked columns a site's prompt lists."""
BUILDINGS_MAX = 24
"""Most columns a site's prompt lists (the nearest)."""


def buildings_near(view: WorldView) -> str:
    """The blocked columns within :data:`BUILDINGS_RADIUS` of the UAV as ``x,y:n`` (blocked
    from the ground through n levels; a no-fly column through every level), nearest first:
    a few short tokens a small model can read, where listing a site's voxels would not fit."""
    x, y, _ = (int(v) for v in view.position)
    sx, sy, _ = view.blocked.shape
    r = BUILDINGS_RADIUS
    x0, x1, y0, y1 = max(0, x - r), min(sx, x + r + 1), max(0, y - r), min(sy, y + r + 1)
    window = view.blocked[x0:x1, y0:y1]
    levels = window.sum(axis=2)
    cells = [
        (abs(i + x0 - x) + abs(j + y0 - y), i + x0, j + y0, int(levels[i, j]))
        for i, j in zip(*np.nonzero(levels), strict=True)
    ]
    cells.sort()
    return " ".join(f"{i},{j}:{n}" for _, i, j, n in cells[:BUILDINGS_MAX]) or "none"


def text_maps(view: WorldView) -> tuple[str, str]:
    """The two maps a prompt template may show (``local_map``, ``coarse_map`` of
    :class:`~pirl.advice.prompt.PromptState`): the window of ``env.obs_window`` cells round the
    UAV at its altitude (``U`` it, ``#`` blocked, ``o`` seen, ``.`` not yet, blank off the
    grid) and the grid in ``env.obs_global`` blocks a side, one digit per block for the tenths
    of its coverable cells seen (``#``: a block with none); both with the highest y on top."""
    cfg = view.cfg
    sx, sy, _ = cfg.size
    x0, y0, z0 = (int(v) for v in view.position)
    half = cfg.obs_window // 2
    seen = view.views > 0
    rows = []
    for y in range(y0 + half, y0 - half - 1, -1):
        row = []
        for x in range(x0 - half, x0 + half + 1):
            if not (0 <= x < sx and 0 <= y < sy):
                row.append(" ")
            elif (x, y) == (x0, y0):
                row.append("U")
            elif view.blocked[x, y, z0]:
                row.append("#")
            else:
                row.append("o" if seen[x, y] else ".")
        rows.append("".join(row).rstrip())
    g = cfg.obs_global
    bx, by = np.arange(sx) * g // sx, np.arange(sy) * g // sy
    total = np.zeros((g, g))
    done = np.zeros((g, g))
    np.add.at(total, (bx[:, None], by[None, :]), view.coverable)
    np.add.at(done, (bx[:, None], by[None, :]), seen & view.coverable)
    share = np.divide(done, total, out=np.zeros_like(done), where=total > 0)
    digits = np.minimum(9, (share * 10).astype(int))
    cell = [[str(digits[i, j]) if total[i, j] else "#" for j in range(g)] for i in range(g)]
    coarse = ["".join(cell[i][j] for i in range(g)) for j in range(g - 1, -1, -1)]
    return "\n".join(rows), "\n".join(coarse)


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
    maps = prompt_variant.startswith(TEMPLATE_PREFIX)
    prompts = [build_prompt(view_prompt_state(v, maps), prompt_variant, decimals) for v in views]
    return prompts, (list(views) if getattr(advisor, "wants_view", False) else None)


__all__ = [
    "advice_requests",
    "prompt_state",
    "text_maps",
    "view_prompt_state",
    "view_requests",
]
