"""Camera rays: pixel centres, orientation, field of view."""

import numpy as np
import pytest

from raycore.camera import orthographic_rays, perspective_rays

VIEW = {"position": [0.0, 0.0, -5.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0]}


def test_perspective_rays_span_the_field_of_view():
    origins, directions = perspective_rays(**VIEW, fov=60.0, width=5, height=3)
    assert origins.shape == directions.shape == (15, 3)
    np.testing.assert_array_equal(origins, np.tile([0.0, 0.0, -5.0], (15, 1)))
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)
    grid = directions.reshape(3, 5, 3)
    np.testing.assert_allclose(grid[1, 2], [0.0, 0.0, 1.0], atol=1e-15)
    # the top row's centre is 2/3 of the way from the axis to the top edge of a 60° view
    top = grid[0, 2]
    np.testing.assert_allclose(top[1] / top[2], 2 / 3 * np.tan(np.radians(30)))
    # row 0 is the top of the image, column 0 its left (camera right is -x looking down +z)
    assert grid[0, 0, 1] > 0 and grid[0, 0, 0] > 0 and grid[2, 4, 0] < 0


def test_perspective_pixels_are_square():
    _, directions = perspective_rays(**VIEW, fov=40.0, width=8, height=4)
    grid = directions.reshape(4, 8, 3)
    plane = grid / grid[..., 2:]  # on the image plane at distance 1
    np.testing.assert_allclose(np.diff(plane[0, :, 0]), np.diff(plane[0, :, 0])[0])
    np.testing.assert_allclose(abs(np.diff(plane[:, 0, 1])[0]), abs(np.diff(plane[0, :, 0])[0]))


def test_orthographic_rays_are_parallel_and_span_the_view_height():
    origins, directions = orthographic_rays(**VIEW, view_height=2.0, width=4, height=2)
    np.testing.assert_array_equal(directions, np.tile([0.0, 0.0, 1.0], (8, 1)))
    grid = origins.reshape(2, 4, 3)
    np.testing.assert_allclose(grid[:, :, 2], -5.0)
    np.testing.assert_allclose(grid[:, 0, 1], [0.5, -0.5])  # pixel centres of a 2-unit view
    np.testing.assert_allclose(grid[0, :, 0], [1.5, 0.5, -0.5, -1.5])


def test_up_need_not_be_perpendicular():
    tilted = dict(VIEW, up=[0.0, 1.0, 1.0])
    np.testing.assert_allclose(perspective_rays(**tilted, fov=50.0, width=3, height=3)[1],
                               perspective_rays(**VIEW, fov=50.0, width=3, height=3)[1])


@pytest.mark.parametrize(("change", "name"), [
    ({"look_at": [0.0, 0.0, -5.0]}, "look_at"),
    ({"up": [0.0, 0.0, 2.0]}, "up"),
    ({"fov": 180.0}, "fov"),
    ({"fov": 0.0}, "fov"),
    ({"width": 0}, "width"),
    ({"height": 2.5}, "height"),
    ({"position": [0.0, np.nan, 0.0]}, "position"),
])
def test_bad_perspective_arguments_name_themselves(change, name):
    with pytest.raises(ValueError, match=name):
        perspective_rays(**{**VIEW, "fov": 45.0, "width": 4, "height": 4, **change})


@pytest.mark.parametrize("view_height", [0.0, -1.0, np.inf])
def test_bad_view_height(view_height):
    with pytest.raises(ValueError, match="view_height"):
        orthographic_rays(**VIEW, view_height=view_height, width=4, height=4)


@pytest.mark.parametrize("make", [
    lambda dtype: perspective_rays(**VIEW, fov=50.0, width=16, height=8, dtype=dtype),
    lambda dtype: orthographic_rays(**{**VIEW, "position": [1e4, 0.0, -5.0]}, view_height=3.0,
                                    width=16, height=8, dtype=dtype),
])
def test_float32_rays_are_the_float64_rays_rounded(make):
    origins, directions = make("float32")
    assert origins.dtype == directions.dtype == np.float32
    exact_origins, exact_directions = make("float64")
    np.testing.assert_allclose(origins, exact_origins, rtol=2e-7, atol=1e-7)
    np.testing.assert_allclose(directions, exact_directions, rtol=2e-7, atol=2e-7)


def test_bad_dtype():
    with pytest.raises(ValueError, match="dtype"):
        perspective_rays(**VIEW, fov=50.0, width=4, height=4, dtype="float16")
