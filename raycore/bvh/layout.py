"""Flat node layout for traversal, and tree-quality statistics.

The binary SAH tree is collapsed into a wide one (Wald et al. 2008, "Getting rid of packets"),
whose nodes' children are chosen for the least SAH cost (Ylitie et al. 2017, see
:func:`_ranked_costs`): each node holds up to eight children, whose boxes are stored plane by
plane so that one vector instruction tests all eight (:mod:`raycore.bvh.simd`).  A wide node
is one 256-byte row of float32 (four cache lines)::

    [0:8] lo x   [8:16] lo y   [16:24] lo z   [24:32] hi x   [32:40] hi y   [40:48] hi z
    [48:56] refs   [56:64] counts   (int32 bit patterns)

A child with count 0 is an internal node whose row is ``ref``; a child with count > 0 is a leaf
holding primitives ``ref .. ref + count - 1`` in leaf order; an unused slot has an empty box
(lo = +inf, hi = -inf) that no ray enters.  Boxes are rounded outwards to float32, so a float64
scene keeps conservative boxes at half the memory.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit, parallel_chunksize, prange

from raycore.bvh.build import BuildParams, build_binary_bvh
from raycore.bvh.records import (
    BINARY_COUNT,
    BINARY_REF,
    FLOAT32_MAX,
    PRIM_INDEX,
    check_primitive_count,
    records_from_bounds,
)
from raycore.bvh.split import blocks_of

WIDTH = 8
NODE_WIDTH = 8 * WIDTH
REFS, COUNTS = 6 * WIDTH, 7 * WIDTH


@dataclass(frozen=True)
class BVH:
    """A built BVH in flat form.

    Attributes
    ----------
    nodes : ndarray of float32, shape (K, 64)
        Wide rows (see the module docstring); row 0 holds the root's children.
    refs : ndarray of int32, shape (K, 64)
        The same memory viewed as int32, for the references and counts.
    order : ndarray of int64, shape (F,), or None
        Primitive indices in leaf order (None once a mesh's leaves are packed into blocks,
        which then hold the face indices: :mod:`raycore.bvh.leaves`).
    lo, hi : ndarray of float64, shape (3,)
        Bounds of everything.
    depth, node_count, leaf_count : int
        Of the binary tree the wide one was collapsed from.
    sah_cost : float
        Expected cost of a random ray hitting the root (MacDonald & Booth 1990), with the
        build's traversal and intersection costs.
    """

    nodes: np.ndarray
    refs: np.ndarray
    order: np.ndarray | None
    lo: np.ndarray
    hi: np.ndarray
    depth: int
    node_count: int
    leaf_count: int
    sah_cost: float

    @property
    def nbytes(self):
        return self.nodes.nbytes + (0 if self.order is None else self.order.nbytes)


@njit(cache=True, inline="always")
def _half_area(nodes, node):
    box = nodes[node]
    dx = np.float64(box[3]) - np.float64(box[0])
    dy = np.float64(box[4]) - np.float64(box[1])
    dz = np.float64(box[5]) - np.float64(box[2])
    return dx * dy + dy * dz + dz * dx


#: Fields of a collapse's tree statistics (float64): summed half-areas of internal nodes and of
#: leaves times their blocks, node count, leaf count.
INTERNAL_AREA, LEAF_AREA, NODE_COUNT, LEAF_COUNT = range(4)


@njit(cache=True, inline="always")
def _count_node(nodes, refs, node, stats, block):
    """Add binary ``node`` to the tree statistics ``stats`` (a leaf weighs its blocks of
    ``block`` primitives)."""
    count = refs[node, BINARY_COUNT]
    area = _half_area(nodes, node)
    stats[NODE_COUNT] += 1
    if count > 0:
        stats[LEAF_AREA] += area * blocks_of(count, block)
        stats[LEAF_COUNT] += 1
    else:
        stats[INTERNAL_AREA] += area


# ---------------------------------------------------------------------------- which nodes
# The greedy collapse (open the child of largest area until a row is full) left a third of the
# rows with two children: a small subtree below a full row became a row of its own.  Ylitie,
# Karras and Laine ("Efficient incoherent ray traversal on GPUs through compressed wide BVHs",
# HPG 2017, section 3.1) choose each row's children by dynamic programming over the binary
# tree instead, for the least SAH cost of the wide tree: a row costs its box's area times the
# traversal cost, a leaf its area times its blocks.
#
# The costs are kept for internal nodes only, in a table of their own numbered breadth first,
# subtree by subtree; an internal node's count field (0 in the binary tree) holds -(its
# number + 1) while the tree is collapsed.  Kept for every record instead, the table was
# resident far beyond the records in use (each subtree's records are reserved for its worst
# case, and the kernel backs memory in 2 MiB pages): the build's temporaries grew from 38 to 78
# bytes a triangle at 1.6M triangles.


@njit(cache=True)
def _breadth_first(refs, root, top_count, order, boundary):
    """List the binary nodes below ``root`` (itself included) breadth first in ``order``, a
    node before its children, without entering nodes ``>= top_count`` when ``top_count > 0``
    (the subtrees built in parallel), which are listed in ``boundary`` instead.

    Returns
    -------
    listed, bounded, internal : int
        Entries of ``order`` and of ``boundary`` written, and internal nodes listed.
    """
    order[0] = root
    listed, bounded, internal = 1, 0, 0
    k = 0
    while k < listed:
        node = order[k]
        k += 1
        if refs[node, BINARY_COUNT] > 0:
            continue
        internal += 1
        for side in range(2):
            child = refs[node, BINARY_REF] + side
            if top_count > 0 and child >= top_count:
                boundary[bounded] = child
                bounded += 1
            else:
                order[listed] = child
                listed += 1
    return listed, bounded, internal


@njit(cache=True, inline="always")
def _slot_cost(nodes, refs, costs, node, budget, prices, block):
    """The least cost of binary ``node``'s subtree in at most ``budget`` slots of a row: a leaf's
    area times its blocks times the intersection cost, however many slots; an internal node's
    from its row of ``costs`` (:func:`_ranked_costs`)."""
    count = refs[node, BINARY_COUNT]
    if count > 0:
        return _half_area(nodes, node) * prices[1] * blocks_of(count, block)
    return np.float64(costs[-1 - count, budget - 1])


@njit(cache=True, inline="always")
def _cheapest_split(nodes, refs, costs, node, budget, prices, block):
    """``(cost, left_budget)``: the least cost of internal binary ``node``'s two children in
    ``budget`` slots of a row between them."""
    left = refs[node, BINARY_REF]
    best, best_left = np.inf, 1
    for left_budget in range(1, budget):
        cost = (_slot_cost(nodes, refs, costs, left, left_budget, prices, block)
                + _slot_cost(nodes, refs, costs, left + 1, budget - left_budget, prices, block))
        if cost < best:
            best, best_left = cost, left_budget
    return best, best_left


@njit(cache=True)
def _ranked_costs(nodes, refs, order, listed, first, costs, prices, block):
    """Number the internal nodes of ``order[:listed]`` (a node before its children, as
    :func:`_breadth_first` lists them) from ``first`` on, in that order, and fill their rows of
    ``costs``, children first: ``costs[number, j - 1]`` is the least SAH cost (unnormalised)
    of the node's subtree given at most ``j`` slots of a row.

    An internal node in one slot is a row of its own: its area times the traversal cost, plus
    its children's cheapest split of a whole row; with more slots it may instead put its
    children in the row, splitting the slots between them.

    Parameters
    ----------
    costs : ndarray of float32, shape (I, WIDTH)
        One row per internal node of the tree.
    prices : ndarray of float64, shape (2,)
        Traversal cost of a row, intersection cost of a leaf block.
    """
    number = first
    for k in range(listed):
        if refs[order[k], BINARY_COUNT] <= 0:
            refs[order[k], BINARY_COUNT] = -1 - number
            number += 1
    for k in range(listed - 1, -1, -1):
        node = order[k]
        count = refs[node, BINARY_COUNT]
        if count > 0:
            continue
        row = -1 - count
        whole = _cheapest_split(nodes, refs, costs, node, WIDTH, prices, block)[0]
        alone = _half_area(nodes, node) * prices[0] + whole
        costs[row, 0] = alone
        for budget in range(2, WIDTH):
            split = _cheapest_split(nodes, refs, costs, node, budget, prices, block)[0]
            costs[row, budget - 1] = min(alone, split)
        costs[row, WIDTH - 1] = min(alone, whole)


@njit(cache=True, parallel=True)
def _internal_counts(refs, roots, size, counts):
    """``counts[t]``: internal nodes below each of ``roots`` (subtrees of at most ``size``
    nodes), on all cores."""
    none = np.empty(0, np.int64)
    for t in prange(len(roots)):
        order = np.empty(size, np.int64)
        counts[t] = _breadth_first(refs, roots[t], np.int64(0), order, none)[2]


@njit(cache=True, parallel=True)
def _subtree_costs(nodes, refs, roots, size, firsts, costs, prices, block):
    """:func:`_ranked_costs` below each of ``roots``, numbered from ``firsts``, on all
    cores."""
    none = np.empty(0, np.int64)
    for t in prange(len(roots)):
        order = np.empty(size, np.int64)
        listed = _breadth_first(refs, roots[t], np.int64(0), order, none)[0]
        _ranked_costs(nodes, refs, order, listed, firsts[t], costs, prices, block)


@njit(cache=True, inline="always")
def _fill_row(nodes, refs, node, costs, prices, slots, pending, budgets, stats, block):
    """Choose the children of the row of internal binary ``node`` by their slot costs: put them
    in ``slots`` and return how many; add every binary node met below ``node`` to ``stats``.
    ``pending``, ``budgets``: scratch of WIDTH entries."""
    left = refs[node, BINARY_REF]
    _, left_budget = _cheapest_split(nodes, refs, costs, node, WIDTH, prices, block)
    # depth first, the left child first, each with its share of the slots
    pending[0], budgets[0] = left + 1, WIDTH - left_budget
    pending[1], budgets[1] = left, left_budget
    waiting = 2
    size = 0
    while waiting:
        waiting -= 1
        child, budget = pending[waiting], budgets[waiting]
        _count_node(nodes, refs, child, stats, block)
        if refs[child, BINARY_COUNT] <= 0 and budget > 1:
            split, left_budget = _cheapest_split(nodes, refs, costs, child, budget, prices,
                                                 block)
            if split < _slot_cost(nodes, refs, costs, child, 1, prices, block):
                # its children take its slots
                first = refs[child, BINARY_REF]
                pending[waiting], budgets[waiting] = first + 1, budget - left_budget
                pending[waiting + 1], budgets[waiting + 1] = first, left_budget
                waiting += 2
                continue
        slots[size] = child
        size += 1
    return size


@njit(cache=True)
def _collapse(nodes, refs, root, first_row, top_count, deferred, deferred_rows, queue, wide,
              write, count_root, stats, costs, prices, block):
    """Group the binary nodes below ``root`` into wide nodes of up to WIDTH children, breadth
    first, as rows ``first_row, first_row + 1, ...`` of ``wide``.

    Each wide node's children are the cheapest choice by ``costs`` and ``prices``
    (:func:`_ranked_costs`, for every internal node below ``root``), :func:`_fill_row`.  A row
    depends only on its binary node, so the top of the tree (``top_count`` > 0) can leave the
    rows of binary nodes past the top records (``>= top_count``) to collapses of their own, run
    beside each other: such a node is listed in ``deferred``, and its row taken from
    ``deferred_rows`` in the same order.

    Parameters
    ----------
    nodes, refs : ndarray, shape (M, BINARY_WIDTH)
        Binary node records (float32 and their int32 view).
    queue : ndarray of int64
        Scratch, at least as long as the rows made.
    wide : ndarray of float32, shape (K, NODE_WIDTH)
        Written only when ``write``: a first call counts rows, a second fills them.
    count_root : bool
        Whether ``root`` itself adds to ``stats`` (the tree statistics, see INTERNAL_AREA), to
        which every binary node below it adds.

    Returns
    -------
    rows, deferred_count : int
    """
    wide_refs = wide.view(np.int32)
    slots = np.empty(WIDTH, np.int64)
    slot_row = np.empty(WIDTH, np.int64)
    pending = np.empty(WIDTH, np.int64)
    budgets = np.empty(WIDTH, np.int64)
    if count_root:
        _count_node(nodes, refs, root, stats, block)
    queue[0] = root
    rows = 1
    row = 0
    deferred_count = 0
    while row < rows:
        node = queue[row]
        size = 1
        slots[0] = node  # a root leaf: a wide node with one child
        if refs[node, BINARY_COUNT] <= 0:
            size = _fill_row(nodes, refs, node, costs, prices, slots, pending, budgets, stats,
                             block)
        for slot in range(size):
            child = slots[slot]
            if refs[child, BINARY_COUNT] > 0 or node == child:
                continue
            if top_count > 0 and child >= top_count:
                if write:
                    slot_row[slot] = deferred_rows[deferred_count]
                else:
                    deferred[deferred_count] = child
                deferred_count += 1
            else:
                queue[rows] = child
                slot_row[slot] = first_row + rows
                rows += 1
        if write:
            _write_row(nodes, refs, wide, wide_refs, first_row + row, slots, slot_row, size)
        row += 1
    return rows, deferred_count


@njit(cache=True, inline="always")
def _write_row(nodes, refs, wide, wide_refs, row, slots, slot_row, size):
    """Wide row ``row`` from binary nodes ``slots[:size]``.  A box that reaches the clamp of the
    primitive records (+-FLOAT32_MAX) is widened to infinity, so that it still contains a
    primitive beyond float32's range."""
    for slot in range(WIDTH):
        if slot >= size:
            for axis in range(3):
                wide[row, axis * WIDTH + slot] = np.inf
                wide[row, (axis + 3) * WIDTH + slot] = -np.inf
            wide_refs[row, REFS + slot] = 0
            wide_refs[row, COUNTS + slot] = 0
            continue
        child = slots[slot]
        for axis in range(3):
            lo = nodes[child, axis]
            hi = nodes[child, 3 + axis]
            wide[row, axis * WIDTH + slot] = -np.inf if lo == -FLOAT32_MAX else lo
            wide[row, (axis + 3) * WIDTH + slot] = np.inf if hi == FLOAT32_MAX else hi
        count = max(refs[child, BINARY_COUNT], 0)  # an internal node's may hold its number
        wide_refs[row, REFS + slot] = refs[child, BINARY_REF] if count > 0 else slot_row[slot]
        wide_refs[row, COUNTS + slot] = count


