"""Camera footprint geometry: the paper's square and the pinhole frustum (with occlusion)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import rel_cells, scenario
from pirl.world.footprint import PAPER_MAX_HALF

CENTRE = (15, 15)


@pytest.fixture
def paper_world(make_env):
    env = make_env(size=(31, 31, 3), footprint="paper")
    env.reset(seed=0, options={"scenario": scenario((15, 15, 1))})
    return env.unwrapped.world


@pytest.fixture
def frustum_world(make_env):
    env = make_env(size=(31, 31, 3), footprint="frustum")
    env.reset(seed=0, options={"scenario": scenario((15, 15, 2))})
    return env.unwrapped.world


def square(h: int) -> set[tuple[int, int]]:
    return {(dx, dy) for dx in range(-h, h + 1) for dy in range(-h, h + 1)}


def footprint(world, z=2, tilt=90, pan=0, zoom10=10, xy=CENTRE):
    return world.footprint(0, pose=(xy[0], xy[1], z), camera=(tilt, pan, zoom10))


# -- paper model ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("tilt", "zoom10", "side"),
    [
        (90, 10, 3),
        (75, 20, 9),
        (90, 15, 5),
        (90, 5, 3),
        (90, 14, 3),
        (90, 20, 5),
        (85, 20, 5),
        (80, 20, 5),
        (80, 10, 3),
        (75, 10, 5),
        (75, 5, 3),
        (75, 7, 3),
        (75, 8, 5),
        (75, 13, 7),
        (0, 18, 9),
        (0, 17, 7),
    ],
)
def test_paper_square_side_per_zoom_and_tilt(paper_world, tilt, zoom10, side):
    m = 2 if tilt < 80 else 1
    h = math.floor(m * zoom10 / 10 + 0.5)
    assert 2 * h + 1 == side
    cells = footprint(paper_world, z=1, tilt=tilt, zoom10=zoom10)
    assert len(cells) == side * side
    assert rel_cells(cells, CENTRE) == square(h)


def test_paper_square_for_every_camera_setting(paper_world):
    for tilt in range(0, 91, 5):
        for zoom10 in range(5, 21):
            h = math.floor((2 if tilt < 80 else 1) * zoom10 / 10 + 0.5)
            assert h <= PAPER_MAX_HALF
            cells = footprint(paper_world, z=1, tilt=tilt, zoom10=zoom10)
            assert rel_cells(cells, CENTRE) == square(h), (tilt, zoom10)


def test_paper_ignores_altitude_and_pan(paper_world):
    ref = rel_cells(footprint(paper_world, z=0, tilt=75, pan=0, zoom10=12), CENTRE)
    for z in range(3):
        for pan in range(-90, 91, 15):
            cells = footprint(paper_world, z=z, tilt=75, pan=pan, zoom10=12)
            assert rel_cells(cells, CENTRE) == ref


def test_paper_is_clipped_at_the_borders(paper_world):
    corner = footprint(paper_world, tilt=90, zoom10=10, xy=(0, 0))
    assert {tuple(c) for c in corner.tolist()} == {(0, 0), (0, 1), (1, 0), (1, 1)}
    edge = footprint(paper_world, tilt=75, zoom10=20, xy=(30, 10))
    cells = {tuple(c) for c in edge.tolist()}
    assert cells == {(i, j) for i in range(26, 31) for j in range(6, 15)}
    assert len(edge) == 5 * 9
    far = footprint(paper_world, tilt=75, zoom10=20, xy=(30, 30))
    assert len(far) == 25


def test_paper_largest_footprint_normalizes_coverage(paper_world):
    assert paper_world.max_footprint == 81


# -- frustum model -------------------------------------------------------------------------


def test_frustum_nadir_view_is_symmetric_about_the_uav(frustum_world):
    """Straight down, the rectangle is centred on the UAV: the seen cells must be too.

    Cells whose centres fall exactly on the rectangle's edge must be treated alike on both
    sides (all in or all out), whatever the altitude and zoom.
    """
    asymmetric = []
    for z in range(3):
        for zoom10 in range(5, 21):
            rel = rel_cells(footprint(frustum_world, z=z, tilt=90, zoom10=zoom10), CENTRE)
            assert (0, 0) in rel
            mirrored_x = {(-dx, dy) for dx, dy in rel}
            mirrored_y = {(dx, -dy) for dx, dy in rel}
            if rel != mirrored_x or rel != mirrored_y:
                asymmetric.append((z, zoom10 / 10, sorted(rel)))
    assert not asymmetric, "nadir footprints not symmetric (z, zoom, cells): " + "; ".join(
        f"z={z} zoom={zm}: {cells}" for z, zm, cells in asymmetric[:4]
    )


def test_frustum_nadir_contains_the_uav_cell_and_is_wider_along_y(frustum_world):
    # Pan 0: the image's long (4) side lies along y, its short (3) side along x.
    rel = rel_cells(footprint(frustum_world, z=2, tilt=90, zoom10=5), CENTRE)
    assert (0, 0) in rel
    xs = [dx for dx, _ in rel]
    ys = [dy for _, dy in rel]
    assert max(ys) - min(ys) > max(xs) - min(xs)


@pytest.mark.parametrize("tilt", [30, 45, 60, 75])
def test_frustum_tilt_shifts_the_view_forward_along_pan(frustum_world, tilt):
    cells = footprint(frustum_world, z=2, tilt=tilt, pan=0) - np.array(CENTRE)
    mean = cells.mean(axis=0)
    assert mean[0] > 1.0
    assert abs(mean[1]) < 1e-9
    if tilt <= 45:  # steeper views also see a little behind the UAV (half-fov 36.9 deg)
        assert cells[:, 0].min() >= 0
    # The view is mirror-symmetric about the pan axis.
    rel = {(int(a), int(b)) for a, b in cells}
    assert rel == {(dx, -dy) for dx, dy in rel}


def test_frustum_lower_tilt_looks_farther(frustum_world):
    means = [
        (footprint(frustum_world, z=2, tilt=t) - np.array(CENTRE))[:, 0].mean()
        for t in (75, 60, 45, 30)
    ]
    assert means == sorted(means)
    assert means[-1] > means[0] + 1.0


@pytest.mark.parametrize("tilt", [30, 45, 60])
def test_frustum_pan_rotates_the_view(frustum_world, tilt):
    base = rel_cells(footprint(frustum_world, tilt=tilt, pan=0), CENTRE)
    left = rel_cells(footprint(frustum_world, tilt=tilt, pan=90), CENTRE)
    right = rel_cells(footprint(frustum_world, tilt=tilt, pan=-90), CENTRE)
    # Pan 90 points +y: the pan-0 footprint rotated a quarter turn counter-clockwise.
    assert left == {(-dy, dx) for dx, dy in base}
    assert right == {(dy, -dx) for dx, dy in base}
    assert np.mean([dy for _, dy in left]) > 1.0
    assert np.mean([dy for _, dy in right]) < -1.0
    diag = footprint(frustum_world, tilt=tilt, pan=45) - np.array(CENTRE)
    mx, my = diag.mean(axis=0)
    assert mx > 0.5 and my > 0.5
    assert mx == pytest.approx(my)


def test_frustum_zoom_shrinks_the_view(frustum_world):
    for tilt in (90, 60, 45):
        counts = [len(footprint(frustum_world, tilt=tilt, zoom10=zm)) for zm in (5, 10, 15, 20)]
        assert counts == sorted(counts, reverse=True), (tilt, counts)
        assert counts[0] > counts[-1]
    # Straight down, a narrower view is nested in a wider one.
    for z in range(3):
        for zoom10 in range(5, 20):
            wide = rel_cells(footprint(frustum_world, z=z, tilt=90, zoom10=zoom10), CENTRE)
            narrow = rel_cells(footprint(frustum_world, z=z, tilt=90, zoom10=zoom10 + 1), CENTRE)
            assert narrow <= wide


def test_frustum_higher_altitude_enlarges_the_view(frustum_world):
    for zoom10 in (5, 10, 15, 20):
        views = [
            rel_cells(footprint(frustum_world, z=z, tilt=90, zoom10=zoom10), CENTRE)
            for z in range(3)
        ]
        assert views[0] <= views[1] <= views[2]
        assert len(views[0]) < len(views[2])
    counts = [len(footprint(frustum_world, z=z, tilt=45)) for z in range(3)]
    assert counts[0] < counts[1] < counts[2]


def test_frustum_respects_max_range(frustum_world):
    for tilt in range(0, 91, 15):
        for pan in (0, 45, -30):
            for zoom10 in (5, 10, 20):
                cells = footprint(frustum_world, tilt=tilt, pan=pan, zoom10=zoom10)
                dist = np.hypot(*(cells - np.array(CENTRE)).T)
                assert (dist <= 8.0 + 1e-9).all()
    # At the horizon the view reaches well ahead.
    horizon = footprint(frustum_world, tilt=0) - np.array(CENTRE)
    assert horizon[:, 0].max() >= 5
    # Looking level from 3 cells up with zoom 2, the lowest ray meets the ground at 8.9 cells:
    # everything in view lies beyond max_range, so nothing is seen.
    assert len(footprint(frustum_world, z=2, tilt=0, zoom10=20)) == 0


def test_frustum_never_exceeds_its_normalizer(make_env):
    """dC = new cells / max_footprint stays in [0, 1] for every camera setting and altitude."""
    env = make_env(size=(41, 41, 3), footprint="frustum")
    env.reset(seed=0, options={"scenario": scenario((20, 20, 0))})
    world = env.unwrapped.world
    best = 0
    for z in range(3):
        for tilt in range(0, 91, 5):
            for pan in range(-90, 91, 15):
                for zoom10 in range(5, 21):
                    n = len(world.footprint(0, pose=(20, 20, z), camera=(tilt, pan, zoom10)))
                    best = max(best, n)
    assert best == world.max_footprint


def test_frustum_is_clipped_at_the_borders(frustum_world):
    cells = footprint(frustum_world, tilt=45, pan=0, xy=(28, 15))
    assert cells[:, 0].max() == 30
    assert len(cells) < len(footprint(frustum_world, tilt=45, pan=0))
    assert ((cells >= 0) & (cells <= 30)).all()


SPHERE = [[19.0, 15.0, 0.0, 1.5]]


def _occluded_pair(make_env, obstacles):
    views = {}
    for occlusion in (False, True):
        env = make_env(size=(31, 31, 3), footprint="frustum", occlusion=occlusion)
        env.reset(seed=0, options={"scenario": scenario((15, 15, 2), obstacles)})
        world = env.unwrapped.world
        views[occlusion] = {tuple(c) for c in world.footprint(0, camera=(45, 0, 10)).tolist()}
    return views[False], views[True], world


def test_occlusion_hides_cells_behind_a_sphere(make_env):
    open_view, occluded_view, world = _occluded_pair(make_env, SPHERE)
    assert occluded_view < open_view
    hidden = open_view - occluded_view
    # Hidden cells lie in the sphere's shadow: at or beyond its near side, along the view.
    assert all(i >= 19 - 1.5 for i, _ in hidden)
    assert all(abs(j - 15) <= 3 for _, j in hidden)
    # Some of them are free, coverable ground that the sphere hides.
    hidden_free = [c for c in hidden if world.coverable[0][c]]
    assert len(hidden_free) >= 3
    # Cells beside the sphere stay visible.
    assert (18, 18) in occluded_view and (18, 12) in occluded_view


def test_occlusion_changes_nothing_without_obstacles(make_env):
    open_view, occluded_view, _ = _occluded_pair(make_env, None)
    assert open_view == occluded_view


def test_occlusion_changes_nothing_for_a_sphere_out_of_sight(make_env):
    open_view, occluded_view, _ = _occluded_pair(make_env, [[5.0, 5.0, 1.0, 1.5]])
    assert open_view == occluded_view


def test_occlusion_reduces_coverage_in_the_episode(open_env):
    new = {}
    for occlusion in (False, True):
        env, _, info = open_env(
            (15, 15, 2), size=(31, 31, 3), obstacles=SPHERE, footprint="frustum",
            occlusion=occlusion, start_tilt=45,
        )  # fmt: skip
        new[occlusion] = info["covered"]
    assert new[True] < new[False]
