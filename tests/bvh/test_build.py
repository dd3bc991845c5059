"""The binned SAH build: structure, containment, parameters, reported quality, threads and
degenerate input."""

import functools
from dataclasses import replace

import numba
import numpy as np
import pytest

from raycore import Scene
from raycore.bvh.build import CHUNK, MAX_DEPTH, MIN_TASK, BuildParams, build_binary_bvh
from raycore.bvh.layout import COUNTS, REFS, WIDTH, build_bvh
from raycore.bvh.leaves import FACE_COLUMN, face_ints
from raycore.bvh.records import (
    BINARY_COUNT,
    BINARY_REF,
    MAX_PRIMITIVES,
    PARALLEL_FROM,
    PRIM_INDEX,
    check_primitive_count,
    records_from_bounds,
)
from raycore.bvh.simd import BLOCK_PLANES, lanes_for
from raycore.mesh import FACE_CHUNK, Mesh, referenced_bounds, triangle_records


def random_boxes(count, seed=0):
    rng = np.random.default_rng(seed)
    centers = rng.normal(size=(count, 3)) * 10
    half = rng.random((count, 3)) * 0.5
    return centers - half, centers + half


def half_area(lo, hi):
    """Half the surface area of boxes ``lo``, ``hi`` (shape (..., 3)), in float64."""
    extent = (np.asarray(hi, np.float64) - np.asarray(lo, np.float64)).T
    return extent[0] * extent[1] + extent[1] * extent[2] + extent[2] * extent[0]


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


def slot_faces(mesh):
    """(L * B,) face index of each slot of a built mesh's blocks, -1 for padding (the blocks'
    face plane: raycore.bvh.leaves)."""
    lanes = lanes_for(mesh.leaf_blocks.dtype)
    return face_ints(mesh.leaf_blocks)[:, FACE_COLUMN:FACE_COLUMN + lanes].ravel()


def unpacked(mesh):
    """A built mesh's tree with its leaves pointing into a leaf order again, as the build made
    it: the blocks' face indices in slot order, padding left out (raycore.bvh.leaves)."""
    faces = slot_faces(mesh)
    real = faces >= 0
    position = np.cumsum(real) - 1  # of each slot, in the order without padding
    refs = mesh.bvh.refs.copy()
    firsts = refs[:, REFS:REFS + WIDTH]
    leaf = refs[:, COUNTS:COUNTS + WIDTH] > 0
    firsts[leaf] = position[lanes_for(mesh.leaf_blocks.dtype) * firsts[leaf]]
    return replace(mesh.bvh, nodes=refs.view(np.float32), refs=refs,
                   order=faces[real].astype(np.int64))


def check_leaves(bvh, lo, hi, max_leaf_size):
    """Every primitive lies in exactly one leaf, whose box contains its bounds ``lo``, ``hi``
    (float64, compared exactly with the float32 boxes); returns the leaf sizes."""
    count = len(lo)
    assert np.array_equal(np.sort(bvh.order), np.arange(count))
    leaves = list(walk(bvh))
    box_lo = np.array([leaf[0] for leaf in leaves])
    box_hi = np.array([leaf[1] for leaf in leaves])
    first = np.array([leaf[2] for leaf in leaves])
    sizes = np.array([leaf[3] for leaf in leaves])
    assert sizes.max() <= max_leaf_size
    # leaf of each position in leaf order, and the primitive at that position
    leaf_of = np.repeat(np.arange(len(leaves)), sizes)
    position = np.repeat(first, sizes) + np.arange(sizes.sum()) - np.repeat(
        np.cumsum(sizes) - sizes, sizes)
    prims = bvh.order[position]
    assert np.array_equal(np.sort(prims), np.arange(count)), "a primitive in no or two leaves"
    assert np.all(box_lo[leaf_of] <= lo[prims]) and np.all(box_hi[leaf_of] >= hi[prims])
    assert 0 <= bvh.depth <= MAX_DEPTH
    return sizes.tolist()


def binary_nodes(nodes):
    """Rows of the binary tree reachable from its root (records no node reaches are skipped),
    with the depth of each: (rows, depths)."""
    refs = nodes.view(np.int32)
    rows, depths = [], []
    stack = [(0, 0)]
    while stack:
        row, depth = stack.pop()
        rows.append(row)
        depths.append(depth)
        if refs[row, BINARY_COUNT] == 0:
            child = refs[row, BINARY_REF]
            stack += [(child, depth + 1), (child + 1, depth + 1)]
    return np.array(rows), np.array(depths)


