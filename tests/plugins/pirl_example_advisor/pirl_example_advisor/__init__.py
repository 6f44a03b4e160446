"""An example advisor plugin: it always recommends the camera at its widest and a move east.

Not good advice, only a whole one: it shows the contract a plugin fulfils (``make_advisor``,
the entry point, returns an object with the :class:`pirl.advice.base.Advisor` contract).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pirl.advice.base import Advisor, Answer
from pirl.advice.recommendation import Recommendation


class SteadyAdvisor(Advisor):
    """The same recommendation for every prompt, in the LLM answer format."""

    name = "example"
    model = "steady"
    label = "example:steady"

    def settings_key(self) -> str:
        return "steady-v1"

    def advise(self, prompts: list[str], views: Sequence[Any] | None = None) -> list[Answer]:
        rec = Recommendation(pan=0, tilt=75, zoom=1.8, dx=1, dy=0, dz=0)
        return [Answer(rec.to_text(), rec) for _ in prompts]


def make_advisor(cfg: Any) -> Advisor:
    """The entry point: PIRL's run config in, an advisor out."""
    return SteadyAdvisor()
