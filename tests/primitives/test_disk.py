import math

import numpy as np
import pytest
from hypothesis import given, settings

from raycore.primitives import analytic, disk

from . import reference, sampling

CENTER = np.array([0.5, 0.25, -0.75])
NORMAL = np.array([0.25, -1.0, 0.5])
UNIT = NORMAL / np.linalg.norm(NORMAL)
RADIUS = 1.5


def intersect(origins, directions, dtype="float64", center=(0, 0, 0), normal_vector=(0, 0, 1),
              radius=1.0, **options):
    return analytic.intersect_disk(np.atleast_2d(origins), np.atleast_2d(directions), center,
                                   normal_vector, radius, dtype=dtype, **options)


# ---------------------------------------------------------------------------- analytic cases


@pytest.mark.parametrize(
    ("origin", "direction", "expected"),
    [
        pytest.param((0.5, 0, 3), (0, 0, -1), 3.0, id="from-above"),
        pytest.param((0.5, 0, -3), (0, 0, 2), 1.5, id="from-below"),
        pytest.param((1, 0, 3), (0, 0, -1), 3.0, id="rim"),
        pytest.param((0, -1, 3), (0, 0, -1), 3.0, id="rim-negative"),
        pytest.param((1 + 2**-20, 0, 3), (0, 0, -1), math.inf, id="just-outside-rim"),
        pytest.param((2, 0, 3), (0, 0, -1), math.inf, id="outside"),
        pytest.param((-2, 0, 1), (1, 0, -0.5), 2.0, id="oblique"),
        pytest.param((0, 0, 1), (1, 0, 0), math.inf, id="parallel"),
        pytest.param((-3, 0, 0), (1, 0, 0), math.inf, id="in-plane"),
        pytest.param((0, 0, 3), (0, 0, 1), math.inf, id="behind"),
    ],
)
def test_simple_rays(origin, direction, expected, dtype):
    hits = intersect(origin, direction, dtype)
    assert hits.t[0] == expected
    assert hits.geom_id[0] == (0 if expected < math.inf else -1)


@pytest.mark.parametrize(("tmin", "tmax", "expected"),
                         [(3.0, 3.0, 3.0), (3.5, np.inf, math.inf), (0.0, 2.5, math.inf)])
def test_tmin_tmax_clip_inclusively(tmin, tmax, expected, dtype):
    assert intersect((0, 0, 3), (0, 0, -1), dtype, tmin=tmin, tmax=tmax).t[0] == expected


@pytest.mark.parametrize(
    ("x", "y", "uv"),
    [(0.5, 0, (0, 0.25)), (0, 0.5, (0.25, 0.25)), (-2, 0, (0.5, 1)), (0, -1, (0.75, 0.5)),
     (0, 0, (0, 0))],
)
def test_normal_and_polar_uv(x, y, uv, dtype):
    # for a +z normal the frame is (x, y): u is the angle from +x over 2π, v the radius over r
    hits = intersect([(x, y, 3), (x, y, -3)], [(0, 0, -1), (0, 0, 1)], dtype, radius=2.0,
                     normal=True, uv=True)
    np.testing.assert_array_equal(hits.normal, [(0, 0, 1), (0, 0, 1)])
    np.testing.assert_allclose(hits.uv, [uv, uv], atol=1e-7)


def test_bounds_and_pack():
    params = disk.pack(CENTER, NORMAL, RADIUS)
    assert params.shape == (analytic.PARAM_WIDTH,) and np.all(params[17:] == 0)
    lo, hi = analytic.analytic_bounds(analytic.DISK, params)
    extent = RADIUS * np.sqrt(1 - UNIT**2)
    np.testing.assert_allclose(lo, CENTER - extent, atol=1e-13)
    np.testing.assert_allclose(hi, CENTER + extent, atol=1e-13)
    assert np.all(lo <= CENTER - extent) and np.all(hi >= CENTER + extent)


