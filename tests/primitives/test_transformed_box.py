import math

import numpy as np
import pytest
from hypothesis import given, settings

from raycore.primitives import analytic, box

from . import reference, sampling
from .test_box import _on_edges, _on_faces

LO = np.array([-1.0, -0.5, 0.25])
HI = np.array([0.75, 1.5, 2.0])


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _affine(linear, translation):
    matrix = np.eye(4)
    matrix[:3, :3] = linear
    matrix[:3, 3] = translation
    return matrix


# rotated, scaled unevenly and moved; entries rounded to float32 so that both precisions see
# the same box
TRANSFORM = _affine(_rotation((1, 2, 2), 0.7) @ np.diag([1.5, 0.75, 1.25]), (0.5, -1, 2))
TRANSFORM = TRANSFORM.astype(np.float32).astype(np.float64)
SHEAR = _affine([[1, 0, 1], [0, 1, 0], [0, 0, 1]], (0, 0, 0))


def intersect(origins, directions, transform, dtype="float64", lo=(0, 0, 0), hi=(1, 1, 1),
              **options):
    return analytic.intersect_transformed_box(np.atleast_2d(origins), np.atleast_2d(directions),
                                              lo, hi, transform, dtype=dtype, **options)


def world(points, transform=TRANSFORM):
    return points @ transform[:3, :3].T + transform[:3, 3]


# ---------------------------------------------------------------------------- analytic cases


def test_scale_and_translation(dtype):
    transform = _affine(np.diag([2.0, 3.0, 4.0]), (1, 2, 3))
    hits = intersect([(-5, 2, 3), (1, 2, 3), (1, 2, 20)], [(1, 0, 0), (0, 0, 1), (0, 0, -2)],
                     transform, dtype, lo=(-1, -1, -1), hi=(1, 1, 1), normal=True, uv=True)
    np.testing.assert_array_equal(hits.t, [4.0, 4.0, 6.5])
    np.testing.assert_array_equal(hits.normal, [(-1, 0, 0), (0, 0, 1), (0, 0, 1)])
    np.testing.assert_allclose(hits.uv, [(0.5, 0.5)] * 3)


def test_rotation_maps_faces_and_normals(dtype):
    # 90° about z: local x -> world y, local y -> world -x; the box covers x in [-2, 0]
    transform = _affine(_rotation((0, 0, 1), np.pi / 2).round(15), (0, 0, 0))
    hits = intersect((5, 0.5, 1.5), (-1, 0, 0), transform, dtype, hi=(1, 2, 3), normal=True)
    assert hits.t[0] == pytest.approx(5.0, rel=1e-6)
    np.testing.assert_allclose(hits.normal[0], (1, 0, 0), atol=1e-7)
    params = box.pack_transformed((0, 0, 0), (1, 2, 3), transform).astype(dtype)
    ray = np.array([5, 0.5, 1.5, -1, 0, 0, 0, np.inf], dtype=dtype)
    assert analytic.analytic_hit(analytic.TRANSFORMED_BOX, params, *ray, 0)[1] == 2  # local -y


def test_shear_normals_use_the_inverse_transpose(dtype):
    # x += z: the +x face leans, so its normal is (1, 0, -1) / √2, not the sheared (1, 0, 0)
    hits = intersect([(5, 0.5, 0.5), (1.5, 0.5, 5)], [(-1, 0, 0), (0, 0, -1)], SHEAR, dtype,
                     normal=True)
    np.testing.assert_allclose(hits.t, [3.5, 4.0], rtol=1e-7)
    np.testing.assert_allclose(hits.normal, [(2**-0.5, 0, -(2**-0.5)), (0, 0, 1)], atol=1e-7)


def test_identity_matches_the_axis_aligned_box():
    rng = np.random.default_rng(3)
    origins = rng.uniform(-4, 4, size=(2000, 3))
    directions = rng.uniform(LO - 0.5, HI + 0.5, size=(2000, 3)) - origins
    plain = analytic.intersect_box(origins, directions, LO, HI)
    transformed = intersect(origins, directions, np.eye(4), lo=LO, hi=HI)
    assert 0.1 < plain.hit.mean() < 0.9
    np.testing.assert_array_equal(transformed.t, plain.t)


