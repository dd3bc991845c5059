"""Camera rays: pixel centres, orientation, field of view."""

import numpy as np
import pytest

from raycore.camera import (
    orthographic_camera,
    orthographic_rays,
    perspective_camera,
    perspective_rays,
)

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


@pytest.mark.parametrize("view", [
    {"position": [0.0, 0.0, -5e200], "look_at": [0.0, 0.0, 1e200], "up": [0.0, 1.0, 0.0]},
    {"position": [0.0, 0.0, -1.7e308], "look_at": [0.0, 0.0, 1.7e308], "up": [0.0, 1.0, 0.0]},
    {**VIEW, "up": [0.0, 1e300, 0.0]},
    {**VIEW, "up": [0.0, 1e-300, 0.0]},
])
def test_far_look_at_and_huge_or_tiny_up_give_the_unit_view_directions(view):
    """Squares that overflow or vanish: such cameras were refused as parallel or gave NaN."""
    _, directions = perspective_rays(**view, fov=50.0, width=3, height=3)
    np.testing.assert_allclose(directions,
                               perspective_rays(**VIEW, fov=50.0, width=3, height=3)[1],
                               rtol=1e-15, atol=1e-15)


@pytest.mark.parametrize(("make", "dtype", "name"), [
    (lambda: perspective_camera([1e39, 0, 0], [0, 0, 0], [0, 1, 0], 45.0, 4, 4), "float32",
     "position"),
    (lambda: orthographic_camera([0, 0, 0], [0, 0, 1], [0, 1, 0], 1.7e308, 8, 2), "float64",
     "view_height"),
    (lambda: orthographic_camera([0, 3e38, 0], [0, 3e38, 1], [0, 1, 0], 1e38, 4, 4),
     "float32", "view_height"),
])
def test_rays_beyond_the_dtypes_range_are_refused(make, dtype, name):
    """Rather than made as inf, which miss everything."""
    camera = make()
    if dtype == "float32":
        assert np.all(np.isfinite(camera.rays("float64")))  # they fit float64
    with pytest.raises(ValueError, match=name):
        camera.rays(dtype, samples=4)


@pytest.mark.parametrize(("change", "name"), [
    ({"look_at": [0.0, 0.0, -5.0]}, "look_at"),
    ({"up": [0.0, 0.0, 2.0]}, "up"),
    ({"fov": 180.0}, "fov"),
    ({"fov": 0.0}, "fov"),
    ({"width": 0}, "width"),
    ({"height": 2.5}, "height"),
    ({"position": [0.0, np.nan, 0.0]}, "position"),
    ({"fov": None}, "fov"),
    ({"fov": "45"}, "fov"),
    ({"fov": np.array([45.0, 50.0])}, "fov"),
    ({"samples": 4, "seed": -1}, "seed"),
    ({"samples": 4, "seed": 2**64}, "seed"),
    ({"seed": None}, "seed"),
    ({"samples": 4, "seed": 1.5}, "seed"),
    # a bool is not a size or a count; NumPy raised TypeError for samples=True
    ({"width": True}, "width"),
    ({"samples": True}, "samples"),
    # a side no array could have: NumPy's "Maximum allowed dimension exceeded" before
    ({"width": 10**30}, "width"),
    ({"height": 2**31}, "height"),
])
def test_bad_perspective_arguments_name_themselves(change, name):
    with pytest.raises(ValueError, match=name):
        perspective_rays(**{**VIEW, "fov": 45.0, "width": 4, "height": 4, **change})


# 10**400: an int past float64's range (np.isfinite refused ints past int64 with TypeError)
@pytest.mark.parametrize("view_height", [0.0, -1.0, np.inf, None, "2",
                                         pytest.param(10**400, id="int-past-float64")])
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


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("samples", [1, 4, 5])
@pytest.mark.parametrize("camera, rays", [
    (lambda: perspective_camera(**VIEW, fov=50.0, width=7, height=5),
     lambda **kw: perspective_rays(**VIEW, fov=50.0, width=7, height=5, **kw)),
    (lambda: orthographic_camera(**VIEW, view_height=3.0, width=7, height=5),
     lambda **kw: orthographic_rays(**VIEW, view_height=3.0, width=7, height=5, **kw)),
])
def test_a_cameras_bands_of_rows_are_its_rays(camera, rays, samples, dtype):
    # a render makes its rays a band of rows at a time: each ray is the one the whole image has
    camera = camera()
    whole = rays(dtype=dtype, samples=samples, seed=3)
    for got, want in zip(camera.rays(dtype, samples, 3), whole, strict=True):
        np.testing.assert_array_equal(got, want)
    bands = [camera.rays(dtype, samples, 3, rows) for rows in ((0, 2), (2, 3), (3, 5))]
    for k in range(2):
        banded = np.concatenate([band[k] for band in bands])
        assert banded.dtype == whole[k].dtype
        np.testing.assert_array_equal(banded, whole[k])
    # written into one pair of arrays that every band reuses, as a render does
    row = camera.width * samples
    memory = [np.full((2 * row, 3), np.nan, dtype) for _ in range(2)]
    for first, last in ((2, 3), (0, 2), (3, 5)):
        out = [array[:(last - first) * row] for array in memory]
        assert camera.rays(dtype, samples, 3, (first, last), out) is out
        for k in range(2):
            np.testing.assert_array_equal(out[k], whole[k][first * row:last * row])


