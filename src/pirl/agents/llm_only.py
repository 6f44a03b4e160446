"""LLM-only control: the advisor drives the UAV (the paper's LLM-only baseline).

Each answer becomes a queue of atomic actions, camera first (tilt, pan, zoom steps towards the
advised values, snapped to the camera grid), then the move (x, then y, then z). The advisor is
asked again when the queue is empty. An answer that fails or cannot be parsed, or asks for
nothing to change, yields one hover step (a camera action that changes nothing) and a new
question next step; such answers are counted. With ``max_calls`` the advisor is asked at most
that many times per episode; after that the UAV holds still (a budget for slow LLMs).
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from pirl.advice.base import Advisor
from pirl.advice.recommendation import Recommendation
from pirl.advice.state import advice_requests
from pirl.agents.policy import Policy, hold_action
from pirl.config import grid as g
from pirl.config.errors import ConfigError
from pirl.world import dynamics as D
from pirl.world.planning import WorldView
from pirl.world.state import WorldBatch

# For each axis x, y, z: the action that moves along it in the + and in the - direction.
_MOVE_ACTIONS = ((D.X_PLUS, D.X_MINUS), (D.Y_PLUS, D.Y_MINUS), (D.Z_PLUS, D.Z_MINUS))


def _snap(value: float, step: float, low: float, high: float) -> float:
    return min(high, max(low, round(value / step) * step))


def action_queue(camera: tuple[int, int, int], rec: Recommendation) -> list[int]:
    """Atomic actions for one recommendation from ``camera`` = (tilt, pan, zoom10)."""
    tilt, pan, zoom10 = camera
    want_tilt = int(_snap(rec.tilt, g.TILT_STEP, g.TILT_MIN, g.TILT_MAX))
    want_pan = int(_snap(rec.pan, g.PAN_STEP, g.PAN_MIN, g.PAN_MAX))
    want_zoom = round(_snap(rec.zoom * 10, g.ZOOM_STEP10, g.ZOOM_MIN10, g.ZOOM_MAX10))
    queue: list[int] = []
    tilts = abs(want_tilt - tilt) // g.TILT_STEP
    pans = abs(want_pan - pan) // g.PAN_STEP
    zooms = abs(want_zoom - zoom10) // g.ZOOM_STEP10
    queue += [D.TILT_PLUS if want_tilt > tilt else D.TILT_MINUS] * tilts
    queue += [D.PAN_PLUS if want_pan > pan else D.PAN_MINUS] * pans
    queue += [D.ZOOM_PLUS if want_zoom > zoom10 else D.ZOOM_MINUS] * zooms
    for axis, delta in enumerate((rec.dx, rec.dy, rec.dz)):
        if delta:
            queue.append(_MOVE_ACTIONS[axis][0 if delta > 0 else 1])
    return queue


class LLMOnlyPolicy(Policy):
    """The advisor's answers, executed as action queues."""

    name = "llm-only"

    @classmethod
    def build(
        cls,
        seed: int | None = None,
        advisor: Advisor | None = None,
        prompt_variant: str = "paper",
        max_calls: int = 0,
    ) -> LLMOnlyPolicy:
        if advisor is None:
            raise ConfigError("llm-only needs an advisor")
        return cls(advisor, prompt_variant, max_calls=max_calls)

    def __init__(self, advisor: Advisor, prompt_variant: str = "paper", max_calls: int = 0) -> None:
        self.advisor = advisor
        self.prompt_variant = prompt_variant
        self.max_calls = max_calls
        self.episode_calls = 0
        self.label = f"LLM-only ({advisor.label})"
        self.queue: list[int] = []
        self.counts = Counter()  # shared by a fleet's teammates (:meth:`teammate`)

    def teammate(self) -> LLMOnlyPolicy:
        """Another UAV's LLM-only in a fleet: the same advisor and budget per episode (its own
        ``max_calls``), counted with this one's calls."""
        mate = LLMOnlyPolicy(self.advisor, self.prompt_variant, self.max_calls)
        mate.counts = self.counts
        return mate

    @property
    def calls(self) -> int:
        """Advisor calls so far (every teammate's)."""
        return self.counts["calls"]

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        self.world, self.e = world, index
        self.queue = []
        self.episode_calls = 0

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        budget_left = not self.max_calls or self.episode_calls < self.max_calls
        if not self.queue and budget_left:
            self.episode_calls += 1
            prompts, views = advice_requests(
                self.world, [self.e], self.advisor, self.prompt_variant
            )
            self.counts["calls"] += 1
            answer = self.advisor.advise(prompts, views)[0]
            if answer.recommendation is None:
                self.counts["failed"] += 1
            else:
                view = WorldView.of(self.world, self.e)
                self.queue = action_queue(view.camera, answer.recommendation)
                if not self.queue:
                    self.counts["empty"] += 1
        if self.queue:
            return self.queue.pop(0)
        return hold_action(WorldView.of(self.world, self.e).camera)

    def stats(self) -> dict[str, int]:
        """Advisor calls, failed or unparseable answers, and answers that asked for nothing."""
        return {key: self.counts[key] for key in ("calls", "failed", "empty")}