@njit(cache=True, parallel=True)
def _collapse_subtrees(nodes, refs, roots, queue_size, first_rows, wide, write, stats, rows,
                       costs, prices, block):
    """:func:`_collapse` below each of ``roots`` on all cores; ``stats`` (T, 4) and ``rows``
    (T,) receive each one's figures.  ``queue_size`` bounds any one's rows."""
    none = np.empty(0, np.int64)
    for t in prange(len(roots)):
        queue = np.empty(queue_size, np.int64)
        own = np.zeros(4)  # not a row of stats, which neighbouring subtrees' threads share
        # typed values, not literals, so that this call shares _wide_layout's compiled _collapse
        rows[t], _ = _collapse(nodes, refs, roots[t], first_rows[t], np.int64(0), none, none,
                               queue, wide, write, np.bool_(False), own, costs, prices,
                               block)
        for k in range(4):  # not a slice assignment, whose shape check takes long to compile
            stats[t, k] = own[k]


@njit(cache=True)
def _collapse_whole(nodes, refs, prim_count, prices, block):
    """:func:`_wide_layout` of a tree built as one subtree (``top_count`` 1), in one call from
    Python: its internal nodes' :func:`_ranked_costs`, then the collapse, counting rows and
    filling them.  A small tree's collapse took a dozen calls, each dearer than its work."""
    # typed values, not literals, so that these calls share the compiled functions that
    # _wide_layout's calls from Python use (a literal compiles a function once more)
    zero, no, yes = np.int64(0), np.bool_(False), np.bool_(True)
    order = np.empty(max(2 * prim_count - 1, 1), np.int64)
    none = np.empty(0, np.int64)
    listed, _, internal = _breadth_first(refs, zero, zero, order, none)
    costs = np.empty((internal, WIDTH), np.float32)
    _ranked_costs(nodes, refs, order, listed, zero, costs, prices, block)
    queue = np.empty(max(prim_count, 1), np.int64)
    stats = np.zeros(4)
    rows, _ = _collapse(nodes, refs, zero, zero, zero, none, none, queue,
                        np.empty((0, NODE_WIDTH), np.float32), no, yes, stats, costs, prices,
                        block)
    wide = np.empty((rows, NODE_WIDTH), np.float32)
    _collapse(nodes, refs, zero, zero, zero, none, none, queue, wide, yes, yes, np.zeros(4),
              costs, prices, block)
    return wide, stats