@pytest.mark.parametrize(
    ("center", "normal", "radius", "name"),
    [((0, 0), (0, 0, 1), 1.0, "center"), ((0, 0, 0), (0, 0, 0), 1.0, "normal"),
     ((0, 0, 0), (np.inf, 0, 1), 1.0, "normal"), ((0, 0, 0), (0, 0, 1), 0.0, "radius"),
     ((0, 0, 0), (0, 0, 1), -2.0, "radius"), ((0, 0, 0), (0, 0, 1), np.nan, "radius")],
)
def test_bad_shape_raises_naming_the_argument(center, normal, radius, name):
    with pytest.raises(ValueError, match=name):
        intersect((0, 0, 5), (0, 0, -1), center=center, normal_vector=normal, radius=radius)


# ---------------------------------------------------------------------------- properties


@settings(max_examples=60, derandomize=True, deadline=None)
@given(origin=sampling.points, direction=sampling.directions)
def test_matches_fractions(origin, direction):
    hits = intersect(origin, direction, center=CENTER, normal_vector=NORMAL, radius=RADIUS,
                     normal=True, uv=True)
    t = hits.t[0]
    expected = reference.disk_fraction(origin, direction, CENTER, NORMAL, RADIUS)
    assert math.isinf(t) == math.isinf(expected)
    if not math.isinf(t):
        assert t == pytest.approx(expected, rel=1e-9, abs=1e-12)
        np.testing.assert_allclose(hits.normal[0], UNIT, rtol=1e-15)
        assert 0 <= hits.uv[0, 0] < 1 and 0 <= hits.uv[0, 1] <= 1


# ---------------------------------------------------------------------------- the bar


def _frame():
    e1 = np.cross(UNIT, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(UNIT, e1)


def _polar(rng, count, radius):
    e1, e2 = _frame()
    angle = rng.uniform(0, 2 * np.pi, size=(count, 1))
    return CENTER + radius * (np.cos(angle) * e1 + np.sin(angle) * e2)


class Shape:
    """The disk as seen by :func:`sampling.mixed_rays`."""

    center = CENTER
    size = RADIUS

    def surface(self, rng, count):
        return _polar(rng, count, RADIUS * np.sqrt(rng.random((count, 1))))

    def grazing(self, rng, count):
        # half through the rim from any direction, half nearly in the disk's plane
        half = count // 2
        directions = sampling.random_directions(rng, half)
        rim = _polar(rng, half, RADIUS)
        along = sampling.tangent_rays(rng, self.surface(rng, count - half),
                                      np.tile(UNIT, (count - half, 1)), RADIUS)
        return (np.concatenate([rim - 3 * directions, along[0]]),
                np.concatenate([directions, along[1]]))

    def inside(self, rng, count):
        # an open shape: start just off either side
        return self.surface(rng, count) + rng.normal(scale=1e-3, size=(count, 1)) * UNIT


@pytest.fixture(scope="module")
def bar_case():
    rays = sampling.mixed_rays(np.random.default_rng(47), sampling.BAR_RAYS, Shape())
    expected = reference.disk(rays.origins, rays.directions, CENTER, NORMAL, RADIUS, rays.tmin,
                              rays.tmax)
    return rays, expected


def test_bar_data_covers_the_interesting_cases(bar_case):
    rays, expected = bar_case
    hit = np.isfinite(expected)
    assert 0.2 < hit.mean() < 0.8
    assert 0.3 < hit[rays.category == "inside"].mean() < 0.7
    assert 0.2 < hit[rays.category == "grazing"].mean() < 0.8
    assert 0.1 < hit[rays.category == "clipped"].mean() < 0.9


def test_fast_reference_matches_fractions(bar_case):
    rays, expected = bar_case
    sample, slow = sampling.scalar_reference(reference.disk_fraction, rays, CENTER, NORMAL, RADIUS)
    np.testing.assert_array_equal(slow, expected[sample])


def test_bar(bar_case, dtype):
    rays, expected = bar_case
    hits = analytic.intersect_disk(rays.origins, rays.directions, CENTER, NORMAL, RADIUS,
                                   tmin=rays.tmin, tmax=rays.tmax, dtype=dtype)
    sampling.check_bar("disk", dtype, hits.t, expected, rays.category)
