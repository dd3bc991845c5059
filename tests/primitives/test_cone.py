import math

import numpy as np
import pytest
from hypothesis import given, settings

from raycore.primitives import analytic, cone

from . import reference, sampling

BASE = np.array([-0.5, 0.25, 0.0])
APEX = np.array([1.0, 1.25, 1.75])
RADIUS = 0.75
AXIS = (APEX - BASE) / np.linalg.norm(APEX - BASE)
SQRT_HALF = 2**-0.5


def intersect(origins, directions, dtype="float64", base=(0, 0, 0), apex=(0, 0, 1), radius=1.0,
              **options):
    return analytic.intersect_cone(np.atleast_2d(origins), np.atleast_2d(directions), base,
                                   apex, radius, dtype=dtype, **options)


def part_of(origin, direction, dtype="float64"):
    params = cone.pack((0, 0, 0), (0, 0, 1), 1.0).astype(dtype)
    ray = np.array([*origin, *direction, 0.0, np.inf], dtype=dtype)
    return analytic.analytic_hit(analytic.CONE, params, *ray, 0)[1]


# ---------------------------------------------------------------------------- analytic cases

# the 45° cone with its base (radius 1) at z = 0 and its apex at z = 1; part 0 side, 1 base
@pytest.mark.parametrize(
    ("origin", "direction", "expected", "part"),
    [
        pytest.param((-5, 0, 0.5), (1, 0, 0), 4.5, 0, id="side"),
        pytest.param((-5, 0, 0.5), (2, 0, 0), 2.25, 0, id="side-long-direction"),
        pytest.param((0.25, 0, -2), (0, 0, 1), 2.0, 1, id="base"),
        pytest.param((0, 0, 3), (0, 0, -1), 2.0, 0, id="apex"),
        pytest.param((-5, 0.5, 0.5), (1, 0, 0), 5.0, 0, id="tangent"),
        pytest.param((-5, 0.5 + 2**-20, 0.5), (1, 0, 0), math.inf, -1, id="just-past-tangent"),
        pytest.param((-5, 0, 1.5), (1, 0, 0), math.inf, -1, id="mirror-nappe-is-not-there"),
        pytest.param((-5, 0, -0.5), (1, 0, 0), math.inf, -1, id="below"),
        # a = 0: parallel to a generator
        pytest.param((0, 0, 0.5), (-1, 0, 1), 0.25, 0, id="parallel-to-surface-from-inside"),
        pytest.param((0, 0, 0.5), (1, 0, -1), 0.5, 1, id="parallel-to-surface-to-base"),
        pytest.param((2, 0, 0.5), (-1, 0, 1), math.inf, -1, id="parallel-to-surface-outside"),
        pytest.param((-2, 0, -1), (1, 0, 1), 1.0, 1, id="on-a-generator-hits-the-rim"),
        pytest.param((5, 0, 1), (1, 0, 0), math.inf, -1, id="behind"),
        pytest.param((0, 0, 0.25), (1, 0, 0), 0.75, 0, id="inside-side"),
        pytest.param((0, 0, 0.25), (0, 0, -1), 0.25, 1, id="inside-base"),
    ],
)
def test_simple_rays(origin, direction, expected, part, dtype):
    hits = intersect(origin, direction, dtype)
    assert hits.t[0] == expected
    assert hits.geom_id[0] == (0 if expected < math.inf else -1)
    assert part_of(origin, direction, dtype) == part


@pytest.mark.parametrize(("tmin", "tmax", "expected"),
                         [(4.5, np.inf, 4.5), (4.6, np.inf, 5.5), (0.0, 4.0, math.inf),
                          (6.0, np.inf, math.inf)])
def test_tmin_tmax_clip_inclusively(tmin, tmax, expected, dtype):
    assert intersect((-5, 0, 0.5), (1, 0, 0), dtype, tmin=tmin, tmax=tmax).t[0] == expected


@pytest.mark.parametrize(
    ("origin", "direction", "normal", "uv"),
    [
        # side: the normal leans towards the apex; u is the angle from e1 = +x towards e2 = +y,
        # v goes from 0 at the base to 1 at the apex
        ((-5, 0, 0.5), (1, 0, 0), (-SQRT_HALF, 0, SQRT_HALF), (0.5, 0.5)),
        ((0, 5, 0.25), (0, -1, 0), (0, SQRT_HALF, SQRT_HALF), (0.25, 0.25)),
        ((0, 0, 3), (0, 0, -1), (0, 0, 1), (0, 1)),  # the apex: the axis
        # base: polar
        ((0.25, 0, -2), (0, 0, 1), (0, 0, -1), (0, 0.25)),
        ((-0.5, 0, -2), (0, 0, 1), (0, 0, -1), (0.5, 0.5)),
    ],
)
def test_normal_is_outward_and_uv_as_documented(origin, direction, normal, uv, dtype):
    hits = intersect(origin, direction, dtype, normal=True, uv=True)
    np.testing.assert_allclose(hits.normal[0], normal, atol=1e-7)
    np.testing.assert_allclose(hits.uv[0], uv, atol=1e-7)


def test_bounds_and_pack():
    params = cone.pack(BASE, APEX, RADIUS)
    assert params.shape == (analytic.PARAM_WIDTH,) and np.all(params[19:] == 0)
    lo, hi = analytic.analytic_bounds(analytic.CONE, params)
    extent = RADIUS * np.sqrt(1 - AXIS**2)
    exact_lo = np.minimum(BASE - extent, APEX)
    exact_hi = np.maximum(BASE + extent, APEX)
    np.testing.assert_allclose(lo, exact_lo, atol=1e-13)
    np.testing.assert_allclose(hi, exact_hi, atol=1e-13)
    assert np.all(lo <= exact_lo) and np.all(hi >= exact_hi)