def _slot_costs(binary, prim_count, prices, block):
    """:func:`_ranked_costs` of every internal binary node of a tree built in several subtrees,
    (I, WIDTH) float32, numbered: the top of the tree first, then each subtree built in
    parallel (on all cores).  Each subtree is listed twice, to count its internal nodes and
    then to number them, so that the table is sized to them before any is filled, as
    :func:`_collapse` counts rows before it writes them."""
    refs = binary.nodes.view(np.int32)
    top_count = binary.top_count
    order = np.empty(top_count, np.int64)
    boundary = np.empty(2 * top_count, np.int64)
    listed, bounded, top_internal = _breadth_first(refs, 0, top_count, order, boundary)
    roots = boundary[:bounded]
    size = 2 * binary.largest_subtree - 1  # nodes of a subtree over m primitives: 2m - 1
    counts = np.zeros(bounded, np.int64)
    if bounded:
        with parallel_chunksize(1):
            _internal_counts(refs, roots, size, counts)
    firsts = top_internal + np.cumsum(counts) - counts
    costs = np.empty((top_internal + int(counts.sum()), WIDTH), np.float32)
    if bounded:
        with parallel_chunksize(1):
            _subtree_costs(binary.nodes, refs, roots, size, firsts, costs, prices, block)
    _ranked_costs(binary.nodes, refs, order, listed, 0, costs, prices, block)
    return costs


