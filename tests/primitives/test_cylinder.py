import math

import numpy as np
import pytest
from hypothesis import given, settings

from raycore.primitives import analytic, cylinder

from . import reference, sampling

P0 = np.array([0.25, -0.5, 0.125])
P1 = np.array([1.5, 0.75, 2.0])
RADIUS = 0.625
AXIS = (P1 - P0) / np.linalg.norm(P1 - P0)


def intersect(origins, directions, dtype="float64", p0=(0, 0, 0), p1=(0, 0, 2), radius=1.0,
              **options):
    return analytic.intersect_cylinder(np.atleast_2d(origins), np.atleast_2d(directions), p0,
                                       p1, radius, dtype=dtype, **options)


def part_of(origin, direction, dtype="float64"):
    params = cylinder.pack((0, 0, 0), (0, 0, 2), 1.0).astype(dtype)
    ray = np.array([*origin, *direction, 0.0, np.inf], dtype=dtype)
    return analytic.analytic_hit(analytic.CYLINDER, params, *ray, 0)[1]


# ---------------------------------------------------------------------------- analytic cases

# the cylinder from (0, 0, 0) to (0, 0, 2) with radius 1; parts 0 side, 1 cap at p0, 2 at p1
@pytest.mark.parametrize(
    ("origin", "direction", "expected", "part"),
    [
        pytest.param((-5, 0, 1), (1, 0, 0), 4.0, 0, id="side"),
        pytest.param((-5, 0, 1), (0.5, 0, 0), 8.0, 0, id="side-short-direction"),
        pytest.param((0.5, 0, -3), (0, 0, 1), 3.0, 1, id="cap-p0"),
        pytest.param((0, 0.5, 5), (0, 0, -1), 3.0, 2, id="cap-p1"),
        pytest.param((-5, 1, 1), (1, 0, 0), 5.0, 0, id="tangent-side"),
        pytest.param((-5, 1 + 2**-20, 1), (1, 0, 0), math.inf, -1, id="just-past-tangent"),
        pytest.param((1, 0, -3), (0, 0, 1), 3.0, 1, id="along-side-hits-rim"),
        pytest.param((0.5, 0.5, -1), (0, 0, 1), 1.0, 1, id="parallel-to-axis"),
        pytest.param((2, 0, -1), (0, 0, 1), math.inf, -1, id="parallel-to-axis-outside"),
        pytest.param((-5, 0, 3), (1, 0, 0), math.inf, -1, id="above"),
        pytest.param((-5, 0, 2), (1, 0, 0), 4.0, 0, id="in-top-plane"),
        pytest.param((-3, 0, 3), (1, 0, -1), 2.0, 0, id="through-rim"),
        pytest.param((5, 0, 1), (1, 0, 0), math.inf, -1, id="behind"),
        pytest.param((0, 0, 1), (1, 0, 0), 1.0, 0, id="inside-side"),
        pytest.param((0, 0, 1), (0, 0, 1), 1.0, 2, id="inside-cap"),
    ],
)
def test_simple_rays(origin, direction, expected, part, dtype):
    hits = intersect(origin, direction, dtype)
    assert hits.t[0] == expected
    assert hits.geom_id[0] == (0 if expected < math.inf else -1)
    assert part_of(origin, direction, dtype) == part


@pytest.mark.parametrize(("tmin", "tmax", "expected"),
                         [(4.0, np.inf, 4.0), (4.5, np.inf, 6.0), (0.0, 3.5, math.inf),
                          (6.5, np.inf, math.inf)])
def test_tmin_tmax_clip_inclusively(tmin, tmax, expected, dtype):
    assert intersect((-5, 0, 1), (1, 0, 0), dtype, tmin=tmin, tmax=tmax).t[0] == expected


@pytest.mark.parametrize(
    ("origin", "direction", "normal", "uv"),
    [
        # side: u is the angle around the axis from e1 = +x towards e2 = +y, v the height / h
        ((-5, 0, 1), (1, 0, 0), (-1, 0, 0), (0.5, 0.5)),
        ((0, 5, 0.5), (0, -1, 0), (0, 1, 0), (0.25, 0.25)),
        ((0, 0, 1.5), (1, 0, 0), (1, 0, 0), (0, 0.75)),
        # caps: polar, v = distance from the axis / radius
        ((0.5, 0, -3), (0, 0, 1), (0, 0, -1), (0, 0.5)),
        ((0, -0.25, 5), (0, 0, -1), (0, 0, 1), (0.75, 0.25)),
    ],
)
def test_normal_is_outward_and_uv_as_documented(origin, direction, normal, uv, dtype):
    hits = intersect(origin, direction, dtype, normal=True, uv=True)
    np.testing.assert_allclose(hits.normal[0], normal, atol=1e-7)
    np.testing.assert_allclose(hits.uv[0], uv, atol=1e-7)


