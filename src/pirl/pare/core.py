"""PARE's pure core: one step's shaped rewards from the poses before and after it, the advice
each world holds and the weights (:mod:`pirl.pare.alignment`). No environment, no advisor.

Advice rows are ``(pan, tilt, zoom, dx, dy, dz)``; each world's advice metadata is
``(has advice, step it was asked at, kind)``. A world without advice gets ``f_llm = 0`` and
status ``missing``; with advice, its status says where the advice came from and how old it is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from pirl.config.choices import PareMode
from pirl.pare.alignment import _align_one

STATUSES = ("missing", "fresh", "cached", "stale", PareMode.STUDENT.value)
MISSING, FRESH, CACHED, STALE, STUDENT = range(5)
KIND_TEACHER, KIND_CACHED, KIND_STUDENT = 0, 1, 2
"""Where a world's advice came from (column KIND of the metadata)."""
HAS, STEP, KIND = 0, 1, 2
"""Columns of the advice metadata."""


@dataclass(frozen=True)
class Weights:
    """The weights of the LLM term (:mod:`pirl.pare.alignment`)."""

    lam_cam: float = 1.0
    """Weight of the camera alignment."""
    lam_move: float = 1.0
    """Weight of the move alignment."""
    alpha: float = 0.5
    """Direction vs position in the move alignment."""

    def constants(self, size: tuple[int, int, int]) -> np.ndarray:
        """The kernel's constants on a grid of ``size`` (X, Y, Z): d_max, alpha, lam_cam,
        lam_move (computed once per run, not per step)."""
        d_max = float(np.linalg.norm(np.asarray(size, dtype=np.float64) - 1.0))
        return np.array([d_max, self.alpha, self.lam_cam, self.lam_move])


@dataclass
class Shaped:
    """One step's PARE outcome per world."""

    table: np.ndarray
    """(N, 5): f_llm, dir_align, pos_align, move, cam (0 without advice)."""
    status: np.ndarray
    """(N,) index into :data:`STATUSES`."""
    staleness: np.ndarray
    """(N,) steps since the advice was asked (0 without advice)."""


@numba.njit(cache=True)
def _shape_kernel(p_t, pose, rec, meta, t, consts, table, marks):
    """Rows of ``table`` (f_llm and the alignment terms) and ``marks`` (status, staleness)
    of every world; ``pose`` rows are (x, y, z, tilt, pan, zoom tenths) after the step,
    ``consts`` = (d_max, alpha, lam_cam, lam_move)."""
    n = p_t.shape[0]
    p_next = np.empty((n, 3))
    cam_next = np.empty((n, 3))
    d_max, alpha, lam_cam, lam_move = consts[0], consts[1], consts[2], consts[3]
    for e in range(n):
        p_next[e, 0], p_next[e, 1], p_next[e, 2] = pose[e, 0], pose[e, 1], pose[e, 2]
        cam_next[e, 0], cam_next[e, 1], cam_next[e, 2] = pose[e, 3], pose[e, 4], pose[e, 5] / 10.0
        if meta[e, HAS] == 0:
            for k in range(5):
                table[e, k] = 0.0
            marks[e, 0], marks[e, 1] = MISSING, 0
            continue
        _align_one(e, p_t, p_next, cam_next, rec, d_max, alpha, table[:, 1:])
        table[e, 0] = lam_cam * table[e, 4] + lam_move * table[e, 3]
        staleness = t - meta[e, STEP]
        if meta[e, KIND] == KIND_STUDENT:
            status = STUDENT
        elif staleness > 0:
            status = STALE
        elif meta[e, KIND] == KIND_CACHED:
            status = CACHED
        else:
            status = FRESH
        marks[e, 0], marks[e, 1] = status, staleness


def shape(
    p_t: np.ndarray,
    pose: np.ndarray,
    rec: np.ndarray,
    meta: np.ndarray,
    t: int,
    consts: np.ndarray,
) -> Shaped:
    """The LLM term of one step for every world.

    ``p_t`` (N, 3) float64: positions before the step; ``pose`` (N, 6) int64: position and
    camera (tilt, pan, zoom tenths) after it; ``rec`` (N, 6) and ``meta`` (N, 3): the advice
    each world holds; ``t``: the step; ``consts``: :meth:`Weights.constants` of the grid.
    """
    n = len(p_t)
    table = np.empty((n, 5), dtype=np.float64)
    marks = np.empty((n, 2), dtype=np.int64)
    _shape_kernel(p_t, pose, rec, meta, t, consts, table, marks)
    return Shaped(table, marks[:, 0], marks[:, 1])


def add_llm_term(rewards: np.ndarray, f_llm: np.ndarray, llm_weight: np.ndarray) -> None:
    """``rewards += llm_weight * f_llm`` in the rewards' own precision."""
    rewards += (llm_weight * f_llm).astype(rewards.dtype)


__all__ = [
    "CACHED", "FRESH", "HAS", "KIND", "KIND_CACHED", "KIND_STUDENT", "KIND_TEACHER", "MISSING",
    "STALE", "STATUSES", "STEP", "STUDENT", "Shaped", "Weights", "add_llm_term", "shape",
]  # fmt: skip