def _wide_layout(binary, prim_count, params):
    """Collapse a :class:`~raycore.bvh.build.BinaryBVH` into wide rows: (nodes, stats), with
    stats the tree statistics (see INTERNAL_AREA), summed in an order that does not depend on
    the number of threads.

    The top of the tree is collapsed first; the rows below it, inside the subtrees that were
    built in parallel, are then collapsed in parallel too, each group after the rows before it.
    Every collapse runs twice, counting rows and then filling them, so that the rows need no
    room beyond their own.  The binary tree's internal nodes are left numbered (their count
    fields, :func:`_ranked_costs`): it is of no use once collapsed.
    """
    nodes = binary.nodes
    refs = nodes.view(np.int32)
    block = params.block_size
    prices = np.array([params.traversal_cost, params.intersection_cost])
    if binary.top_count == 1:
        return _collapse_whole(nodes, refs, prim_count, prices, block)
    costs = _slot_costs(binary, prim_count, prices, block)
    empty = np.empty((0, NODE_WIDTH), np.float32)
    none = np.empty(0, np.int64)
    stats = np.zeros(4)
    queue = np.empty(binary.top_count, np.int64)
    deferred = np.empty(WIDTH * binary.top_count, np.int64)
    top_rows, count = _collapse(nodes, refs, 0, 0, binary.top_count, deferred, none, queue,
                                empty, False, True, stats, costs, prices, block)
    deferred = deferred[:count]
    # a subtree over m primitives has at most m - 1 internal nodes, one per wide row
    queue_size = binary.largest_subtree
    sub_stats = np.empty((count, 4))
    sub_rows = np.empty(count, np.int64)
    with parallel_chunksize(1):
        _collapse_subtrees(nodes, refs, deferred, queue_size, np.zeros(count, np.int64), empty,
                           False, sub_stats, sub_rows, costs, prices, block)
    first_rows = top_rows + np.concatenate([[0], np.cumsum(sub_rows)[:-1]]).astype(np.int64)
    wide = _new_rows(top_rows + int(sub_rows.sum()))
    _collapse(nodes, refs, 0, 0, binary.top_count, none, first_rows, queue, wide, True, True,
              np.zeros(4), costs, prices, block)
    with parallel_chunksize(1):
        _collapse_subtrees(nodes, refs, deferred, queue_size, first_rows, wide, True, sub_stats,
                           sub_rows, costs, prices, block)
    for part in sub_stats:
        stats += part
    return wide, stats


