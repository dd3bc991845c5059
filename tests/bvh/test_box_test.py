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
from raycore.bvh.traverse import _bounds32, _box_ray


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
