"""The wide node's box test (raycore.bvh.simd.enter8, set up by traverse._box_ray) never misses
a box that the ray enters, for rays of either precision: checked against an exact slab test in
rational arithmetic.

The test runs in float32 for float64 rays too, so the cases aim at what that rounding could
break: origins within a few float64 ulps of a face (not representable in float32), rays lying in
a face's plane, axis-parallel and nearly parallel directions, bounds that end at a face.  Nor
does the traversal drop a pending box that the ray enters before its closest hit so far.
"""

from fractions import Fraction

import numpy as np
import pytest
from numba import njit

import raycore
from raycore.bvh.layout import NODE_WIDTH, WIDTH
from raycore.bvh.simd import enter8
from raycore.bvh.traverse import _bounds32, _box_ray, _float32_step, _rounded32


@njit
def _entered(nodes, o, d, tmin, tmax, entry):
    box = _box_ray(o[0], o[1], o[2], d[0], d[1], d[2])
    lo, hi = _bounds32(tmin, tmax)
    return enter8(nodes, 0, box, lo, hi, entry)


def _exact_enters(lo, hi, o, d, tmin, tmax):
    """Whether the ray o + t d, t in [tmin, tmax], meets the closed box [lo, hi], exactly."""
    near, far = Fraction(tmin), Fraction(tmax) if np.isfinite(tmax) else None
    for a in range(3):
        oa, da = Fraction(float(o[a])), Fraction(float(d[a]))
        la, ha = Fraction(float(lo[a])), Fraction(float(hi[a]))
        if da == 0:
            if not la <= oa <= ha:
                return False
            continue
        t0, t1 = (la - oa) / da, (ha - oa) / da
        t0, t1 = min(t0, t1), max(t0, t1)
        near = max(near, t0)
        far = t1 if far is None else min(far, t1)
    return far is None or near <= far


def _cases(dtype, rng, count):
    """(boxes (8, 2, 3) float32, origins (count, 3), directions (count, 3), tmax (count,))."""
    centers = rng.uniform(-100, 100, (WIDTH, 3))
    sizes = rng.uniform(1e-3, 10, (WIDTH, 3))
    boxes = np.stack([centers - sizes, centers + sizes], 1).astype(np.float32)
    box = rng.integers(0, WIDTH, count)
    lo, hi = boxes[box, 0].astype(np.float64), boxes[box, 1].astype(np.float64)
    # a point on the box's surface: one axis pinned to a face, the others anywhere on it
    point = rng.uniform(lo, hi)
    axis = rng.integers(0, 3, count)
    face = np.where(rng.random((count, 1)) < 0.5, lo, hi)[np.arange(count), axis]
    point[np.arange(count), axis] = face
    # then moved off it by a few float64 ulps, inwards or outwards, or left on it
    ulps = rng.integers(-4, 5, count).astype(np.float64)
    point[np.arange(count), axis] += ulps * np.spacing(np.abs(face))
    directions = rng.normal(size=(count, 3))
    # aim some rays from afar at the point, and let others start there
    start = rng.random(count) < 0.5
    reach = rng.uniform(1, 1000, count)
    origins = np.where(start[:, None], point, point - reach[:, None] * directions)
    # axis-parallel and nearly parallel directions, some lying in the face's plane
    flat = rng.random(count) < 0.3
    directions[flat, axis[flat]] = rng.choice([0.0, 1e-30, -1e-30], flat.sum())
    # bounds that end exactly at the point, or run on
    tmax = np.where(rng.random(count) < 0.3, np.where(start, 0.0, reach), np.inf)
    return boxes, origins.astype(dtype), directions.astype(dtype), tmax


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_box_test_never_misses_an_entered_box(dtype):
    rng = np.random.default_rng(20261124)
    boxes, origins, directions, tmax = _cases(dtype, rng, 4000)
    nodes = np.zeros((1, NODE_WIDTH), np.float32)
    for axis in range(3):
        nodes[0, axis * WIDTH:(axis + 1) * WIDTH] = boxes[:, 0, axis]
        nodes[0, (axis + 3) * WIDTH:(axis + 4) * WIDTH] = boxes[:, 1, axis]
    entry = np.empty(WIDTH, dtype)
    missed, entered = [], 0
    for o, d, t_max in zip(origins, directions, tmax.astype(dtype), strict=True):
        mask = _entered(nodes, o, d, dtype(0), t_max, entry)
        for j in range(WIDTH):
            if _exact_enters(boxes[j, 0], boxes[j, 1], o, d, 0.0, float(t_max)):
                entered += 1
                if not mask >> j & 1:
                    missed.append((o.tolist(), d.tolist(), float(t_max), j))
    assert not missed, missed[:5]
    # the cases reach the boxes (most rays are aimed at one)
    assert entered > 2000


@njit
def _roundings(values, below, above, lo, hi):
    for i in range(len(values)):
        step = _float32_step(values[i])
        below[i] = _rounded32(values[i], -step)
        above[i] = _rounded32(values[i], step)
        lo[i], hi[i] = _bounds32(values[i], values[i])


