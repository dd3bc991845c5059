import math

import numpy as np
import pytest
from hypothesis import given, settings

from raycore.primitives import analytic, box

from . import reference, sampling

LO = np.array([-1.0, -0.5, 0.25])
HI = np.array([0.75, 1.5, 2.0])
FACE_NORMALS = [(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, -1), (0, 0, 1)]


def intersect(origins, directions, dtype="float64", lo=(-1, -1, -1), hi=(1, 1, 1), **options):
    return analytic.intersect_box(np.atleast_2d(origins), np.atleast_2d(directions), lo, hi,
                                  dtype=dtype, **options)


def part_of(origin, direction, dtype="float64", lo=(-1, -1, -1), hi=(1, 1, 1), tmin=0.0,
            tmax=np.inf):
    """``(t, face)`` from the kernel itself."""
    params = box.pack(lo, hi).astype(dtype)
    ray = np.array([*origin, *direction, tmin, tmax], dtype=dtype)
    return analytic.analytic_hit(analytic.BOX, params, *ray, 0)


# ---------------------------------------------------------------------------- analytic cases


@pytest.mark.parametrize(
    ("origin", "direction", "expected"),
    [
        pytest.param((-5, 0, 0), (1, 0, 0), 4.0, id="hit"),
        pytest.param((-5, 0, 0), (4, 0, 0), 1.0, id="long-direction"),
        pytest.param((-5, 2, 0), (1, 0, 0), math.inf, id="miss"),
        pytest.param((5, 0, 0), (1, 0, 0), math.inf, id="behind"),
        pytest.param((0, 0, 0), (0, 0, 1), 1.0, id="inside"),
        pytest.param((-2, -2, -2), (1, 1, 1), 1.0, id="corner"),
        pytest.param((-5, 1, 0), (1, 0, 0), 4.0, id="in-face-plane"),
        pytest.param((-5, 1, 0), (1, -0.0, 0), 4.0, id="in-face-plane-negative-zero"),
        pytest.param((-5, 1, 1), (1, 0, 0), 4.0, id="along-edge"),
        pytest.param((-5, -1, -1), (1, -0.0, -0.0), 4.0, id="along-edge-negative-zeros"),
        pytest.param((-5, 1 + 2**-20, 0), (1, 0, 0), math.inf, id="just-outside-face-plane"),
        pytest.param((-1, 0, 0), (1, 0, 0), 0.0, id="origin-on-face"),
        pytest.param((1, 0, 0), (1, 0, 0), 0.0, id="origin-on-face-leaving"),
        pytest.param((-3, 2, 0), (1, -1, 0), 2.0, id="through-edge"),
    ],
)
def test_simple_rays(origin, direction, expected, dtype):
    hits = intersect(origin, direction, dtype)
    assert hits.t[0] == expected
    assert hits.geom_id[0] == (0 if expected < math.inf else -1)


@pytest.mark.parametrize(("tmin", "tmax", "expected", "face"),
                         [(4.0, np.inf, 4.0, 0), (4.5, np.inf, 6.0, 1), (0.0, 3.5, math.inf, -1),
                          (6.5, np.inf, math.inf, -1), (4.5, 5.5, math.inf, -1)])
def test_tmin_tmax_clip_inclusively(tmin, tmax, expected, face, dtype):
    assert intersect((-5, 0, 0), (1, 0, 0), dtype, tmin=tmin, tmax=tmax).t[0] == expected
    assert part_of((-5, 0, 0), (1, 0, 0), dtype, tmin=tmin, tmax=tmax) == (expected, face)


@pytest.mark.parametrize("face", range(6))
def test_faces_normals_and_uv(face, dtype):
    """From outside and from the centre: the part, the outward normal, and face-local uv."""
    axis = face // 2
    normal = np.array(FACE_NORMALS[face], dtype=float)
    lo, hi = np.array([-1.0, -2.0, -4.0]), np.array([3.0, 2.0, 0.0])
    center = (lo + hi) / 2
    # aim at the point of the face at 1/4 along axis (k+1)%3 and 3/4 along (k+2)%3
    target = np.where(normal > 0, hi, lo)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    target[i] = lo[i] + 0.25 * (hi[i] - lo[i])
    target[j] = lo[j] + 0.75 * (hi[j] - lo[j])
    for origin, direction in ((target + 3 * normal, -normal), (center, target - center)):
        hits = intersect(origin, direction, dtype, lo=lo, hi=hi, normal=True, uv=True)
        assert hits.hit[0]
        np.testing.assert_allclose(origin + hits.t[0] * direction, target, atol=1e-6)
        np.testing.assert_array_equal(hits.normal[0], normal)
        np.testing.assert_allclose(hits.uv[0], (0.25, 0.75), atol=1e-6)
        assert part_of(origin, direction, dtype, lo, hi)[1] == face


def test_bounds_and_pack():
    params = box.pack(LO, HI)
    assert params.shape == (analytic.PARAM_WIDTH,) and np.all(params[6:] == 0)
    lo, hi = analytic.analytic_bounds(analytic.BOX, params)
    np.testing.assert_array_equal(lo, LO)
    np.testing.assert_array_equal(hi, HI)


