"""The oracle advisor: geometric advice in the LLM's answer format. Not an LLM.

It reads the true map (which the prompt does not carry), so it is an upper-bound ablation that
shows what good advice does to PIRL. It recommends the camera with the largest footprint and
the first move of a shortest free path to the nearest place whose view would add uncovered
ground. Every report labels it "oracle (not an LLM)".

``accuracy`` below 1 makes it a *degradable* oracle, a stand-in for an imperfect LLM: for each
state, with probability ``1 - accuracy``, its answer is replaced by one drawn uniformly from
every valid answer (a camera pose on the grid and one of the seven moves). The draw is seeded
by the prompt, so one state always gets one answer, as from an LLM at temperature 0, and
caches and students stay consistent. Its label says the accuracy.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Sequence

import numpy as np

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.recommendation import Recommendation
from pirl.config import grid
from pirl.world.planning import WorldView, claims, largest_footprint_camera, nearest, useful_map

ORACLE_LABEL = "oracle (not an LLM)"


def oracle_recommendation(view: WorldView) -> Recommendation:
    """The oracle's advice for one world state.

    In a fleet (the view has teammates) it never sends two UAVs to the same ground: each
    useful place belongs to the UAV nearest to it by moves (:func:`claims`), and a UAV is led
    to the nearest useful place of its own; only when it has none left, to the nearest of any.
    Its path goes round the cells teammates hold."""
    camera, altitude = largest_footprint_camera(view)
    x, y, z = view.position
    useful = useful_map(view, camera, altitude)
    dx = dy = dz = 0
    if z != altitude:
        dz = 1 if altitude > z else -1
    else:
        path = None
        if view.teammates.size:
            mine = claims(view) == view.rank
            path = nearest(
                view, view.position,
                lambda c: c[2] == altitude and useful[c[0], c[1]] and mine[c],
            )  # fmt: skip
        if path is None:
            path = nearest(view, view.position, lambda c: c[2] == altitude and useful[c[0], c[1]])
        if path and len(path) >= 2:
            dx, dy, dz = (b - a for a, b in zip(path[0], path[1], strict=True))
    tilt, pan, zoom10 = camera
    return Recommendation(pan=pan, tilt=tilt, zoom=zoom10 / 10.0, dx=dx, dy=dy, dz=dz)


MOVES: tuple[tuple[int, int, int], ...] = (
    (0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1),
)  # fmt: skip
"""Every move an answer may advise: hold, or one cell along one axis."""


def random_recommendation(rng: np.random.Generator) -> Recommendation:
    """A valid answer drawn uniformly: camera pose on the grid, then one of :data:`MOVES`."""
    pan = grid.pan_steps()[int(rng.integers(len(grid.pan_steps())))]
    tilt = grid.tilt_steps()[int(rng.integers(len(grid.tilt_steps())))]
    zoom = grid.zoom_steps()[int(rng.integers(len(grid.zoom_steps())))]
    dx, dy, dz = MOVES[int(rng.integers(len(MOVES)))]
    return Recommendation(pan=float(pan), tilt=float(tilt), zoom=zoom, dx=dx, dy=dy, dz=dz)


def degraded(rec: Recommendation, prompt: str, accuracy: float) -> Recommendation:
    """``rec`` kept with probability ``accuracy``, else a uniform valid answer; both draws are
    seeded by ``prompt`` alone (one state, one answer)."""
    if accuracy >= 1.0:
        return rec
    digest = hashlib.sha256(prompt.encode()).digest()
    rng = np.random.default_rng(int.from_bytes(digest[:8], "little"))
    return rec if rng.random() < accuracy else random_recommendation(rng)


def oracle_label(accuracy: float = 1.0) -> str:
    """How reports name the oracle: ``oracle (not an LLM)``, or ``oracle, accuracy 0.5 (not
    an LLM)`` when degraded."""
    return ORACLE_LABEL if accuracy >= 1.0 else f"oracle, accuracy {accuracy:g} (not an LLM)"


NO_VIEW = "the oracle plans from the map: it needs a world view with each prompt"


class OracleAdvisor(Advisor):
    """Advice computed from the map (one :class:`WorldView` per prompt)."""

    name = "oracle"
    model = "geometric"
    label = ORACLE_LABEL
    wants_view = True
    accuracy = 1.0
    """Share of states answered with the oracle's own advice (a class default, so a subclass
    with an ``__init__`` of its own is the oracle itself)."""

    def __init__(self, accuracy: float = 1.0) -> None:
        if not 0.0 <= accuracy <= 1.0:
            raise ValueError(f"accuracy must be in [0, 1], got {accuracy}")
        self.accuracy = float(accuracy)
        self.label = oracle_label(self.accuracy)

    def settings_key(self) -> str:
        return "oracle-v1" if self.accuracy >= 1.0 else f"oracle-v1-accuracy-{self.accuracy:g}"

    def advise(self, prompts: list[str], views: Sequence[WorldView] | None = None) -> list[Answer]:
        """The oracle's answer for each view; an error answer where a prompt has none."""
        if views is None or len(views) != len(prompts):
            return [error_answer(NO_VIEW) for _ in prompts]
        answers = []
        for prompt, view in zip(prompts, views, strict=True):
            start = time.perf_counter()
            rec = degraded(oracle_recommendation(view), prompt, self.accuracy)
            answers.append(Answer(rec.to_text(), rec, latency_s=time.perf_counter() - start))
        return answers
