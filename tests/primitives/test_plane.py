import math

import numpy as np
import pytest
from hypothesis import given, settings

from raycore.primitives import analytic, plane

from . import reference, sampling

POINT = np.array([0.5, 0.25, -0.75])
NORMAL = np.array([1.0, 2.0, -0.5])
UNIT = NORMAL / np.linalg.norm(NORMAL)


def intersect(origins, directions, dtype="float64", point=(0, 0, 0), normal_vector=(0, 0, 1),
              **options):
    return analytic.intersect_plane(np.atleast_2d(origins), np.atleast_2d(directions), point,
                                    normal_vector, dtype=dtype, **options)


# ---------------------------------------------------------------------------- analytic cases


@pytest.mark.parametrize("scale", [2.0**520, 2.0**-560, 2.0**-1070])
def test_a_normal_of_any_finite_length_is_the_same_plane(scale):
    # the normal's squares overflow or vanish at these lengths: it must not be taken as zero;
    # scaled by powers of two, it is exactly the same direction
    rng = np.random.default_rng(5)
    origins, directions = rng.normal(size=(200, 3)) * 4, rng.normal(size=(200, 3))
    want = intersect(origins, directions, normal_vector=NORMAL)
    got = intersect(origins, directions, normal_vector=NORMAL * scale)
    np.testing.assert_array_equal(got.t, want.t)


@pytest.mark.parametrize(
    ("origin", "direction", "expected"),
    [
        pytest.param((1, 2, 5), (0, 0, -1), 5.0, id="from-above"),
        pytest.param((1, 2, -5), (0, 0, 1), 5.0, id="from-below"),
        pytest.param((1, 2, 5), (0, 0, -0.5), 10.0, id="short-direction"),
        pytest.param((0, 0, 5), (3, 0, -1), 5.0, id="oblique"),
        pytest.param((0, 0, 5), (1, 0, 0), math.inf, id="parallel"),
        pytest.param((0, 0, 0), (1, 1, 0), math.inf, id="in-plane"),
        pytest.param((0, 0, 5), (0, 0, 1), math.inf, id="behind"),
        pytest.param((1, 1, 0), (0, 0, 1), 0.0, id="origin-on-plane"),
    ],
)
def test_simple_rays(origin, direction, expected, dtype):
    hits = intersect(origin, direction, dtype)
    assert hits.t[0] == expected
    assert hits.geom_id[0] == (0 if expected < math.inf else -1)


@pytest.mark.parametrize(("tmin", "tmax", "expected"),
                         [(5.0, 5.0, 5.0), (5.5, np.inf, math.inf), (0.0, 4.5, math.inf)])
def test_tmin_tmax_clip_inclusively(tmin, tmax, expected, dtype):
    assert intersect((1, 2, 5), (0, 0, -1), dtype, tmin=tmin, tmax=tmax).t[0] == expected


def test_normal_is_the_given_one_from_both_sides_and_uv_are_frame_coordinates(dtype):
    hits = intersect([(1, 2, 5), (1, 2, -5)], [(0, 0, -1), (0, 0, 1)], dtype, point=(0.5, 0, 0),
                     normal_vector=(0, 0, 7), normal=True, uv=True)
    np.testing.assert_array_equal(hits.normal, [(0, 0, 1), (0, 0, 1)])
    # the frame of a +z normal is (x, y); coordinates are measured from the given point
    np.testing.assert_array_equal(hits.uv, [(0.5, 2), (0.5, 2)])


def test_uv_are_coordinates_in_an_orthonormal_frame():
    origins = POINT + 4 * UNIT + np.array([(3.0, -1.0, 2.0), (-2.0, 4.0, 1.0), (0, 0, 0)])
    directions = np.tile([0.1, 0.2, 0.0] - UNIT, (3, 1))
    hits = intersect(origins, directions, point=POINT, normal_vector=NORMAL, normal=True,
                     uv=True)
    assert hits.hit.all()
    points = origins + hits.t[:, None] * directions
    offsets = points - POINT
    # in-plane offsets: their length is that of (u, v), whatever the frame's orientation
    np.testing.assert_allclose(np.sum(offsets * UNIT, axis=1), 0, atol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(offsets, axis=1),
                               np.linalg.norm(hits.uv, axis=1), rtol=1e-13)
    np.testing.assert_allclose(hits.normal, np.tile(UNIT, (3, 1)), rtol=1e-15)


