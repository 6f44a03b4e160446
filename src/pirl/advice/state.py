"""What PARE shows the advisor: a world's state as a prompt (and, for the oracle, its map)."""

from __future__ import annotations

from pirl.advice.prompt import PromptState
from pirl.world import dynamics as D
from pirl.world.state import WorldBatch


def prompt_state(world: WorldBatch, e: int) -> PromptState:
    """The :class:`~pirl.advice.prompt.PromptState` of world ``e`` now."""
    row = world.ints[e]
    cfg = world.cfg
    coverable = int(row[D.COVERABLE])
    obstacles = tuple(
        (float(cx), float(cy), float(cz), float(r)) for cx, cy, cz, r in world.obstacle_list(e)
    )
    return PromptState(
        position=(int(row[D.PX]), int(row[D.PY]), int(row[D.PZ])),
        tilt=int(row[D.TILT]),
        pan=int(row[D.PAN]),
        zoom=int(row[D.ZOOM]) / 10.0,
        battery=world.battery(e),
        coverage=int(row[D.COVERED]) / coverable if coverable else 1.0,
        size=cfg.size,
        footprint=cfg.footprint,
        fov_deg=cfg.fov_deg,
        obstacles=obstacles,
        max_range=cfg.max_range,
    )