def _float32_ulps_apart(a, b):
    """How many float32 values lie in (a, b] (a <= b, both float32), by their ordered bits."""
    def order(x):
        bits = np.float32(x).view(np.int32).astype(np.int64)
        return np.where(bits < 0, -(bits & 0x7FFFFFFF), bits)
    return order(b) - order(a)


def _rounding_cases(rng):
    """float64 values near float32 ones, ties between two, subnormals and the ends of float32's
    range, and float32 values among them."""
    near32 = rng.uniform(-1e4, 1e4, 3000).astype(np.float32).astype(np.float64)
    ties = near32 + np.spacing(near32.astype(np.float32)).astype(np.float64) / 2
    return near32, np.concatenate([
        near32, ties, np.nextafter(near32, np.inf), np.nextafter(near32, -np.inf),
        rng.normal(size=3000) * 10.0 ** rng.integers(-40, 38, 3000),
        np.array([0.0, -0.0, 2.0**-149, -(2.0**-149), 2.0**-150, 3 * 2.0**-151, 1e-300,
                  -1e-300, 2.0**-126, float(np.finfo(np.float32).max), np.inf, -np.inf])])


def test_float64_values_are_rounded_outwards_to_float32():
    # The box test takes a float64 ray's origin rounded outwards to float32 and its bounds
    # widened by more than γ(6), without a branch (the origin moved by more than an ulp, then
    # rounded to nearest; the bounds rounded to nearest, then widened): checked against exact
    # comparisons.
    float32_values, values = _rounding_cases(np.random.default_rng(7))
    outputs = [np.empty(len(values), np.float32) for _ in range(4)]
    _roundings(values, *outputs)
    below, above, lo, hi = (out.astype(np.float64) for out in outputs)
    # (comparisons of float32 and float64 values, and Fractions of finite ones, are exact)
    assert np.all(below <= values) and np.all(values <= above)
    finite = np.abs(values) <= np.finfo(np.float32).max
    # within three float32 ulps of the float32 nearest the value
    nearest = values[finite].astype(np.float32)
    assert np.all(_float32_ulps_apart(outputs[0][finite], nearest) <= 3)
    assert np.all(_float32_ulps_apart(nearest, outputs[1][finite]) <= 3)
    # the bounds: lo at most the value, hi at least (1 + γ(6)) times it (as far from zero
    # when negative), as the box test's near distances need
    gamma6 = Fraction(6 * 2**-24) / (1 - Fraction(6 * 2**-24))
    assert np.all(lo[finite] <= values[finite])
    assert all(h == np.inf or Fraction(h) >= Fraction(v) + abs(Fraction(v)) * gamma6
               for h, v in zip(hi[finite], values[finite], strict=True))
    assert np.all(hi[~finite & (values > 0)] == np.inf)
    # a float32 value (a float32 ray's) is kept as it is
    kept = [np.empty(len(float32_values), np.float32) for _ in range(4)]
    _roundings(float32_values.astype(np.float32), *kept)
    assert np.array_equal(kept[0], float32_values) and np.array_equal(kept[1], float32_values)


def _square(cells, height, shift):
    """A unit square at z = ``height``, moved by ``shift`` in x and y, cut into 2 * cells**2
    triangles: (V, 3) vertices and (F, 3) faces."""
    xs = np.linspace(0, 1, cells + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    vertices = np.stack([x.ravel() + shift, y.ravel() + shift, np.full(x.size, height)], 1)
    corner = (np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)).ravel()
    faces = np.concatenate([np.stack([corner, corner + cells + 1, corner + 1], 1),
                            np.stack([corner + 1, corner + cells + 1, corner + cells + 2], 1)])
    return vertices, faces


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_a_box_entered_before_the_closest_hit_is_visited(dtype):
    # Two squares a few float32 ulps apart, in subtrees of their own.  A ray that finds the
    # farther square first must still visit the nearer one's boxes: their computed entry
    # distance may exceed the exact one by a factor 1 + γ(6) (the box test is float32 for rays
    # of either precision), so a box entered before that hit can appear to start after it.
    # Pending boxes were once culled against the hit itself, not the bound the box test pads,
    # and a few rays in a hundred thousand came back with the farther square.
    rng = np.random.default_rng(1)
    for _ in range(40):
        height = rng.uniform(0.3, 3)
        gap = height * rng.uniform(1e-8, 6e-7)
        far_square = _square(16, height + gap, 0.0)
        near_square = _square(16, height, 0.013)
        both, near = raycore.Scene(dtype), raycore.Scene(dtype)
        both.add_mesh(np.concatenate([far_square[0], near_square[0]]),
                      np.concatenate([far_square[1], near_square[1] + len(far_square[0])]))
        near.add_mesh(*near_square)
        count = 20000
        origins = np.column_stack([rng.uniform(0.1, 0.9, (count, 2)), rng.uniform(-1, 0, count)])
        targets = np.column_stack([rng.uniform(0.1, 0.9, (count, 2)), np.full(count, height)])
        directions = targets - origins
        hits, nearer = both.intersect(origins, directions), near.intersect(origins, directions)
        assert np.all(hits.t <= nearer.t)
