"""The binned SAH build: structure, containment, parameters and reported quality."""

import numpy as np
import pytest

from raycore.bvh.build import MAX_DEPTH, BuildParams, build_binary_bvh
from raycore.bvh.layout import COUNTS, REFS, WIDTH, build_bvh


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
        for slot in range(WIDTH):
            lo = bvh.nodes[row, slot:3 * WIDTH:WIDTH]
            hi = bvh.nodes[row, 3 * WIDTH + slot:6 * WIDTH:WIDTH]
            if np.any(lo > hi):
                continue  # an unused slot
            assert np.all(lo >= outer_lo) and np.all(hi <= outer_hi), "child box leaks out"
            ref = bvh.refs[row, REFS + slot]
            count = bvh.refs[row, COUNTS + slot]
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
    leaves = list(walk(bvh))
    assert bvh.leaf_count == len(leaves)
    assert 0 < bvh.depth <= MAX_DEPTH

    # MacDonald–Booth cost of the binary tree the wide one was collapsed from, recomputed
    order, node_lo, node_hi, left, _, first, count, depth = build_binary_bvh(
        lo, hi, params.bins, params.max_leaf_size, params.traversal_cost,
        params.intersection_cost)
    extent = node_hi - node_lo
    area = extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 2] * extent[:, 0]
    leaf = count > 0
    expected = (params.traversal_cost * area[~leaf].sum()
                + params.intersection_cost * (area[leaf] * count[leaf]).sum()) / area[0]
    assert bvh.sah_cost == pytest.approx(expected, rel=1e-12)
    assert bvh.node_count == len(node_lo) == 2 * bvh.leaf_count - 1 and bvh.depth == depth
    # collapsing keeps the binary tree's leaves, and fills a wide node unless only leaves are
    # left to open
    assert sorted((int(f), int(c)) for *_, f, c in leaves) == sorted(
        zip(first[leaf].tolist(), count[leaf].tolist(), strict=True))
    used = np.isfinite(bvh.nodes[:, 0:WIDTH])
    assert used.sum(axis=1).min() >= 2
    partial = used.sum(axis=1) < WIDTH
    assert np.all(bvh.refs[partial, COUNTS:COUNTS + WIDTH][used[partial]] > 0)


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
