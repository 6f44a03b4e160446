"""Top-down rgb_array renders of the single env and VecEnv.get_images."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from conftest import scenario
from pirl.env import make_vec_env
from pirl.env.render import cell_pixels


@pytest.mark.parametrize("size", [(20, 12, 3), (15, 15, 3), (60, 45, 3), (3, 3, 3)])
def test_rgb_array_shape_and_dtype(size):
    env = gym.make("pirl/VCPP-v0", size=size, render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    c = cell_pixels(size)
    assert c >= 4
    assert image.shape == (size[1] * c, size[0] * c, 3)
    assert image.dtype == np.uint8


def test_cell_pixels_setting():
    assert cell_pixels((20, 12, 3)) == 24
    assert cell_pixels((20, 12, 3), 6) == 6
    assert cell_pixels((400, 400, 3)) == 4
    env = gym.make("pirl/VCPP-v0", size=(20, 12, 3), render_mode="rgb_array", render_cell_px=6)
    env.reset(seed=0)
    assert env.render().shape == (72, 120, 3)


def test_no_render_mode_renders_nothing():
    env = gym.make("pirl/VCPP-v0", size=(8, 8, 3))
    env.reset(seed=0)
    assert env.unwrapped.render() is None


def test_render_changes_after_covering_cells_and_marks_the_uav():
    size = (20, 12, 3)
    env = gym.make("pirl/VCPP-v0", size=size, render_mode="rgb_array", wind_prob=0.0)
    env.reset(seed=0, options={"scenario": scenario((3, 2, 1))})
    c = cell_pixels(size)
    before = env.render()

    def centre_pixel(image, x, y):
        # +x to the right, +y up: row from the top is (Y - 1 - y).
        return image[int((size[1] - 1 - y + 0.5) * c), int((x + 0.5) * c)]

    # The UAV is drawn in red at its cell.
    r, g, b = centre_pixel(before, 3, 2).astype(int)
    assert r > 180 and g < 80 and b < 80
    for _ in range(6):
        env.step(0)
    after = env.render()
    assert not np.array_equal(before, after)
    r, g, b = centre_pixel(after, 9, 2).astype(int)
    assert r > 180 and g < 80 and b < 80
    # A cell covered on the way and left behind is drawn in a different colour than before.
    assert not np.array_equal(centre_pixel(before, 6, 3), centre_pixel(after, 6, 3))
    # A far cell nobody saw is unchanged.
    assert np.array_equal(centre_pixel(before, 15, 10), centre_pixel(after, 15, 10))


def test_vec_get_images():
    size = (20, 12, 3)
    venv = make_vec_env(3, seed=0, size=size)
    venv.reset()
    images = venv.get_images()
    c = cell_pixels(size)
    assert len(images) == 3
    for image in images:
        assert image.shape == (size[1] * c, size[0] * c, 3) and image.dtype == np.uint8
    assert not np.array_equal(images[0], images[1])  # different worlds
    venv.step(np.array([0, 2, 8]))
    again = venv.get_images()
    assert any(not np.array_equal(a, b) for a, b in zip(images, again, strict=True))
    tiled = venv.render()
    assert tiled.dtype == np.uint8 and tiled.ndim == 3
