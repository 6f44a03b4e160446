"""PARE's alignment terms, for one world or a batch of worlds.

With ``dp = p_{t+1} - p_t`` and ``dq = (dx, dy, dz)`` of the advice:

- ``dir_align = cos(dp, dq)``, 0 when either vector is zero;
- ``pos_align = 1 - |p_{t+1} - (p_t + dq)| / d_max`` with ``d_max = |(X-1, Y-1, Z-1)|``;
- ``move = alpha * dir_align + (1 - alpha) * pos_align``;
- ``cam = -(|tilt - tilt_rec|/90 + |pan - pan_rec|/180 + |zoom - zoom_rec|/1.5) / 3``
  (the paper's L1 distance, each axis over its range, a penalty only);
- ``f_llm = lam_cam * cam + lam_move * move``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np

from pirl.advice.recommendation import Recommendation


@numba.njit(cache=True)
def _align_one(e, p_t, p_next, cam_next, rec, d_max, alpha, out):
    """Row e of ``out`` gets (dir_align, pos_align, move, cam) of world e."""
    dot = nq = ndp = dist = 0.0
    for k in range(3):
        dp = p_next[e, k] - p_t[e, k]
        dq = rec[e, 3 + k]
        dot += dp * dq
        ndp += dp * dp
        nq += dq * dq
        off = p_next[e, k] - (p_t[e, k] + dq)
        dist += off * off
    norms = np.sqrt(ndp) * np.sqrt(nq)
    dir_align = dot / norms if norms > 0.0 else 0.0
    # A one-cell world has d_max = 0: there only being on target counts.
    on_target = 1.0 if dist == 0.0 else 0.0
    pos_align = 1.0 - np.sqrt(dist) / d_max if d_max > 0.0 else on_target
    cam = (
        -(
            abs(cam_next[e, 0] - rec[e, 1]) / 90.0
            + abs(cam_next[e, 1] - rec[e, 0]) / 180.0
            + abs(cam_next[e, 2] - rec[e, 2]) / 1.5
        )
        / 3.0
    )
    out[e, 0] = dir_align
    out[e, 1] = pos_align
    out[e, 2] = alpha * dir_align + (1.0 - alpha) * pos_align
    out[e, 3] = cam


@numba.njit(cache=True)
def alignment_kernel(p_t, p_next, cam_next, rec, d_max, alpha, out):
    """Alignment terms of every world (rows of ``out``: dir_align, pos_align, move, cam)."""
    for e in range(p_t.shape[0]):
        _align_one(e, p_t, p_next, cam_next, rec, d_max, alpha, out)


def alignment_arrays(
    p_t: np.ndarray,
    p_next: np.ndarray,
    cam_next: np.ndarray,
    rec: np.ndarray,
    size: np.ndarray,
    alpha: float = 0.5,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batched terms: positions (N, 3), camera (N, 3) as (tilt, pan, zoom), advice (N, 6) as
    (pan, tilt, zoom, dx, dy, dz). Returns ``dir_align, pos_align, move, cam``, each (N,)."""
    out = np.empty((len(p_t), 4))
    d_max = float(np.linalg.norm(np.asarray(size, dtype=np.float64) - 1.0))
    alignment_kernel(
        np.asarray(p_t, dtype=np.float64),
        np.asarray(p_next, dtype=np.float64),
        np.asarray(cam_next, dtype=np.float64),
        np.asarray(rec, dtype=np.float64),
        d_max,
        float(alpha),
        out,
    )
    return out[:, 0], out[:, 1], out[:, 2], out[:, 3]


def alignment(
    p_t: Sequence[float],
    p_next: Sequence[float],
    cam_next: Sequence[float],
    rec: Recommendation,
    size: Sequence[int],
    alpha: float = 0.5,
) -> dict[str, float]:
    """The terms for one step: ``dir_align``, ``pos_align``, ``move`` and ``cam``.

    ``cam_next`` is the camera after the action as ``(tilt, pan, zoom)``; ``size`` is
    ``(X, Y, Z)``.
    """
    row = np.array([[rec.pan, rec.tilt, rec.zoom, rec.dx, rec.dy, rec.dz]], dtype=np.float64)
    terms = alignment_arrays(
        np.asarray([p_t], dtype=np.float64),
        np.asarray([p_next], dtype=np.float64),
        np.asarray([cam_next], dtype=np.float64),
        row,
        np.asarray(size, dtype=np.float64),
        alpha,
    )
    names = ("dir_align", "pos_align", "move", "cam")
    return {name: float(value[0]) for name, value in zip(names, terms, strict=True)}


def f_llm(terms: dict[str, float], lam_cam: float = 1.0, lam_move: float = 1.0) -> float:
    """The LLM reward term from the alignment terms."""
    return lam_cam * terms["cam"] + lam_move * terms["move"]