def _read_only(array):
    array.flags.writeable = False
    return array


@pytest.mark.parametrize("out", [
    [np.empty((7, 3)), np.empty((7, 3))],  # too short
    [np.empty((35, 3), np.float32), np.empty((35, 3))],  # another dtype
    [np.empty((35, 3))],  # one array
    [np.empty((35, 3)), np.empty((35, 6))[:, :3]],  # not contiguous
    [np.empty((35, 3)), _read_only(np.empty((35, 3)))],
    [np.empty((35, 3)), [[0.0] * 3] * 35],  # not an array
    5,  # not a pair
])
def test_bad_output_arrays(out):
    # the kernels write without bounds checks: a wrong array is refused, not written past
    with pytest.raises(ValueError, match="out must be"):
        perspective_camera(**VIEW, fov=50.0, width=7, height=5).rays("float64", out=out)


# 3 and None: not a pair, which was unpacked before it was checked (TypeError)
@pytest.mark.parametrize("rows", [(0, 0), (-1, 2), (3, 2), (0, 6), (0.5, 2), (False, 2), 3,
                                  (1, 2, 3), "ab"])
def test_bad_band_of_rows(rows):
    with pytest.raises(ValueError, match="rows"):
        perspective_camera(**VIEW, fov=50.0, width=4, height=5).rays(rows=rows)


def test_bad_dtype():
    with pytest.raises(ValueError, match="dtype"):
        perspective_rays(**VIEW, fov=50.0, width=4, height=4, dtype="float16")


# ---------------------------------------------------------------------- frame_box

def _view(position, look_at, up, corners):
    """Camera-space (right, up, depth) of points, from the camera's own axes."""
    forward = np.subtract(look_at, position)
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    relative = corners - position
    return relative @ right, relative @ true_up, relative @ forward


def _corners(lo, hi):
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                     for z in (lo[2], hi[2])], dtype=float)


@pytest.mark.parametrize("width, height, fov", [(512, 512, 45.0), (640, 360, 30.0),
                                                (200, 400, 90.0)])
def test_frame_box_sees_every_corner_and_fills_the_view(width, height, fov):
    from raycore.camera import THREE_QUARTER, frame_box

    lo, hi = np.array([-3.0, 0.5, 10.0]), np.array([1.0, 2.0, 11.0])
    position, look_at, view_height = frame_box(lo, hi, width, height, fov=fov, fill=0.9)
    np.testing.assert_allclose(look_at, (lo + hi) / 2)
    toward = (position - look_at) / np.linalg.norm(position - look_at)
    np.testing.assert_allclose(toward, np.divide(THREE_QUARTER, np.linalg.norm(THREE_QUARTER)))
    x, y, depth = _view(position, look_at, (0, 1, 0), _corners(lo, hi))
    assert np.all(depth > 0)
    tan_v = np.tan(np.radians(fov) / 2)
    # the farthest-reaching corner is at 0.9 of the half view: inside, and as near as allowed
    reach = np.maximum(np.abs(x) / (tan_v * width / height), np.abs(y) / tan_v) / depth
    assert reach.max() == pytest.approx(0.9, rel=1e-9)
    # orthographic: every corner within the view height and the width that goes with it
    half = np.maximum(np.abs(y), np.abs(x) * height / width)
    assert half.max() == pytest.approx(0.9 * view_height / 2, rel=1e-9)


def test_frame_box_keeps_a_given_camera_and_takes_an_empty_box_as_a_cube():
    from raycore.camera import frame_box

    position, look_at, view_height = frame_box([1, 1, 1], [-1, -1, -1], 100, 100,
                                               position=[0, 0, 10], look_at=[0, 0, 0])
    np.testing.assert_array_equal(position, [0, 0, 10])
    np.testing.assert_array_equal(look_at, [0, 0, 0])
    assert view_height == pytest.approx(2 / 0.9)  # the cube -1..1 seen face-on
    with pytest.raises(ValueError, match="fov"):
        frame_box([0, 0, 0], [1, 1, 1], 10, 10, fov=180)


@pytest.mark.parametrize("planes", [0, 1])
def test_frame_box_takes_the_bounds_of_a_scene_with_nothing_bounded(planes):
    # Scene.bounds of an empty scene, or of planes only, is (inf, -inf): the cube -1..1
    from raycore import Scene
    from raycore.camera import frame_box

    scene = Scene()
    for _ in range(planes):
        scene.add_plane([0, 0, 0], [0, 1, 0])
    cube = frame_box([-1, -1, -1], [1, 1, 1], 8, 8)
    for got, want in zip(frame_box(*scene.bounds, 8, 8), cube, strict=True):
        np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError, match="lo"):  # a box that is not empty must be finite
        frame_box([0, 0, -np.inf], [1, 1, 1], 8, 8)
