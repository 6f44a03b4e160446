"""PARE's pure core and what it reads through the env's hooks: shaped terms from arrays alone,
and prompts built from world views that say what the world batch says."""

from __future__ import annotations

import numpy as np
import pytest

from pirl.advice.recommendation import Recommendation
from pirl.advice.state import view_prompt_state
from pirl.env import make_vec_env
from pirl.pare import alignment, f_llm
from pirl.pare.core import HAS, KIND_CACHED, KIND_STUDENT, KIND_TEACHER, STATUSES, Weights, shape


def test_shape_is_a_function_of_poses_advice_and_weights():
    size = (12, 10, 3)
    weights = Weights(lam_cam=2.0, lam_move=0.5, alpha=0.3)
    p_t = np.array([[1.0, 1.0, 0.0], [4.0, 4.0, 1.0], [2.0, 3.0, 2.0], [0.0, 0.0, 0.0]])
    pose = np.array(
        [[2, 1, 0, 45, 0, 10], [4, 5, 1, 90, 90, 15], [2, 3, 1, 0, -90, 20], [0, 1, 0, 0, 0, 10]]
    )
    recs = [
        Recommendation(pan=0, tilt=45, zoom=1.0, dx=1, dy=0, dz=0),
        Recommendation(pan=45, tilt=90, zoom=1.5, dx=0, dy=1, dz=0),
        Recommendation(pan=-90, tilt=0, zoom=2.0, dx=0, dy=0, dz=1),
        Recommendation(pan=0, tilt=0, zoom=1.0, dx=0, dy=1, dz=0),
    ]
    rec = np.array([[r.pan, r.tilt, r.zoom, r.dx, r.dy, r.dz] for r in recs], dtype=np.float64)
    # teacher now, cached now, student, and a world without advice.
    meta = np.array([[1, 7, KIND_TEACHER], [1, 7, KIND_CACHED], [1, 7, KIND_STUDENT], [0, 0, 0]])
    out = shape(p_t, pose, rec, meta, 7, weights.constants(size))
    for e in range(3):
        camera = (pose[e, 3], pose[e, 4], pose[e, 5] / 10.0)
        terms = alignment(p_t[e], pose[e, :3], camera, recs[e], size, alpha=0.3)
        expected = f_llm(terms, lam_cam=2.0, lam_move=0.5)
        assert out.table[e, 0] == pytest.approx(expected)
        assert out.table[e, 3] == pytest.approx(terms["move"])
    assert [STATUSES[s] for s in out.status] == ["fresh", "cached", "student", "missing"]
    assert out.table[3].tolist() == [0.0] * 5 and out.staleness.tolist() == [0, 0, 0, 0]
    later = shape(p_t, pose, rec, meta, 9, weights.constants(size))
    assert [STATUSES[s] for s in later.status[:2]] == ["stale", "stale"]
    assert later.staleness.tolist()[:2] == [2, 2] and meta[:, HAS].tolist() == [1, 1, 1, 0]


def test_prompt_state_of_a_view_says_what_the_world_batch_says():
    venv = make_vec_env(3, seed=4, size=(12, 10, 3), reward="ewri", llm_weight=True)
    venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(25):
        venv.step(rng.integers(0, 12, 3))
        world = venv.core.world
        for e, view in enumerate(venv.world_views(range(3))):
            state = view_prompt_state(view)
            row = world.status[e]
            assert state.coverage == row["covered"] / row["coverable"]
            assert state.battery == world.battery(e)
            assert state.position == world.position(e)
            assert (state.tilt, state.pan, state.zoom) == world.camera(e)
            assert len(state.obstacles) == row["n_obstacles"]