def test_bounds_and_pack():
    params = box.pack_transformed((0, 0, 0), (1, 1, 1), SHEAR)
    assert params.shape == (analytic.PARAM_WIDTH,) and np.all(params[18:] == 0)
    lo, hi = analytic.analytic_bounds(analytic.TRANSFORMED_BOX, params)
    np.testing.assert_allclose(lo, (0, 0, 0), atol=1e-14)
    np.testing.assert_allclose(hi, (2, 1, 1), atol=1e-14)
    lo, hi = analytic.analytic_bounds(analytic.TRANSFORMED_BOX,
                                      box.pack_transformed(LO, HI, TRANSFORM))
    corners = world(np.array(np.meshgrid(*zip(LO, HI, strict=True))).reshape(3, -1).T)
    assert np.all(lo <= corners.min(axis=0)) and np.all(hi >= corners.max(axis=0))
    np.testing.assert_allclose(lo, corners.min(axis=0), atol=1e-13)
    np.testing.assert_allclose(hi, corners.max(axis=0), atol=1e-13)


@pytest.mark.parametrize(
    ("transform", "lo", "name"),
    [(np.eye(3, 4), (0, 0, 0), "transform"),
     (np.diag([1.0, 1, np.nan, 1]), (0, 0, 0), "transform"),
     (_affine(np.eye(3), (0, 0, 0)) + np.eye(4, k=-1) * [0, 0, 1, 0], (0, 0, 0), "transform"),
     (_affine(np.diag([1.0, 0.0, 1.0]), (0, 0, 0)), (0, 0, 0), "transform"),
     (_affine(np.diag([1.0, 1e-10, 1.0]), (0, 0, 0)), (0, 0, 0), "transform"),
     (np.eye(4), (2, 0, 0), "hi")],
)
def test_bad_shape_raises_naming_the_argument(transform, lo, name):
    with pytest.raises(ValueError, match=name):
        intersect((0, 0, 5), (0, 0, -1), transform, lo=lo)


# ---------------------------------------------------------------------------- properties


@settings(max_examples=60, derandomize=True, deadline=None)
@given(origin=sampling.points, direction=sampling.directions)
def test_matches_fractions(origin, direction):
    hits = intersect(origin, direction, TRANSFORM, lo=LO, hi=HI, normal=True, uv=True)
    t = hits.t[0]
    expected = reference.transformed_box_fraction(origin, direction, LO, HI, TRANSFORM)
    assert math.isinf(t) == math.isinf(expected)
    if not math.isinf(t):
        assert t == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert np.linalg.norm(hits.normal[0]) == pytest.approx(1.0, abs=1e-12)
        # outward: a convex body lies behind each of its faces
        point = np.add(origin, t * np.asarray(direction))
        assert np.dot(hits.normal[0], point - world((LO + HI) / 2)) > 0
        assert np.all((0 <= hits.uv[0]) & (hits.uv[0] <= 1))


# ---------------------------------------------------------------------------- the bar


class Shape:
    """The transformed box as seen by :func:`sampling.mixed_rays`."""

    center = world((LO + HI) / 2)
    size = 1.5

    def surface(self, rng, count):
        return world(_on_faces(rng, count, LO, HI)[0])

    def grazing(self, rng, count):
        """Half through edges from any direction, half along edges."""
        half = count // 2
        points, free = _on_edges(rng, count, LO, HI)
        directions = sampling.random_directions(rng, count)
        directions[half:] = TRANSFORM[:3, free[half:]].T * rng.choice([-1, 1], (count - half, 1))
        return world(points) - 4 * directions, directions

    def inside(self, rng, count):
        return world(LO + (0.0005 + 0.999 * rng.random((count, 3))) * (HI - LO))


@pytest.fixture(scope="module")
def bar_case():
    rays = sampling.mixed_rays(np.random.default_rng(71), sampling.BAR_RAYS, Shape())
    expected = reference.transformed_box(rays.origins, rays.directions, LO, HI, TRANSFORM,
                                         rays.tmin, rays.tmax)
    return rays, expected


def test_bar_data_covers_the_interesting_cases(bar_case):
    rays, expected = bar_case
    hit = np.isfinite(expected)
    assert 0.3 < hit.mean() < 0.8
    assert hit[rays.category == "inside"].all()
    assert 0.5 < hit[rays.category == "grazing"].mean() < 1
    assert 0.1 < hit[rays.category == "clipped"].mean() < 0.9


def test_fast_reference_matches_fractions(bar_case):
    rays, expected = bar_case
    sample, slow = sampling.scalar_reference(reference.transformed_box_fraction, rays,
                                             LO, HI, TRANSFORM, count=200)
    np.testing.assert_array_equal(slow, expected[sample])


def test_bar(bar_case, dtype):
    rays, expected = bar_case
    hits = analytic.intersect_transformed_box(rays.origins, rays.directions, LO, HI, TRANSFORM,
                                              tmin=rays.tmin, tmax=rays.tmax, dtype=dtype)
    sampling.check_bar("transformed box", dtype, hits.t, expected, rays.category)