@pytest.mark.parametrize(
    ("base", "apex", "radius", "name"),
    [((0, 0), (0, 0, 1), 1.0, "base_center"), ((0, 0, 0), (0, np.inf, 1), 1.0, "apex"),
     ((1, 2, 3), (1, 2, 3), 1.0, "apex"), ((0, 0, 0), (0, 0, 1), 0.0, "radius"),
     ((0, 0, 0), (0, 0, 1), np.nan, "radius"),
     # (radius / height)^2 overflows: it raised OverflowError, a 500 from the service
     ((0, 0, 0), (0, 0, 1e-300), 1.0, "apex")],
)
def test_bad_shape_raises_naming_the_argument(base, apex, radius, name):
    with pytest.raises(ValueError, match=name):
        intersect((0, 0, 5), (0, 0, -1), base=base, apex=apex, radius=radius)


# ---------------------------------------------------------------------------- properties


@settings(max_examples=60, derandomize=True, deadline=None)
@given(origin=sampling.points, direction=sampling.directions)
def test_matches_mpmath(origin, direction):
    hits = intersect(origin, direction, base=BASE, apex=APEX, radius=RADIUS, normal=True,
                     uv=True)
    t = hits.t[0]
    expected = reference.cone_mpmath(origin, direction, BASE, APEX, RADIUS)
    assert math.isinf(t) == math.isinf(expected)
    if not math.isinf(t):
        assert t == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert np.linalg.norm(hits.normal[0]) == pytest.approx(1.0, abs=1e-12)
        # outward: a convex body lies behind its surface
        point = np.add(origin, t * np.asarray(direction))
        assert np.dot(hits.normal[0], point - (3 * BASE + APEX) / 4) > 0
        assert 0 <= hits.uv[0, 0] < 1 and 0 <= hits.uv[0, 1] <= 1


# ---------------------------------------------------------------------------- the bar


def _radial(rng, count):
    e1 = np.cross(AXIS, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(AXIS, e1)
    angle = rng.uniform(0, 2 * np.pi, size=(count, 1))
    return np.cos(angle) * e1 + np.sin(angle) * e2


def _side_normals(radial):
    """Outward unit normals of the side along the generators through ``radial``."""
    height = np.linalg.norm(APEX - BASE)
    normals = height * radial + RADIUS * AXIS
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


class Shape:
    """The cone as seen by :func:`sampling.mixed_rays`."""

    center = (3 * BASE + APEX) / 4
    size = float(np.linalg.norm(APEX - BASE) / 2)

    def surface(self, rng, count):
        # the side (area-uniform along the generators) or, in proportion, the base
        slant = np.linalg.norm(APEX - BASE + RADIUS * AXIS)
        base = rng.random(count) < RADIUS / (RADIUS + slant)
        fraction = np.sqrt(rng.random((count, 1)))
        rim = BASE + RADIUS * _radial(rng, count)
        return np.where(base[:, None], BASE + fraction * (rim - BASE),
                        APEX + fraction * (rim - APEX))

    def grazing(self, rng, count):
        """A third each: tangent to the side, through the rim, parallel to generators."""
        third = count // 3
        radial = _radial(rng, count)
        rim = BASE + RADIUS * radial
        fraction = rng.random((count, 1))
        side = APEX + fraction * (rim - APEX)
        tangent = sampling.tangent_rays(rng, side[:third], _side_normals(radial[:third]),
                                        self.size)
        directions = sampling.random_directions(rng, count)
        directions[:third] = tangent[1]
        # along the generator, moved off it a little: a is (nearly) zero
        parallel = slice(2 * third, count)
        directions[parallel] = (rim - APEX)[parallel]
        points = np.concatenate([side[:third], rim[third:2 * third],
                                 side[parallel] + rng.normal(scale=0.05, size=(count - 2 * third,
                                                                                3))])
        return points - 4 * directions, directions

    def inside(self, rng, count):
        along = 0.0005 + 0.999 * rng.random((count, 1))
        out = 0.999 * np.sqrt(rng.random((count, 1))) * RADIUS * (1 - along)
        return BASE + along * (APEX - BASE) + out * _radial(rng, count)


@pytest.fixture(scope="module")
def bar_case():
    rays = sampling.mixed_rays(np.random.default_rng(97), sampling.BAR_RAYS, Shape())
    expected = reference.cone(rays.origins, rays.directions, BASE, APEX, RADIUS, rays.tmin,
                              rays.tmax)
    return rays, expected


def test_bar_data_covers_the_interesting_cases(bar_case):
    sampling.check_solid_bar_data(*bar_case)


def test_fast_reference_matches_mpmath(bar_case):
    rays, expected = bar_case
    sample, slow = sampling.scalar_reference(reference.cone_mpmath, rays, BASE, APEX, RADIUS)
    np.testing.assert_array_equal(slow, expected[sample])


def test_bar(bar_case, dtype):
    rays, expected = bar_case
    hits = analytic.intersect_cone(rays.origins, rays.directions, BASE, APEX, RADIUS,
                                   tmin=rays.tmin, tmax=rays.tmax, dtype=dtype)
    sampling.check_bar("cone", dtype, hits.t, expected, rays.category)