@pytest.mark.parametrize("count", [1, 2, 7, 1000, 3 * MIN_TASK, 3 * CHUNK])
def test_every_primitive_lands_in_exactly_one_leaf_that_contains_it(count):
    # float64 bounds rounded outwards to float32 boxes must still contain them exactly; the
    # two largest counts go through the top phase and the subtrees built in parallel, the
    # largest also through binning and partitioning on all cores
    lo, hi = random_boxes(count)
    bvh = build_bvh(lo, hi)
    check_leaves(bvh, lo, hi, BuildParams().max_leaf_size)
    assert np.array_equal(bvh.lo, lo.min(axis=0)) and np.array_equal(bvh.hi, hi.max(axis=0))


def test_identical_primitives_still_respect_the_leaf_size():
    lo = np.zeros((50, 3))
    hi = np.ones((50, 3))
    bvh = build_bvh(lo, hi, BuildParams(max_leaf_size=3))
    sizes = [size for *_, size in walk(bvh)]
    assert sum(sizes) == 50 and max(sizes) <= 3


def test_many_identical_primitives_split_by_count_in_a_shallow_tree():
    # every centroid coincides, so no bucket separates anything: halving by count keeps the
    # depth at log2 of the leaf count, and the top phase must do the same
    count = 5 * MIN_TASK
    lo = np.full((count, 3), -1.0)
    hi = np.full((count, 3), 2.0)
    bvh = build_bvh(lo, hi)
    sizes = check_leaves(bvh, lo, hi, BuildParams().max_leaf_size)
    assert sum(sizes) == count
    assert bvh.depth <= np.ceil(np.log2(count))


def test_boxes_beyond_float32_are_bounded_by_infinity():
    # float64 objects past float32's range: the float32 boxes must still contain them
    lo, hi = random_boxes(20, seed=7)
    lo[3], hi[3] = [1e39, 0, 0], [2e39, 1, 1]
    lo[4], hi[4] = [-3e300, -1, -1], [-1e300, 1, 1]
    bvh = build_bvh(lo, hi)
    check_leaves(bvh, lo, hi, BuildParams().max_leaf_size)
    leaf_of = {int(p): (box_lo, box_hi) for box_lo, box_hi, first, size in walk(bvh)
               for p in bvh.order[first:first + size]}
    assert leaf_of[3][1][0] == np.inf and leaf_of[4][0][0] == -np.inf


@pytest.mark.parametrize("count", [3000, 3 * MIN_TASK])
def test_reported_quality_matches_the_tree(count):
    lo, hi = random_boxes(count, seed=3)
    params = BuildParams(traversal_cost=1.5, intersection_cost=1.0)
    bvh = build_bvh(lo, hi, params)
    leaves = list(walk(bvh))
    assert bvh.leaf_count == len(leaves)
    assert 0 < bvh.depth <= MAX_DEPTH

    # MacDonald–Booth cost of the binary tree the wide one was collapsed from, recomputed
    prims = records_from_bounds(lo, hi)
    binary = build_binary_bvh(prims, params)
    assert np.array_equal(prims.view(np.int32)[:, PRIM_INDEX], bvh.order)
    nodes, depth = binary.nodes, binary.depth
    rows, depths = binary_nodes(nodes)
    area = half_area(nodes[rows, 0:3], nodes[rows, 3:6])
    count = nodes.view(np.int32)[rows, BINARY_COUNT]
    leaf = count > 0
    expected = (params.traversal_cost * area[~leaf].sum()
                + params.intersection_cost * (area[leaf] * count[leaf]).sum()) / area[0]
    assert bvh.sah_cost == pytest.approx(expected, rel=1e-12)
    assert bvh.node_count == len(rows) == 2 * bvh.leaf_count - 1
    assert bvh.depth == depth == depths.max()
    # collapsing keeps the binary tree's leaves (the larger tree is collapsed in parts, its top,
    # then the rest in parallel), and a wide node has at least two children
    first = nodes.view(np.int32)[rows, BINARY_REF]
    assert sorted((int(f), int(c)) for *_, f, c in leaves) == sorted(
        zip(first[leaf].tolist(), count[leaf].tolist(), strict=True))
    assert np.isfinite(bvh.nodes[:, 0:WIDTH]).sum(axis=1).min() >= 2




