"""raycore.sensors: LiDAR and sight-line rays against angles and points recomputed here from
first principles; cameras are raycore.camera's rays."""

import math

import numpy as np
import pytest

from raycore import Scene, sensors
from raycore.camera import orthographic_rays, perspective_rays


def _angles(directions, forward, up):
    """(elevation, azimuth) in degrees of each direction in the frame (forward, up x forward,
    up), with math's scalar functions, one ray at a time."""
    left = np.cross(up, forward)
    elevation, azimuth = [], []
    for d in np.asarray(directions, dtype=np.float64):
        elevation.append(math.degrees(math.asin(max(-1.0, min(1.0, d @ up)))))
        azimuth.append(math.degrees(math.atan2(d @ left, d @ forward)) % 360)
    return np.array(elevation), np.array(azimuth)


def _angle_gap(a, b):
    """Smallest difference between azimuths, in degrees (359.99 and 0 are close)."""
    gap = np.abs(np.asarray(a) - np.asarray(b)) % 360
    return np.minimum(gap, 360 - gap)


@pytest.mark.parametrize("dtype, tolerance", [("float64", 1e-9), ("float32", 1e-4)])
def test_lidar_rays_point_at_their_channel_elevation_and_column_azimuth(dtype, tolerance):
    elevations = [-24.0, -3.5, 0.0, 7.25, 89.0]
    position = [1.0, 2.0, 3.0]
    rays = sensors.lidar(position, elevations=elevations, columns=90, min_range=0.5,
                         max_range=80.0, dtype=dtype)
    assert rays.origins.shape == rays.directions.shape == (450, 3)
    assert rays.directions.dtype == np.dtype(dtype)
    assert (rays.tmin, rays.tmax) == (0.5, 80.0)
    np.testing.assert_array_equal(rays.origins, np.tile(position, (450, 1)).astype(dtype))
    np.testing.assert_allclose(np.linalg.norm(rays.directions.astype(float), axis=1), 1.0,
                               atol=tolerance)
    # the default frame: x forward, z up; ray k is channel k // 90, column k % 90
    elevation, azimuth = _angles(rays.directions, np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    k = np.arange(450)
    np.testing.assert_allclose(elevation, np.array(elevations)[k // 90], atol=100 * tolerance)
    # azimuth is ill-defined near the pole: checked for the other channels
    level = k // 90 < 4
    assert _angle_gap(azimuth[level], 4.0 * (k[level] % 90)).max() < 100 * tolerance


def test_lidar_pose_turns_counter_clockwise_about_up_from_forward():
    # a y-up scene: spin axis +y, first column along +z; seen from above (+y), counter-clockwise
    # turns +z towards +x (up x forward = y x z = x)
    up, forward = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    rays = sensors.lidar([0, 0, 0], forward=[0.0, 0.3, 2.0], up=[0.0, 5.0, 0.0],
                         elevations=[0.0, 30.0], columns=4)
    expected = [[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0]]
    np.testing.assert_allclose(rays.directions[:4], expected, atol=1e-15)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    np.testing.assert_allclose(rays.directions[4], c * forward + s * up, atol=1e-15)


@pytest.mark.parametrize("scale", [1e-200, 1e200])
def test_pose_vectors_of_any_length(scale):
    rays = sensors.lidar([0, 0, 0], forward=[scale, 0.0, 0.0], up=[0.0, 0.0, 3 * scale],
                         elevations=[0.0], columns=4)
    np.testing.assert_allclose(rays.directions, [[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]],
                               atol=1e-15)


def test_vertical_fov_spreads_channels_evenly_and_resolution_sets_columns():
    rays = sensors.lidar([0, 0, 0], vertical_fov=[-30.0, 10.0], channels=5,
                         horizontal_resolution=0.5)
    elevation, azimuth = _angles(rays.directions, np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    assert len(rays.directions) == 5 * 720
    np.testing.assert_allclose(elevation[::720], [-30.0, -20.0, -10.0, 0.0, 10.0], atol=1e-9)
    assert _angle_gap(azimuth[:720], 0.5 * np.arange(720)).max() < 1e-9


@pytest.mark.parametrize("name", sorted(sensors.LIDAR_PRESETS))
def test_presets_give_their_data_sheet_layout(name):
    # (channels, lowest and highest elevation in degrees, max range in metres), from the
    # makers' data sheets
    sheets = {"velodyne-vlp16": (16, -15.0, 15.0, 100.0),
              "velodyne-hdl32e": (32, -30.67, 10.67, 100.0),
              "velodyne-hdl64e": (64, -24.9, 2.0, 120.0),
              "ouster-os1-128": (128, -22.5, 22.5, 120.0)}
    channels, lowest, highest, max_range = sheets[name]
    rays = sensors.lidar([0, 0, 0], preset=name, dtype="float32")
    columns = len(rays.directions) // channels
    assert len(rays.directions) == channels * columns and 1000 <= columns <= 2300
    elevation, _ = _angles(rays.directions[::columns], np.array([1.0, 0, 0]),
                           np.array([0, 0, 1.0]))
    np.testing.assert_allclose(elevation[[0, -1]], [lowest, highest], atol=1e-4)
    assert rays.tmax == max_range and 0 < rays.tmin < 2


def test_fields_given_besides_a_preset_win():
    rays = sensors.lidar([0, 0, 0], preset="velodyne-vlp16", columns=8, max_range=5.0)
    assert len(rays.directions) == 16 * 8 and rays.tmax == 5.0 and rays.tmin == 0.5


def test_lidar_ranges_are_distances_to_a_wall():
    # a plane x = 4 in front of the sensor: the range of a beam at elevation e and azimuth a is
    # 4 / (cos e cos a), and beyond max_range there is no return
    scene = Scene(dtype="float64")
    scene.add_plane([4.0, 0.0, 0.0], [-1.0, 0.0, 0.0])
    rays = sensors.lidar([0, 0, 0], elevations=[-10.0, 0.0, 20.0], columns=36, max_range=5.0)
    hits = scene.intersect(*rays)
    e = np.radians(np.repeat([-10.0, 0.0, 20.0], 36))
    a = np.radians(np.tile(np.arange(36) * 10.0, 3))
    with np.errstate(divide="ignore"):
        expected = 4 / (np.cos(e) * np.cos(a))
    expected[(expected <= 0) | (expected > 5.0)] = np.inf
    assert np.isfinite(expected).sum() >= 9 and np.isinf(expected).sum() >= 9
    np.testing.assert_allclose(hits.t, expected, rtol=1e-12)


@pytest.mark.parametrize("arguments, name", [
    ({"columns": 8}, "elevations or vertical_fov"),
    ({"elevations": [0.0], "vertical_fov": [-1.0, 1.0], "channels": 2, "columns": 8},
     "elevations or vertical_fov"),
    ({"elevations": [0.0], "channels": 2, "columns": 8}, "channels"),
    ({"elevations": [], "columns": 8}, "elevations"),
    ({"elevations": [95.0], "columns": 8}, "elevations"),
    ({"elevations": [np.nan], "columns": 8}, "elevations"),
    ({"vertical_fov": [10.0, -10.0], "channels": 4, "columns": 8}, "vertical_fov"),
    ({"vertical_fov": [-10.0, 10.0], "columns": 8}, "channels"),
    ({"vertical_fov": [-10.0, 10.0], "channels": 0, "columns": 8}, "channels"),
    ({"vertical_fov": [-10.0, 10.0], "channels": True, "columns": 8}, "channels"),
    ({"elevations": [0.0]}, "horizontal_resolution or columns"),
    ({"elevations": [0.0], "columns": 8, "horizontal_resolution": 1.0},
     "horizontal_resolution or columns"),
    ({"elevations": [0.0], "horizontal_resolution": 0.0}, "horizontal_resolution"),
    ({"elevations": [0.0], "horizontal_resolution": 400.0}, "horizontal_resolution"),
    # not real numbers: a bool was taken as 1 degree, a complex one raised TypeError
    ({"elevations": [0.0], "horizontal_resolution": True}, "horizontal_resolution"),
    ({"elevations": [0.0], "horizontal_resolution": 1 + 0j}, "horizontal_resolution"),
    ({"elevations": [0.0], "horizontal_resolution": "1"}, "horizontal_resolution"),
    ({"elevations": [0.0], "columns": 2.5}, "columns"),
    # counts no array could hold: NumPy's "Maximum allowed size exceeded" before
    ({"elevations": [0.0], "horizontal_resolution": 1e-300}, "horizontal_resolution"),
    ({"elevations": [0.0], "columns": 10**20}, "columns"),
    ({"vertical_fov": [-10.0, 10.0], "channels": 10**20, "columns": 8}, "channels"),
    ({"elevations": [0.0], "columns": 8, "min_range": -1.0}, "min_range"),
    ({"elevations": [0.0], "columns": 8, "min_range": 2.0, "max_range": 2.0}, "max_range"),
    ({"elevations": [0.0], "columns": 8, "max_range": np.nan}, "max_range"),
    ({"elevations": [0.0], "columns": 8, "min_range": True}, "min_range"),
    ({"elevations": [0.0], "columns": 8, "min_range": "0"}, "min_range"),
    ({"elevations": [0.0], "columns": 8, "max_range": 5j}, "max_range"),
    ({"preset": "velodyne-vlp1", "columns": 8}, "preset"),
    ({"elevations": [0.0], "columns": 8, "forward": [0, 0, 2]}, "forward"),
    ({"elevations": [0.0], "columns": 8, "forward": [0, 0, 0]}, "forward"),
    ({"elevations": [0.0], "columns": 8, "up": [0, 0, 0]}, "up"),
    ({"elevations": [0.0], "columns": 8, "dtype": "float16"}, "dtype"),
])
def test_bad_lidar_arguments_are_named(arguments, name):
    with pytest.raises(ValueError, match=name):
        sensors.lidar([0, 0, 0], **arguments)


def test_ranges_may_be_any_real_number_a_float_holds():
    # Python ints past int64 (np.isfinite raised TypeError on them) and NumPy scalars
    rays = sensors.lidar([0, 0, 0], elevations=[0.0], columns=8, min_range=10**20,
                         max_range=np.float32(2e20))
    assert (rays.tmin, rays.tmax) == (1e20, float(np.float32(2e20)))
    assert type(rays.tmin) is type(rays.tmax) is float


def test_points_rays_reach_their_targets_at_t_one():
    scene = Scene(dtype="float64")
    scene.add_sphere([0.0, 0.0, 5.0], 1.0)
    source = [0.0, 0.0, 0.0]
    targets = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 3.0], [5.0, 0.0, 5.0], [0.0, 0.0, 4.5]])
    rays = sensors.points(source, targets)
    np.testing.assert_array_equal(rays.origins, np.zeros((4, 3)))
    np.testing.assert_array_equal(rays.origins + rays.directions, targets)
    assert (rays.tmin, rays.tmax) == (0.0, 1.0)
    # behind the sphere, before it, beside it, inside it (its surface at z = 4 is crossed)
    np.testing.assert_array_equal(scene.occluded(*rays), [True, False, False, True])
    np.testing.assert_allclose(scene.intersect(*rays).t, [0.4, np.inf, np.inf, 4 / 4.5])


def test_points_pair_one_to_many_and_many_to_many():
    many = np.arange(12.0).reshape(4, 3)
    rays = sensors.points(many, [0.0, 0.0, -1.0], dtype="float32")
    np.testing.assert_array_equal(rays.origins, many.astype(np.float32))
    np.testing.assert_array_equal(rays.origins + rays.directions,
                                  np.tile([0.0, 0.0, -1.0], (4, 1)))
    pairs = sensors.points(many, many + 1)
    np.testing.assert_array_equal(pairs.directions, np.ones((4, 3)))


@pytest.mark.parametrize("sources, targets, name", [
    ([[0, 0, 0], [1, 1, 1]], [[0, 0, 1]] * 3, "as many"),
    ([[0, 0]], [[0, 0, 1]], "sources"),
    ([[0, 0, 0]], [[0, 0, np.inf]], "targets"),
    ([[0, 0, 0], [1, 1, 1]], [[0, 0, 1], [1, 1, 1]], "targets must differ"),
])
def test_bad_points_are_named(sources, targets, name):
    with pytest.raises(ValueError, match=name):
        sensors.points(sources, targets)


def test_cameras_are_raycore_camera_rays():
    view = {"position": [1.0, 2.0, -5.0], "look_at": [0.0, 0.5, 0.0], "up": [0.0, 1.0, 0.0]}
    rays = sensors.perspective(**view, fov=50.0, width=8, height=6, dtype="float32")
    for got, want in zip(rays[:2], perspective_rays(**view, fov=50.0, width=8, height=6,
                                                      dtype="float32"), strict=True):
        np.testing.assert_array_equal(got, want)
    rays = sensors.orthographic(**view, view_height=3.0, width=8, height=6)
    for got, want in zip(rays[:2], orthographic_rays(**view, view_height=3.0, width=8,
                                                       height=6), strict=True):
        np.testing.assert_array_equal(got, want)
    assert (rays.tmin, rays.tmax) == (0.0, np.inf)