@pytest.mark.parametrize(
    ("lo", "hi", "name"),
    [((0, 0), (1, 1, 1), "lo"), ((0, 0, np.nan), (1, 1, 1), "lo"), ((0, 0, 0), (1, 1), "hi"),
     ((0, 0, 0), (1, -1, 1), "hi"), ((0, 0, 0), (1, 0, 1), "hi"), ((0, 0, 0), "abc", "hi")],
)
def test_bad_shape_raises_naming_the_argument(lo, hi, name):
    with pytest.raises(ValueError, match=name):
        intersect((0, 0, 5), (0, 0, -1), lo=lo, hi=hi)


# ---------------------------------------------------------------------------- properties


@settings(max_examples=80, derandomize=True, deadline=None)
@given(origin=sampling.points, direction=sampling.directions)
def test_matches_fractions(origin, direction):
    hits = intersect(origin, direction, lo=LO, hi=HI, normal=True, uv=True)
    t = hits.t[0]
    expected = reference.box_fraction(origin, direction, LO, HI)
    assert math.isinf(t) == math.isinf(expected)
    if not math.isinf(t):
        assert t == pytest.approx(expected, rel=1e-12, abs=1e-15)
        assert sorted(np.abs(hits.normal[0])) == [0, 0, 1]
        assert np.all((0 <= hits.uv[0]) & (hits.uv[0] <= 1))


# ---------------------------------------------------------------------------- the bar


def _on_faces(rng, count, lo, hi):
    """Uniform points on random faces of [lo, hi], and the axis across each one's face."""
    points = lo + rng.random((count, 3)) * (hi - lo)
    axis = rng.integers(0, 3, count)
    rows = np.arange(count)
    points[rows, axis] = np.where(rng.random(count) < 0.5, lo[axis], hi[axis])
    return points, axis


def _on_edges(rng, count, lo, hi):
    """Uniform points on random edges of [lo, hi], and the axis along each one's edge."""
    points = lo + rng.random((count, 3)) * (hi - lo)
    free = rng.integers(0, 3, count)
    for axis in range(3):
        fixed = free != axis
        points[fixed, axis] = np.where(rng.random(fixed.sum()) < 0.5, lo[axis], hi[axis])
    return points, free


class Shape:
    """The box as seen by :func:`sampling.mixed_rays`."""

    center = (LO + HI) / 2
    size = float(np.max(HI - LO) / 2)

    def surface(self, rng, count):
        return _on_faces(rng, count, LO, HI)[0]

    def grazing(self, rng, count):
        """A third each: through edges from any direction, along edges, within face planes
        (exact zero components, so that these rays lie exactly on the boundary)."""
        third = count // 3
        through, _ = _on_edges(rng, third, LO, HI)
        along, free = _on_edges(rng, third, LO, HI)
        within, across = _on_faces(rng, count - 2 * third, LO, HI)
        directions = sampling.random_directions(rng, count)
        along_directions = directions[third:2 * third]
        along_directions[np.arange(3) != free[:, None]] = 0.0
        directions[2 * third + np.arange(len(within)), across] = 0.0
        points = np.concatenate([through, along, within])
        return points - 4 * directions, directions

    def inside(self, rng, count):
        return LO + (0.0005 + 0.999 * rng.random((count, 3))) * (HI - LO)


@pytest.fixture(scope="module")
def bar_case():
    rays = sampling.mixed_rays(np.random.default_rng(59), sampling.BAR_RAYS, Shape())
    expected = reference.box(rays.origins, rays.directions, LO, HI, rays.tmin, rays.tmax)
    return rays, expected


def test_bar_data_covers_the_interesting_cases(bar_case):
    rays, expected = bar_case
    hit = np.isfinite(expected)
    assert 0.3 < hit.mean() < 0.8
    assert hit[rays.category == "inside"].all()
    # grazing rays touch the boundary; rounding their origins to float32 moves some of those
    # through edges off it, on either side
    assert 0.9 < hit[rays.category == "grazing"].mean() < 1
    assert 0.1 < hit[rays.category == "clipped"].mean() < 0.9
    # rays lying exactly in face planes (a zero component, the origin on the plane) are there
    on_plane = (rays.directions == 0) & ((rays.origins == LO) | (rays.origins == HI))
    assert on_plane.any(axis=1).sum() > 1000


def test_fast_reference_matches_fractions(bar_case):
    rays, expected = bar_case
    sample, slow = sampling.scalar_reference(reference.box_fraction, rays, LO, HI)
    np.testing.assert_array_equal(slow, expected[sample])


def test_bar(bar_case, dtype):
    rays, expected = bar_case
    hits = analytic.intersect_box(rays.origins, rays.directions, LO, HI, tmin=rays.tmin,
                                  tmax=rays.tmax, dtype=dtype)
    sampling.check_bar("box", dtype, hits.t, expected, rays.category)


def test_rays_in_face_planes_agree_exactly(bar_case, dtype):
    """The NaN-safe slab test: origin on a face plane, zero component across it -> inclusive."""
    rays, expected = bar_case
    on_plane = ((rays.directions == 0) & ((rays.origins == LO) | (rays.origins == HI))).any(1)
    hits = analytic.intersect_box(rays.origins[on_plane], rays.directions[on_plane], LO, HI,
                                  tmin=rays.tmin[on_plane], tmax=rays.tmax[on_plane],
                                  dtype=dtype)
    np.testing.assert_array_equal(np.isfinite(hits.t), np.isfinite(expected[on_plane]))