def cheapest_collapse(nodes, params):
    """The least SAH cost of any wide tree over the binary tree ``nodes`` (a row costs its box's
    half-area times the traversal cost, a leaf its half-area times its blocks times the
    intersection cost), by enumerating every choice of each row's children: the row of an
    internal node may hold any cut of its subtree of at most WIDTH nodes (sets of descendants
    covering each leaf below once), and a cut's internal nodes are rows of their own."""
    refs = nodes.view(np.int32)

    def box_area(node):
        return half_area(nodes[node, 0:3], nodes[node, 3:6])

    def children(node):
        first = int(refs[node, BINARY_REF])
        return first, first + 1

    @functools.cache
    def cuts(node):
        # every cut of node's subtree (node alone included) of at most WIDTH nodes
        found = {frozenset([node])}
        if refs[node, BINARY_COUNT] == 0:
            left, right = children(node)
            found |= {a | b for a in cuts(left) for b in cuts(right) if len(a) + len(b) <= WIDTH}
        return found

    @functools.cache
    def subtree_cost(node):
        count = int(refs[node, BINARY_COUNT])
        if count > 0:
            return (box_area(node) * params.intersection_cost
                    * -(-count // params.block_size))
        left, right = children(node)
        return box_area(node) * params.traversal_cost + min(
            sum(subtree_cost(child) for child in a | b)
            for a in cuts(left) for b in cuts(right) if len(a) + len(b) <= WIDTH)

    return subtree_cost(0)


def wide_cost(bvh, root_area, params):
    """The same SAH cost of a built wide tree: its root, each row below it (the box of its slot)
    and each leaf."""
    internal = []
    leaves = list(walk(bvh, internal))
    return (params.traversal_cost * (root_area + sum(half_area(lo, hi) for lo, hi in internal))
            + params.intersection_cost * sum(half_area(lo, hi) * -(-count // params.block_size)
                                             for lo, hi, _, count in leaves))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("params", [BuildParams(), BuildParams(max_leaf_size=8, block_size=4),
                                    BuildParams(traversal_cost=3.0, intersection_cost=0.5)])
def test_wide_nodes_are_the_cheapest_choice_of_children(seed, params):
    # the greedy choice (open the child of largest area until a row is full) leaves small
    # subtrees below full rows as rows of two: ten of these trees cost more that way
    lo, hi = random_boxes(60, seed=seed)
    binary = build_binary_bvh(records_from_bounds(lo, hi), params)
    bvh = build_bvh(lo, hi, params)
    root_area = half_area(binary.nodes[0, 0:3], binary.nodes[0, 3:6])
    assert wide_cost(bvh, root_area, params) == pytest.approx(
        cheapest_collapse(binary.nodes, params), rel=1e-6)


def test_sah_prefers_fewer_tests_when_intersections_are_expensive():
    lo, hi = random_boxes(3000, seed=5)
    cheap = build_bvh(lo, hi, BuildParams(max_leaf_size=16, intersection_cost=0.1))
    dear = build_bvh(lo, hi, BuildParams(max_leaf_size=16, intersection_cost=10.0))
    assert cheap.leaf_count < dear.leaf_count


def test_the_tree_does_not_depend_on_the_number_of_threads():
    # enough primitives for the top phase to bin on all cores and leave many subtrees
    lo, hi = random_boxes(3 * CHUNK, seed=11)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = build_bvh(lo, hi)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        every = build_bvh(lo, hi)
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(one.nodes.view(np.int32), every.nodes.view(np.int32))
    assert np.array_equal(one.order, every.order)
    assert (one.sah_cost, one.depth, one.node_count) == (every.sah_cost, every.depth,
                                                         every.node_count)


def grid_mesh(cells):
    """A flat square of 2 * cells**2 triangles in the plane z = 0."""
    u = np.linspace(0.0, 1.0, cells + 1)
    x, y = np.meshgrid(u, u, indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    corner = (np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)[None, :]).ravel()
    faces = np.concatenate([
        np.stack([corner, corner + cells + 1, corner + 1], axis=1),
        np.stack([corner + 1, corner + cells + 1, corner + cells + 2], axis=1)])
    return vertices, faces


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_mesh_leaves_hold_each_triangle_as_the_scene_stores_it(dtype):
    vertices, faces = grid_mesh(60)
    vertices = vertices * 3.1 + 0.1  # coordinates that float32 cannot hold exactly
    mesh = Mesh(vertices, faces)
    params = BuildParams()
    mesh.build(np.dtype(dtype), params)
    stored = vertices.astype(dtype)
    corners = stored[faces]  # (F, 3, 3), a reference built without the compiled passes
    check_leaves(unpacked(mesh), corners.min(axis=1), corners.max(axis=1), params.max_leaf_size)
    assert mesh.leaf_blocks.dtype == np.dtype(dtype)
    faces_of_slots = slot_faces(mesh)
    slots = np.flatnonzero(faces_of_slots >= 0)
    # block b holds value j (a.x, a.y, ..., c.z) of lane l at [b, j * lanes + l], then the
    # face indices
    lanes = lanes_for(dtype)
    stored_corners = mesh.leaf_blocks.reshape(-1, BLOCK_PLANES, lanes)[slots // lanes, :9,
                                                                       slots % lanes]
    assert np.array_equal(stored_corners, corners[faces_of_slots[slots]].reshape(-1, 9))
    # every face once, padding lanes NaN
    assert np.array_equal(np.sort(faces_of_slots[slots]), np.arange(len(faces)))
    padding = np.flatnonzero(faces_of_slots < 0)
    assert np.all(np.isnan(mesh.leaf_blocks.reshape(-1, BLOCK_PLANES, lanes)[
        padding // lanes, :9, padding % lanes]))
    assert np.array_equal(mesh.bvh.lo, stored.min(axis=0))
    lo, hi = mesh.bounds
    assert np.array_equal(lo, vertices.min(axis=0)) and np.array_equal(hi, vertices.max(axis=0))


def test_mesh_bounds_ignore_vertices_no_face_uses():
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [50, 50, 50], [-9, -9, -9]])
    lo, hi = Mesh(vertices, [[0, 1, 2]]).bounds
    assert lo.tolist() == [0, 0, 0] and hi.tolist() == [1, 1, 0]


@pytest.mark.parametrize("count", [PARALLEL_FROM - 1, PARALLEL_FROM, 2 * FACE_CHUNK + 1])
def test_records_and_bounds_are_the_corners_on_one_thread_and_on_all_cores(count):
    # records are made on the calling thread below PARALLEL_FROM, bounds within one chunk of
    # FACE_CHUNK faces, and on all cores above: both must give the bounds of the triangles'
    # corners, and boxes rounded outwards to float32
    rng = np.random.default_rng(count)
    vertices = rng.normal(size=(count, 3)) * 1e3
    faces = rng.integers(0, count - 100, (count, 3))  # the last vertices unused
    corners = vertices[faces]
    lo, hi = referenced_bounds(vertices, faces)
    assert np.array_equal(lo, corners.min(axis=(0, 1)))
    assert np.array_equal(hi, corners.max(axis=(0, 1)))
    stored = vertices.astype(np.float32)
    records = triangle_records(stored, faces)
    assert np.array_equal(records[:, :3], stored[faces].min(axis=1))
    assert np.array_equal(records[:, 3:6], stored[faces].max(axis=1))
    assert np.array_equal(records.view(np.int32)[:, PRIM_INDEX], np.arange(count))
    box_lo, box_hi = corners.min(axis=1), corners.max(axis=1)
    boxes = records_from_bounds(box_lo, box_hi)
    down, up = box_lo.astype(np.float32), box_hi.astype(np.float32)
    down = np.where(down > box_lo, np.nextafter(down, np.float32(-np.inf)), down)
    up = np.where(up < box_hi, np.nextafter(up, np.float32(np.inf)), up)
    assert np.array_equal(boxes[:, :3], down) and np.array_equal(boxes[:, 3:6], up)
    assert np.array_equal(boxes.view(np.int32)[:, PRIM_INDEX], np.arange(count))


def test_one_triangle_makes_a_tree_of_one_leaf():
    scene = Scene()
    scene.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    hits = scene.intersect([[0.25, 0.25, 1.0]], [[0, 0, -1.0]])
    assert hits.prim_id.tolist() == [0] and hits.t.tolist() == [1.0]
    stats = scene.stats()["meshes"][0]
    assert (stats["nodes"], stats["leaves"], stats["depth"]) == (1, 1, 0)


def test_a_mesh_of_identical_triangles_builds_and_answers():
    # 4 * MIN_TASK copies of one triangle: every centroid coincides, through both phases
    count = 4 * MIN_TASK
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    faces = np.tile([0, 1, 2], (count, 1))
    mesh = Mesh(vertices, faces)
    params = BuildParams()
    mesh.build(np.dtype("float32"), params)
    lo = np.zeros((count, 3))
    hi = np.tile([1.0, 1, 0], (count, 1))
    check_leaves(unpacked(mesh), lo, hi, params.max_leaf_size)
    assert mesh.bvh.depth <= np.ceil(np.log2(count))
    scene = Scene()
    scene.add_mesh(vertices, faces)
    hits = scene.intersect([[0.25, 0.25, 1.0]], [[0, 0, -1.0]])
    assert hits.t.tolist() == [1.0] and 0 <= hits.prim_id[0] < count


def test_primitive_counts_the_tree_cannot_hold_raise():
    with pytest.raises(ValueError, match="zero primitives"):
        build_bvh(np.zeros((0, 3)), np.zeros((0, 3)))
    # int32 indices and node references: a count past MAX_PRIMITIVES is refused up front
    check_primitive_count(MAX_PRIMITIVES)
    with pytest.raises(ValueError, match="at most"):
        check_primitive_count(MAX_PRIMITIVES + 1)


@pytest.mark.parametrize("field, value", [("bins", 1), ("max_leaf_size", 0),
                                          ("traversal_cost", 0.0),
                                          ("intersection_cost", float("nan"))])
def test_bad_parameters_raise_naming_them(field, value):
    with pytest.raises(ValueError, match=field):
        BuildParams(**{field: value})