@njit(cache=True)
def _new_rows(rows):
    return np.empty((rows, NODE_WIDTH), np.float32)


def build_bvh_from_records(prims, lo, hi, params=None):
    """Build a flat BVH over primitive records (see :func:`raycore.bvh.build.records_from_bounds`),
    which are left in leaf order.

    Parameters
    ----------
    prims : ndarray of float32, shape (F, PRIM_WIDTH)
    lo, hi : ndarray of float64, shape (3,)
        Bounds of everything, reported as the BVH's.
    params : BuildParams, optional
    """
    params = params or BuildParams()
    check_primitive_count(len(prims))
    binary = build_binary_bvh(prims, params)
    nodes, stats = _wide_layout(binary, len(prims), params)
    root_area = float(_half_area(binary.nodes, 0))
    binary_depth = binary.depth
    del binary  # its nodes are the build's largest temporary after the records
    sah_cost = (params.traversal_cost * stats[INTERNAL_AREA]
                + params.intersection_cost * stats[LEAF_AREA]) / (root_area if root_area > 0
                                                                  else 1.0)
    return BVH(
        nodes=nodes,
        refs=nodes.view(np.int32),
        order=prims.view(np.int32)[:, PRIM_INDEX].astype(np.int64),
        lo=np.asarray(lo, np.float64).copy(),
        hi=np.asarray(hi, np.float64).copy(),
        depth=int(binary_depth),
        node_count=int(stats[NODE_COUNT]),
        leaf_count=int(stats[LEAF_COUNT]),
        sah_cost=float(sah_cost),
    )


def build_bvh(lo, hi, params=None):
    """Build a flat BVH over primitives with bounds ``lo``, ``hi`` (float, shape (F, 3)),
    with :class:`BuildParams` (defaults when None)."""
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    hi = np.ascontiguousarray(hi, dtype=np.float64)
    check_primitive_count(len(lo))
    return build_bvh_from_records(records_from_bounds(lo, hi), lo.min(axis=0), hi.max(axis=0),
                                  params)
