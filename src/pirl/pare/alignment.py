"""PARE's alignment terms (DESIGN.md section 5), for one world or a batch of worlds.

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

import numpy as np

from pirl.advice.recommendation import Recommendation


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
    p_t = np.asarray(p_t, dtype=np.float64)
    p_next = np.asarray(p_next, dtype=np.float64)
    cam_next = np.asarray(cam_next, dtype=np.float64)
    rec = np.asarray(rec, dtype=np.float64)
    dp = p_next - p_t
    dq = rec[:, 3:6]
    norms = np.linalg.norm(dp, axis=1) * np.linalg.norm(dq, axis=1)
    dots = (dp * dq).sum(axis=1)
    dir_align = np.divide(dots, norms, out=np.zeros_like(dots), where=norms > 0)
    d_max = float(np.linalg.norm(np.asarray(size, dtype=np.float64) - 1.0))
    miss = np.linalg.norm(p_next - (p_t + dq), axis=1)
    # A 1x1x1 grid has d_max = 0: the advised cell is either reached (1) or not (0).
    pos_align = 1.0 - miss / d_max if d_max > 0 else (miss == 0.0).astype(np.float64)
    move = alpha * dir_align + (1.0 - alpha) * pos_align
    cam = (
        -(
            np.abs(cam_next[:, 0] - rec[:, 1]) / 90.0
            + np.abs(cam_next[:, 1] - rec[:, 0]) / 180.0
            + np.abs(cam_next[:, 2] - rec[:, 2]) / 1.5
        )
        / 3.0
    )
    return dir_align, pos_align, move, cam


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
