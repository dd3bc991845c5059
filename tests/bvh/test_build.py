"""The binned SAH build: structure, containment, parameters and reported quality."""

import numpy as np
import pytest

from raycore.bvh.build import MAX_DEPTH, BuildParams
from raycore.bvh.layout import LEFT_COUNT, LEFT_REF, build_bvh


def random_boxes(count, seed=0):
    rng = np.random.default_rng(seed)
    centers = rng.normal(size=(count, 3)) * 10
    half = rng.random((count, 3)) * 0.5
    return centers - half, centers + half


def walk(bvh, internal=None):
    """Yield (box_lo, box_hi, first, count) for every leaf, checking node containment.

    Boxes of internal nodes below the root are appended to ``internal`` when given.
    """
    stack = [(0, np.full(3, -np.inf), np.full(3, np.inf))]
    while stack:
        row, outer_lo, outer_hi = stack.pop()
        for side in range(2):
            lo = bvh.nodes[row, 6 * side:6 * side + 3]
            hi = bvh.nodes[row, 6 * side + 3:6 * side + 6]
            if np.any(lo > hi):
                continue  # the empty partner of a root leaf
            assert np.all(lo >= outer_lo) and np.all(hi <= outer_hi), "child box leaks out"
            ref = bvh.refs[row, LEFT_REF + side]
            count = bvh.refs[row, LEFT_COUNT + side]
            if count:
                yield lo, hi, ref, count
            else:
                if internal is not None:
                    internal.append((lo, hi))
                stack.append((ref, lo, hi))


@pytest.mark.parametrize("count", [1, 2, 7, 1000])
def test_every_primitive_lands_in_exactly_one_leaf_that_contains_it(count):
    lo, hi = random_boxes(count)
    bvh = build_bvh(lo, hi)
    assert np.array_equal(np.sort(bvh.order), np.arange(count))
    seen = np.zeros(count, int)
    for box_lo, box_hi, first, size in walk(bvh):
        prims = bvh.order[first:first + size]
        seen[prims] += 1
        assert size <= BuildParams().max_leaf_size
        # float32 boxes are rounded outwards, so they contain the float64 bounds exactly
        assert np.all(box_lo <= lo[prims]) and np.all(box_hi >= hi[prims])
    assert np.all(seen == 1)


def test_identical_primitives_still_respect_the_leaf_size():
    lo = np.zeros((50, 3))
    hi = np.ones((50, 3))
    bvh = build_bvh(lo, hi, BuildParams(max_leaf_size=3))
    sizes = [size for *_, size in walk(bvh)]
    assert sum(sizes) == 50 and max(sizes) <= 3


def test_reported_quality_matches_the_tree():
    lo, hi = random_boxes(5000, seed=3)
    params = BuildParams(traversal_cost=1.5, intersection_cost=1.0)
    bvh = build_bvh(lo, hi, params)
    internal = []
    leaves = list(walk(bvh, internal))
    assert bvh.leaf_count == len(leaves)
    assert bvh.node_count == 2 * bvh.leaf_count - 1 == 2 * len(internal) + 3
    assert 0 < bvh.depth <= MAX_DEPTH

    def half_area(lo, hi):
        e = hi.astype(np.float64) - lo
        return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]

    # MacDonald–Booth cost from the stored (float32) boxes: the root plus the internal children
    root = half_area(bvh.lo, bvh.hi)
    traversal = root + sum(half_area(a, b) for a, b in internal)
    intersection = sum(half_area(a, b) * size for a, b, _, size in leaves)
    expected = (params.traversal_cost * traversal + params.intersection_cost * intersection) / root
    assert bvh.sah_cost == pytest.approx(expected, rel=1e-5)


def test_sah_prefers_fewer_tests_when_intersections_are_expensive():
    lo, hi = random_boxes(3000, seed=5)
    cheap = build_bvh(lo, hi, BuildParams(max_leaf_size=16, intersection_cost=0.1))
    dear = build_bvh(lo, hi, BuildParams(max_leaf_size=16, intersection_cost=10.0))
    assert cheap.leaf_count < dear.leaf_count


@pytest.mark.parametrize("field, value", [("bins", 1), ("max_leaf_size", 0),
                                          ("traversal_cost", 0.0),
                                          ("intersection_cost", float("nan"))])
def test_bad_parameters_raise_naming_them(field, value):
    with pytest.raises(ValueError, match=field):
        BuildParams(**{field: value})