def test_no_cancellation_far_from_the_origin(dtype):
    base = 2.0**20
    hits = intersect((base, base, base + 3), (0, 0, -1), dtype, point=(base, base, base),
                     normal_vector=(1, 1, 1))
    assert hits.t[0] == 3.0


def test_bounds_and_pack():
    params = plane.pack(POINT, NORMAL)
    assert params.shape == (analytic.PARAM_WIDTH,) and np.all(params[15:] == 0)
    lo, hi = analytic.analytic_bounds(analytic.PLANE, params)
    assert np.all(lo == -np.inf) and np.all(hi == np.inf)


@pytest.mark.parametrize(
    ("point", "normal", "name"),
    [((0, 0), (0, 0, 1), "point"), ((0, 0, np.inf), (0, 0, 1), "point"),
     ((0, 0, 0), (0, 0, 0), "normal"), ((0, 0, 0), (0, np.nan, 1), "normal"),
     ((0, 0, 0), (0, 0, 1, 0), "normal")],
)
def test_bad_shape_raises_naming_the_argument(point, normal, name):
    with pytest.raises(ValueError, match=name):
        intersect((0, 0, 5), (0, 0, -1), point=point, normal_vector=normal)


# ---------------------------------------------------------------------------- properties


@settings(max_examples=60, derandomize=True, deadline=None)
@given(origin=sampling.points, direction=sampling.directions)
def test_matches_fractions(origin, direction):
    t = intersect(origin, direction, point=POINT, normal_vector=NORMAL).t[0]
    expected = reference.plane_fraction(origin, direction, POINT, NORMAL)
    assert math.isinf(t) == math.isinf(expected)
    if not math.isinf(t):
        assert t == pytest.approx(expected, rel=1e-9, abs=1e-12)


# ---------------------------------------------------------------------------- the bar


def _in_plane(rng, count, scale):
    e1 = np.cross(UNIT, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(UNIT, e1)
    uv = rng.uniform(-scale, scale, size=(count, 2))
    return POINT + uv[:, :1] * e1 + uv[:, 1:] * e2


class Shape:
    """The plane as seen by :func:`sampling.mixed_rays` (a 3x3 patch of it)."""

    center = POINT
    size = 1.5

    def surface(self, rng, count):
        return _in_plane(rng, count, 1.5)

    def grazing(self, rng, count):
        return sampling.tangent_rays(rng, self.surface(rng, count), np.tile(UNIT, (count, 1)),
                                     self.size)

    def inside(self, rng, count):
        # an open shape: start just off either side
        return self.surface(rng, count) + rng.normal(scale=1e-3, size=(count, 1)) * UNIT


@pytest.fixture(scope="module")
def bar_case():
    rays = sampling.mixed_rays(np.random.default_rng(31), sampling.BAR_RAYS, Shape())
    expected = reference.plane(rays.origins, rays.directions, POINT, NORMAL, rays.tmin,
                               rays.tmax)
    return rays, expected


def test_bar_data_covers_the_interesting_cases(bar_case):
    rays, expected = bar_case
    hit = np.isfinite(expected)
    assert 0.3 < hit.mean() < 0.8
    assert 0.3 < hit[rays.category == "inside"].mean() < 0.7
    assert 0.3 < hit[rays.category == "grazing"].mean() < 0.7
    assert 0.1 < hit[rays.category == "clipped"].mean() < 0.9


def test_fast_reference_matches_fractions(bar_case):
    rays, expected = bar_case
    sample, slow = sampling.scalar_reference(reference.plane_fraction, rays, POINT, NORMAL)
    np.testing.assert_array_equal(slow, expected[sample])


def test_bar(bar_case, dtype):
    rays, expected = bar_case
    hits = analytic.intersect_plane(rays.origins, rays.directions, POINT, NORMAL,
                                    tmin=rays.tmin, tmax=rays.tmax, dtype=dtype)
    sampling.check_bar("plane", dtype, hits.t, expected, rays.category)
