"""The oracle advisor: geometric advice in the LLM's answer format. Not an LLM.

It reads the true map (which the prompt does not carry), so it is an upper-bound ablation that
shows what good advice does to PIRL. It recommends the camera with the largest footprint and
the first move of a shortest free path to the nearest place whose view would add uncovered
ground. Every report labels it "oracle (not an LLM)".
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.recommendation import Recommendation
from pirl.world.planning import WorldView, largest_footprint_camera, nearest, useful_map

ORACLE_LABEL = "oracle (not an LLM)"


def oracle_recommendation(view: WorldView) -> Recommendation:
    """The oracle's advice for one world state."""
    camera, altitude = largest_footprint_camera(view)
    x, y, z = view.position
    useful = useful_map(view, camera, altitude)
    dx = dy = dz = 0
    if z != altitude:
        dz = 1 if altitude > z else -1
    else:
        path = nearest(view, view.position, lambda c: c[2] == altitude and useful[c[0], c[1]])
        if path and len(path) >= 2:
            dx, dy, dz = (b - a for a, b in zip(path[0], path[1], strict=True))
    tilt, pan, zoom10 = camera
    return Recommendation(pan=pan, tilt=tilt, zoom=zoom10 / 10.0, dx=dx, dy=dy, dz=dz)


NO_VIEW = "the oracle plans from the map: it needs a world view with each prompt"


class OracleAdvisor(Advisor):
    """Advice computed from the map (one :class:`WorldView` per prompt)."""

    name = "oracle"
    model = "geometric"
    label = ORACLE_LABEL
    wants_view = True

    def settings_key(self) -> str:
        return "oracle-v1"

    def advise(self, prompts: list[str], views: Sequence[WorldView] | None = None) -> list[Answer]:
        """The oracle's answer for each view; an error answer where a prompt has none."""
        if views is None or len(views) != len(prompts):
            return [error_answer(NO_VIEW) for _ in prompts]
        answers = []
        for view in views:
            start = time.perf_counter()
            rec = oracle_recommendation(view)
            answers.append(Answer(rec.to_text(), rec, latency_s=time.perf_counter() - start))
        return answers