def test_bounds_and_pack():
    params = cylinder.pack(P0, P1, RADIUS)
    assert params.shape == (analytic.PARAM_WIDTH,) and np.all(params[18:] == 0)
    lo, hi = analytic.analytic_bounds(analytic.CYLINDER, params)
    extent = RADIUS * np.sqrt(1 - AXIS**2)
    np.testing.assert_allclose(lo, np.minimum(P0, P1) - extent, atol=1e-13)
    np.testing.assert_allclose(hi, np.maximum(P0, P1) + extent, atol=1e-13)
    assert np.all(lo <= np.minimum(P0, P1) - extent)
    assert np.all(hi >= np.maximum(P0, P1) + extent)


@pytest.mark.parametrize(
    ("p0", "p1", "radius", "name"),
    [((0, 0), (0, 0, 1), 1.0, "p0"), ((0, 0, 0), (0, 0, np.nan), 1.0, "p1"),
     ((1, 2, 3), (1, 2, 3), 1.0, "p1"), ((0, 0, 0), (0, 0, 1), 0.0, "radius"),
     ((0, 0, 0), (0, 0, 1), -1.0, "radius"), ((0, 0, 0), (0, 0, 1), np.inf, "radius")],
)
def test_bad_shape_raises_naming_the_argument(p0, p1, radius, name):
    with pytest.raises(ValueError, match=name):
        intersect((0, 0, 5), (0, 0, -1), p0=p0, p1=p1, radius=radius)


# ---------------------------------------------------------------------------- properties


@settings(max_examples=60, derandomize=True, deadline=None)
@given(origin=sampling.points, direction=sampling.directions)
def test_matches_mpmath(origin, direction):
    hits = intersect(origin, direction, p0=P0, p1=P1, radius=RADIUS, normal=True, uv=True)
    t = hits.t[0]
    expected = reference.cylinder_mpmath(origin, direction, P0, P1, RADIUS)
    assert math.isinf(t) == math.isinf(expected)
    if not math.isinf(t):
        assert t == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert np.linalg.norm(hits.normal[0]) == pytest.approx(1.0, abs=1e-12)
        # outward: a convex body lies behind its surface
        point = np.add(origin, t * np.asarray(direction))
        assert np.dot(hits.normal[0], point - (P0 + P1) / 2) > 0
        assert 0 <= hits.uv[0, 0] < 1 and 0 <= hits.uv[0, 1] <= 1


# ---------------------------------------------------------------------------- the bar


def _frame():
    e1 = np.cross(AXIS, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(AXIS, e1)


def _radial(rng, count):
    e1, e2 = _frame()
    angle = rng.uniform(0, 2 * np.pi, size=(count, 1))
    return np.cos(angle) * e1 + np.sin(angle) * e2


class Shape:
    """The cylinder as seen by :func:`sampling.mixed_rays`."""

    center = (P0 + P1) / 2
    size = float(np.linalg.norm(P1 - P0) / 2)

    def surface(self, rng, count):
        # a point on the side or, in proportion to the areas, on a cap
        height = np.linalg.norm(P1 - P0)
        cap = rng.random(count) < RADIUS / (RADIUS + height)
        along = np.where(cap, rng.integers(0, 2, count), rng.random(count))[:, None]
        out = np.where(cap, np.sqrt(rng.random(count)), 1.0)[:, None] * RADIUS
        return P0 + along * (P1 - P0) + out * _radial(rng, count)

    def grazing(self, rng, count):
        """A third each: tangent to the side, through the rims, parallel to the axis."""
        third = count // 3
        radial = _radial(rng, count)
        along = rng.random((count, 1))
        along[third:2 * third] = rng.integers(0, 2, (third, 1))
        points = P0 + along * (P1 - P0) + RADIUS * radial
        tangent = sampling.tangent_rays(rng, points[:third], radial[:third], self.size)
        directions = sampling.random_directions(rng, count)
        directions[:third] = tangent[1]
        # exactly parallel to the axis: p1 - p0 times a power of two
        directions[2 * third:] = (P1 - P0) * 2.0 ** rng.integers(-3, 3, (count - 2 * third, 1))
        return points - 4 * directions, directions

    def inside(self, rng, count):
        along = 0.0005 + 0.999 * rng.random((count, 1))
        out = 0.999 * RADIUS * np.sqrt(rng.random((count, 1)))
        return P0 + along * (P1 - P0) + out * _radial(rng, count)


@pytest.fixture(scope="module")
def bar_case():
    rays = sampling.mixed_rays(np.random.default_rng(83), sampling.BAR_RAYS, Shape())
    expected = reference.cylinder(rays.origins, rays.directions, P0, P1, RADIUS, rays.tmin,
                                  rays.tmax)
    return rays, expected


def test_bar_data_covers_the_interesting_cases(bar_case):
    sampling.check_solid_bar_data(*bar_case)


def test_fast_reference_matches_mpmath(bar_case):
    rays, expected = bar_case
    sample, slow = sampling.scalar_reference(reference.cylinder_mpmath, rays, P0, P1, RADIUS)
    np.testing.assert_array_equal(slow, expected[sample])


def test_bar(bar_case, dtype):
    rays, expected = bar_case
    hits = analytic.intersect_cylinder(rays.origins, rays.directions, P0, P1, RADIUS,
                                       tmin=rays.tmin, tmax=rays.tmax, dtype=dtype)
    sampling.check_bar("cylinder", dtype, hits.t, expected, rays.category)
