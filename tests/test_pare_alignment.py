"""PARE alignment terms (docs/architecture.md, one training step), computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pirl.advice.recommendation import Recommendation
from pirl.pare.alignment import alignment, alignment_arrays, f_llm

SIZE = (15, 15, 3)
D_MAX = math.sqrt(14**2 + 14**2 + 2**2)  # |(X-1, Y-1, Z-1)| = sqrt(396)


def rec(dx=0, dy=0, dz=0, pan=0.0, tilt=90.0, zoom=1.0) -> Recommendation:
    return Recommendation(pan=pan, tilt=tilt, zoom=zoom, dx=dx, dy=dy, dz=dz)


def test_followed_advice() -> None:
    t = alignment((3, 4, 1), (2, 4, 1), (90, 0, 1.0), rec(dx=-1), SIZE)
    assert t["dir_align"] == pytest.approx(1.0)
    assert t["pos_align"] == pytest.approx(1.0)
    assert t["move"] == pytest.approx(1.0)
    assert t["cam"] == 0.0
    assert f_llm(t) == pytest.approx(1.0)


def test_opposite_move() -> None:
    t = alignment((3, 4, 1), (4, 4, 1), (90, 0, 1.0), rec(dx=-1), SIZE)
    assert t["dir_align"] == pytest.approx(-1.0)
    # Reached (4, 4, 1), advised (2, 4, 1): 2 cells off.
    assert t["pos_align"] == pytest.approx(1 - 2 / D_MAX)
    assert t["move"] == pytest.approx(0.5 * -1 + 0.5 * (1 - 2 / D_MAX))


def test_diagonal_advice_and_axis_move() -> None:
    # dq = (1, 1, 0), dp = (1, 0, 0): cos = 1/sqrt(2); miss = |(4,4,1)-(4,5,1)| = 1.
    t = alignment((3, 4, 1), (4, 4, 1), (90, 0, 1.0), rec(dx=1, dy=1), SIZE)
    assert t["dir_align"] == pytest.approx(1 / math.sqrt(2))
    assert t["pos_align"] == pytest.approx(1 - 1 / D_MAX)


def test_zero_vectors() -> None:
    # The agent stayed (blocked move or camera action): dir_align 0 whatever the advice.
    t = alignment((3, 4, 1), (3, 4, 1), (90, 0, 1.0), rec(dx=1, dz=-1), SIZE)
    assert t["dir_align"] == 0.0
    assert t["pos_align"] == pytest.approx(1 - math.sqrt(2) / D_MAX)
    # The advice is "stay": dir_align 0 even though the agent moved; pos_align counts the miss.
    t = alignment((3, 4, 1), (3, 5, 1), (90, 0, 1.0), rec(), SIZE)
    assert t["dir_align"] == 0.0
    assert t["pos_align"] == pytest.approx(1 - 1 / D_MAX)
    assert t["move"] == pytest.approx(0.5 * (1 - 1 / D_MAX))
    # Both zero: stayed as advised.
    t = alignment((3, 4, 1), (3, 4, 1), (90, 0, 1.0), rec(), SIZE)
    assert (t["dir_align"], t["pos_align"], t["move"]) == (0.0, 1.0, 0.5)


def test_wind_pushed_the_uav_further() -> None:
    # Moved +x and a gust pushed +y: dp = (1, 1, 0), advice (1, 0, 0).
    t = alignment((3, 4, 1), (4, 5, 1), (90, 0, 1.0), rec(dx=1), SIZE)
    assert t["dir_align"] == pytest.approx(1 / math.sqrt(2))
    assert t["pos_align"] == pytest.approx(1 - 1 / D_MAX)


def test_camera_term_by_hand() -> None:
    # tilt 60 vs 45 -> 15/90; pan -30 vs 75 -> 105/180; zoom 1.5 vs 1.0 -> 0.5/1.5.
    t = alignment((0, 0, 0), (0, 0, 0), (60, -30, 1.5), rec(pan=75, tilt=45, zoom=1.0), SIZE)
    expected = -(15 / 90 + 105 / 180 + 0.5 / 1.5) / 3
    assert t["cam"] == pytest.approx(expected)
    # Worst case: every axis at the far end of its range gives -1.
    t = alignment((0, 0, 0), (0, 0, 0), (0, -90, 0.5), rec(pan=90, tilt=90, zoom=2.0), SIZE)
    assert t["cam"] == pytest.approx(-1.0)


def test_alpha_and_lambdas() -> None:
    t = alignment((3, 4, 1), (4, 4, 1), (60, 0, 1.0), rec(dx=-1, tilt=90), SIZE, alpha=1.0)
    assert t["move"] == pytest.approx(-1.0)
    t0 = alignment((3, 4, 1), (4, 4, 1), (60, 0, 1.0), rec(dx=-1, tilt=90), SIZE, alpha=0.0)
    assert t0["move"] == pytest.approx(1 - 2 / D_MAX)
    cam = -(30 / 90) / 3
    assert t["cam"] == pytest.approx(cam)
    assert f_llm(t, lam_cam=2.0, lam_move=0.5) == pytest.approx(2.0 * cam + 0.5 * -1.0)
    assert f_llm(t, lam_cam=0.0, lam_move=0.0) == 0.0


def test_one_cell_world() -> None:
    t = alignment((0, 0, 0), (0, 0, 0), (90, 0, 1.0), rec(), (1, 1, 1))
    assert t["pos_align"] == 1.0 and math.isfinite(t["move"])
    t = alignment((0, 0, 0), (0, 0, 0), (90, 0, 1.0), rec(dx=1), (1, 1, 1))
    assert t["pos_align"] == 0.0


cells = st.tuples(st.integers(0, 14), st.integers(0, 14), st.integers(0, 2))
moves = st.tuples(*[st.integers(-1, 1)] * 3)


@settings(max_examples=200, deadline=None)
@given(
    cells,
    moves,
    moves,
    st.tuples(st.integers(0, 18), st.integers(-6, 6), st.integers(5, 20)),
    st.floats(0, 1),
)
def test_batch_matches_single_and_ranges(p, step, advice, camera, alpha) -> None:
    p_next = tuple(a + b for a, b in zip(p, step, strict=True))
    cam = (5.0 * camera[0], 15.0 * camera[1], camera[2] / 10)
    r = rec(*advice, pan=30.0, tilt=45.0, zoom=1.2)
    t = alignment(p, p_next, cam, r, SIZE, alpha)
    assert -1.0 - 1e-9 <= t["dir_align"] <= 1.0 + 1e-9
    assert t["pos_align"] <= 1.0 and -1.0 <= t["cam"] <= 0.0
    arrays = alignment_arrays(
        np.array([p]), np.array([p_next]), np.array([cam]),
        np.array([[r.pan, r.tilt, r.zoom, r.dx, r.dy, r.dz]]), np.array(SIZE), alpha,
    )  # fmt: skip
    for name, values in zip(("dir_align", "pos_align", "move", "cam"), arrays, strict=True):
        assert values.shape == (1,)
        assert values[0] == pytest.approx(t[name])
