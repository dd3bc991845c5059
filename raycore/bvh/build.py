"""Binned SAH BVH construction (compiled, parallel over cores).

The builder works on axis-aligned bounds of abstract primitives, so one piece serves both levels:
the triangles of a mesh and the objects (instances, analytic shapes) of a scene.  It follows
pbrt-v4's ``BVHAggregate::buildRecursive`` (SAH buckets) and Embree's parallel binned builder,
and splits any node whose SAH cost beats making it a leaf (tinybvh's ``c_trav`` and ``c_int`` are
the two cost parameters).  It works on 32-byte float32 records (:mod:`raycore.bvh.records`),
splitting one node at a time as :mod:`raycore.bvh.split` does.

Work runs in two phases.  The top of the tree is split one depth at a time, every step over all
of a depth's nodes on all cores.  Once every node left is small (at most ``F / TASKS``
primitives), those subtrees are built independently, one per core at a time, each numbering its
nodes inside a range reserved for it (a subtree over n primitives has at most 2n - 1 nodes).
Nothing depends on which thread builds what, so the tree is the same for any number of threads.
"""

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, parallel_chunksize, prange

from raycore.bvh.records import BINARY_COUNT, BINARY_REF, BINARY_WIDTH, PRIM_WIDTH
from raycore.bvh.split import (
    CENTROIDS,
    SIDE_WIDTH,
    best_pair_split,
    best_split,
    bin_range,
    bins_for,
    bound_range,
    clear_bins,
    divide,
    empty_side,
    made_leaf,
    new_bins,
    partition,
    set_scale,
    store_side,
)
from raycore.rays import integer, real_number

#: Deepest tree the build may produce; traversal stacks are sized from it.
MAX_DEPTH = 64

#: The top phase splits nodes until none holds more than 1 / TASKS of the primitives: enough
#: subtrees to keep every core busy to the end, few enough that each is worth a task.
TASKS = 64
#: Nodes of up to this many primitives are left to the subtree phase: each depth of the top
#: phase costs three parallel steps, and a step can wait for a thread switch when another
#: process holds a core.
MIN_TASK = 16384
#: Records per work item of the top phase: each depth's nodes are binned and partitioned in
#: chunks of this many records, enough to amortise a work item's set-up.
CHUNK = 65536


@dataclass(frozen=True)
class BuildParams:
    """SAH build parameters.

    Attributes
    ----------
    bins : int
        Buckets per axis for the SAH sweep (pbrt uses 12, Embree 16-32).
    max_leaf_size : int
        Largest leaf; nodes above it are always split.
    traversal_cost, intersection_cost : float
        Relative costs of visiting a node and of testing one leaf block (tinybvh's c_trav,
        c_int).
    block_size : int
        Primitives a leaf tests at once: a leaf of n primitives costs ceil(n / block_size)
        tests (a mesh's leaves are blocks of eight float32 or four float64 triangles,
        :mod:`raycore.bvh.leaves`).
    """

    bins: int = 16
    max_leaf_size: int = 4
    traversal_cost: float = 1.0
    intersection_cost: float = 1.0
    block_size: int = 1

    def __post_init__(self):
        for name, low, high in (("bins", 2, 256), ("max_leaf_size", 1, 255),
                                 ("block_size", 1, 16)):
            integer(getattr(self, name), name, low, high)
        for name in ("traversal_cost", "intersection_cost"):
            value = real_number(getattr(self, name), name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive and finite, got {value!r}")


# ---------------------------------------------------------------------------- subtrees


@njit(cache=True, inline="always")
def _add_children(nodes, refs, node, child, sides):
    """Point ``node`` at its children ``child``, ``child + 1`` and give them their boxes."""
    refs[node, BINARY_REF] = child
    refs[node, BINARY_COUNT] = 0
    for k in range(6):
        nodes[child, k] = sides[0, k]
        nodes[child + 1, k] = sides[1, k]


@njit(cache=True, inline="always")
def _push(stack, stack_cbox, top, node, start, end, depth, sides, side):
    stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = node, start, end, depth
    for k in range(6):
        stack_cbox[top, k] = sides[side, CENTROIDS + k]


@njit(cache=True)
def _build_subtree(prims, nodes, refs, root, start, end, root_cbox, depth, first_free, bins,
                   costs):
    """Build the subtree of ``root`` (its box already in ``nodes``) over primitives
    ``start:end``, numbering new nodes from ``first_free``.  Returns the deepest leaf's depth, or
    -1 when the tree would pass MAX_DEPTH."""
    counts, boxes = new_bins(bins)
    suffix = np.empty((2, bins))
    sides = np.empty((2, SIDE_WIDTH), np.float32)
    cbox = np.empty(6, np.float32)
    scale = np.zeros(4, np.float32)
    # work stack: (node, start, end, depth) and the node's centroid box
    stack = np.empty((MAX_DEPTH + 2, 4), np.int64)
    stack_cbox = np.empty((MAX_DEPTH + 2, 6), np.float32)
    # element by element: assigning an array to a slice compiles NumPy's shape-mismatch error,
    # 1.7-2.6 s of a first build's compile for each kernel that does it
    for k in range(6):
        sides[0, CENTROIDS + k] = root_cbox[k]
    _push(stack, stack_cbox, 0, root, start, end, depth, sides, 0)
    top = 1
    free = first_free
    deepest = depth
    while top > 0:
        top -= 1
        node, lo, hi, level = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        for k in range(6):
            cbox[k] = stack_cbox[top, k]
        deepest = max(deepest, level)
        used = bins_for(hi - lo, bins)
        set_scale(cbox, used, scale)
        best = (-1, -1, np.inf)
        if hi - lo == 2:
            best = best_pair_split(prims, lo, cbox, scale, used)
        elif hi - lo > 2:
            clear_bins(counts, boxes, used)
            bin_range(prims, lo, hi, cbox, scale, used, counts, boxes)
            best = best_split(counts, boxes, scale, used, suffix, np.int64(costs[3]))
        if made_leaf(nodes, refs, node, lo, hi, costs, best):
            continue
        mid = divide(prims, lo, hi, used, best, sides, cbox, scale)
        if level + 1 >= MAX_DEPTH:
            return -1
        _add_children(nodes, refs, node, free, sides)
        # the left child is popped first, so that subtrees stay contiguous in memory
        _push(stack, stack_cbox, top, free + 1, mid, hi, level + 1, sides, 1)
        _push(stack, stack_cbox, top + 1, free, lo, mid, level + 1, sides, 0)
        top += 2
        free += 2
    return deepest


@njit(cache=True, parallel=True)
def _build_tasks(prims, nodes, refs, tasks, task_cbox, task_base, schedule, bins, costs,
                 deepest):
    """Build every task's subtree (``tasks`` rows: node, start, end, depth), in the order of
    ``schedule`` (largest first), on all cores; ``deepest`` receives each one's depth."""
    for s in prange(len(schedule)):
        t = schedule[s]
        deepest[t] = _build_subtree(prims, nodes, refs, tasks[t, 0], tasks[t, 1], tasks[t, 2],
                                    task_cbox[t], tasks[t, 3], task_base[t], bins, costs)


# ---------------------------------------------------------------------------- top phase


@njit(cache=True, parallel=True)
def _bound_all(prims):
    """A side (SIDE_WIDTH,) float32 holding all primitives, in chunks on all cores."""
    n = prims.shape[0]
    chunks = max(1, (n + CHUNK - 1) // CHUNK)
    parts = np.empty((chunks, SIDE_WIDTH), np.float32)
    for c in prange(chunks):
        own = np.empty((1, SIDE_WIDTH), np.float32)  # see _bin_items
        bound_range(prims, c * CHUNK, min(n, (c + 1) * CHUNK), own, 0)
        for k in range(SIDE_WIDTH):  # not a slice assignment: see _build_subtree
            parts[c, k] = own[0, k]
    acc = np.empty((1, SIDE_WIDTH), np.float32)
    store_side(acc, 0, empty_side())
    for c in range(chunks):
        for k in (0, 1, 2, CENTROIDS, CENTROIDS + 1, CENTROIDS + 2):
            acc[0, k] = min(acc[0, k], parts[c, k])
            acc[0, 3 + k] = max(acc[0, 3 + k], parts[c, 3 + k])
    return acc[0]


@njit(cache=True, parallel=True)
def _bin_items(prims, items, cboxes, scales, bins):
    """Bin every work item (``items`` rows: first record, end, node) with its node's centroid
    box and scale, on all cores: (counts (I, 3, bins) int64, boxes (I, 3, bins, 8) float32).

    Each item fills buckets of its own, allocated in its thread, and copies them out once:
    buckets of neighbouring items in one array share cache lines, and binning into them ran ten
    times slower on two cores than on one.
    """
    counts = np.empty((len(items), 3, bins), np.int64)
    boxes = np.empty((len(items), 3, bins, 8), np.float32)
    for i in prange(len(items)):
        node = items[i, 2]
        own_counts, own_boxes = new_bins(bins)
        clear_bins(own_counts, own_boxes, bins)
        bin_range(prims, items[i, 0], items[i, 1], cboxes[node], scales[node], bins,
                   own_counts, own_boxes)
        # element by element, not as slices: see _build_subtree
        for a in range(3):
            for b in range(bins):
                counts[i, a, b] = own_counts[a, b]
                for k in range(8):
                    boxes[i, a, b, k] = own_boxes[a, b, k]
    return counts, boxes


@njit(cache=True)
def _choose_splits(item_first, item_counts, item_boxes, scales, bins, block):
    """Merge each node's items' buckets and choose its split: (K, 3) float64 rows of axis,
    bucket and cost (axis -1: halve by count), as :func:`best_split` does.  Nodes of the top
    phase hold more than MIN_TASK records, more than any leaf, so they are always split."""
    counts, boxes = new_bins(bins)
    suffix = np.empty((2, bins))
    best = np.empty((len(item_first) - 1, 3))
    for k in range(len(item_first) - 1):
        clear_bins(counts, boxes, bins)
        for i in range(item_first[k], item_first[k + 1]):
            for a in range(3):
                for b in range(bins):
                    counts[a, b] += item_counts[i, a, b]
                    for f in range(3):
                        boxes[a, b, f] = min(boxes[a, b, f], item_boxes[i, a, b, f])
                        boxes[a, b, 3 + f] = max(boxes[a, b, 3 + f], item_boxes[i, a, b, 3 + f])
        best[k, 0], best[k, 1], best[k, 2] = best_split(counts, boxes, scales[k], bins,
                                                          suffix, block)
    return best


@njit(cache=True, parallel=True)
def _partition_items(prims, items, frontier, best, cboxes, scales, bins):
    """Partition every work item on its own, on all cores, by its node's split; for a node
    halved by count, only bound the item's records on each side of the middle.  Returns the
    left records of each item (I,) and each item's sides (I, 2, SIDE_WIDTH)."""
    lefts = np.empty(len(items), np.int64)
    item_sides = np.empty((len(items), 2, SIDE_WIDTH), np.float32)
    last = np.float32(bins - 1)
    for i in prange(len(items)):
        first, stop, k = items[i, 0], items[i, 1], items[i, 2]
        own = np.empty((2, SIDE_WIDTH), np.float32)  # see _bin_items
        axis = int(best[k, 0])
        if axis >= 0:
            lefts[i] = partition(prims, first, stop, axis, int(best[k, 1]), cboxes[k, axis],
                                  scales[k, axis], last, own) - first
        else:
            mid = (frontier[k, 1] + frontier[k, 2]) // 2
            lefts[i] = min(max(mid - first, 0), stop - first)
            bound_range(prims, first, first + lefts[i], own, 0)
            bound_range(prims, first + lefts[i], stop, own, 1)
        for side in range(2):  # not a slice assignment: see _build_subtree
            for k in range(SIDE_WIDTH):
                item_sides[i, side, k] = own[side, k]
    return lefts, item_sides


@njit(cache=True)
def _misplaced_runs(items, item_first, lefts, frontier, best):
    """Where each node's items put records on the wrong side of the node's boundary: per item
    (first record, count) of right records before it and of left records from it on, how many
    such records the node's earlier items hold, each node's boundary, and the swaps to make in
    pieces of CHUNK (P, 3): node, first swap, end."""
    runs = np.empty((len(items), 6), np.int64)  # right first, count, before; left alike
    mids = np.empty(len(frontier), np.int64)
    piece_count = 0
    for k in range(len(frontier)):
        mids[k] = frontier[k, 1] + lefts[item_first[k]:item_first[k + 1]].sum()
        right_before = left_before = 0
        for i in range(item_first[k], item_first[k + 1]):
            split = items[i, 0] + lefts[i]
            runs[i, 0] = split
            runs[i, 1] = max(0, min(items[i, 1], mids[k]) - split) if best[k, 0] >= 0 else 0
            runs[i, 2] = right_before
            runs[i, 3] = max(items[i, 0], mids[k])
            runs[i, 4] = max(0, split - max(items[i, 0], mids[k])) if best[k, 0] >= 0 else 0
            runs[i, 5] = left_before
            right_before += runs[i, 1]
            left_before += runs[i, 4]
        piece_count += (right_before + CHUNK - 1) // CHUNK
    pieces = np.empty((piece_count, 3), np.int64)
    p = 0
    for k in range(len(frontier)):
        moves = 0
        for i in range(item_first[k], item_first[k + 1]):
            moves += runs[i, 1]
        for first in range(0, moves, CHUNK):
            pieces[p, 0], pieces[p, 1], pieces[p, 2] = k, first, min(moves, first + CHUNK)
            p += 1
    return runs, mids, pieces


@njit(cache=True, parallel=True)
def _swap_pieces(prims, runs, item_first, pieces):
    """Trade the misplaced records of each node (see :func:`_misplaced_runs`), the k-th right
    record before its boundary with the k-th left record after it, in pieces on all cores."""
    for p in prange(len(pieces)):
        k, swap, stop = pieces[p, 0], pieces[p, 1], pieces[p, 2]
        own = runs[item_first[k]:item_first[k + 1]]
        a = np.searchsorted(own[:, 2], swap, side="right") - 1
        b = np.searchsorted(own[:, 5], swap, side="right") - 1
        i = own[a, 0] + swap - own[a, 2]
        j = own[b, 3] + swap - own[b, 5]
        while swap < stop:
            while i >= own[a, 0] + own[a, 1]:
                a += 1
                i = own[a, 0]
            while j >= own[b, 3] + own[b, 4]:
                b += 1
                j = own[b, 3]
            for f in range(PRIM_WIDTH):
                prims[i, f], prims[j, f] = prims[j, f], prims[i, f]
            i += 1
            j += 1
            swap += 1


@njit(cache=True)
def _build_whole(prims, nodes, refs, bins, costs):
    """Build the tree over all ``prims`` as one subtree (:func:`_build_subtree`), its root
    bounded here: what :func:`_split_top` and the subtree phase do for a tree of one task, in
    one call from Python rather than a dozen NumPy and compiled ones (with
    :func:`raycore.bvh.layout._collapse_whole`, a top-level tree over one object takes 32 us
    to build rather than 116, on the AVX2 EPYC).  Returns the deepest leaf's depth, or -1."""
    root = np.empty((1, SIDE_WIDTH), np.float32)
    bound_range(prims, 0, len(prims), root, 0)
    for k in range(6):  # element by element: see _build_subtree
        nodes[0, k] = root[0, k]
    zero = np.int64(0)  # typed, not a literal: see raycore.bvh.layout._collapse_whole
    return _build_subtree(prims, nodes, refs, zero, zero, len(prims), root[0, CENTROIDS:], zero,
                          np.int64(1), bins, costs)


def _split_top(prims, nodes, refs, bins, block, task_size):
    """Top phase, for more than ``task_size`` primitives: split nodes one depth at a time until
    none holds more than ``task_size`` primitives.  Each depth's nodes are cut into work items
    of CHUNK records, and each step (binning, partitioning, then trading misplaced records)
    runs over every item of the depth on all cores: three parallel steps per depth, not per
    node, since a parallel step costs a thread switch when another process holds a core.

    Returns
    -------
    tasks : ndarray of int64, shape (T, 4)
        The subtrees left to build: node, start, end, depth.
    task_cbox : ndarray of float32, shape (T, 6)
        Their centroid boxes.
    made : int
        Nodes numbered so far (0 .. made - 1), or -1 when the tree would pass MAX_DEPTH.
    """
    root = _bound_all(prims)
    nodes[0, 0:6] = root[0:6]
    frontier = np.array([[0, 0, len(prims), 0]], np.int64)  # node, start, end, depth
    cboxes = root[None, CENTROIDS:CENTROIDS + 6].copy()
    tasks, task_cbox = [], []
    made = 1
    while len(frontier):
        small = frontier[:, 2] - frontier[:, 1] <= task_size
        tasks.append(frontier[small])
        task_cbox.append(cboxes[small])
        frontier, cboxes = frontier[~small], cboxes[~small]
        if not len(frontier):
            break
        if frontier[0, 3] + 1 >= MAX_DEPTH:
            return None, None, -1
        scales = np.zeros((len(frontier), 4), np.float32)
        for k in range(len(frontier)):
            set_scale(cboxes[k], bins, scales[k])
        chunks = -(-(frontier[:, 2] - frontier[:, 1]) // CHUNK)
        item_first = np.concatenate([[0], np.cumsum(chunks)])
        node_of = np.repeat(np.arange(len(frontier)), chunks)
        first = frontier[node_of, 1] + CHUNK * (np.arange(len(node_of)) - item_first[node_of])
        items = np.stack([first, np.minimum(first + CHUNK, frontier[node_of, 2]), node_of], 1)
        best = _choose_splits(item_first, *_bin_items(prims, items, cboxes, scales, bins),
                              scales, bins, block)
        lefts, item_sides = _partition_items(prims, items, frontier, best, cboxes, scales, bins)
        runs, mids, pieces = _misplaced_runs(items, item_first, lefts, frontier, best)
        _swap_pieces(prims, runs, item_first, pieces)
        # children: the union of each node's items' sides
        sides = np.stack([
            np.minimum.reduceat(item_sides, item_first[:-1], axis=0),
            np.maximum.reduceat(item_sides, item_first[:-1], axis=0)])
        left_right = np.where(_LOWER, sides[0], sides[1])  # (K, 2, SIDE_WIDTH)
        children = made + 2 * np.arange(len(frontier))
        refs[frontier[:, 0], BINARY_REF] = children
        refs[frontier[:, 0], BINARY_COUNT] = 0
        nodes[children, 0:6] = left_right[:, 0, 0:6]
        nodes[children + 1, 0:6] = left_right[:, 1, 0:6]
        made += 2 * len(frontier)
        depth = frontier[:, 3] + 1
        frontier = np.stack([
            np.stack([children, frontier[:, 1], mids, depth], 1),
            np.stack([children + 1, mids, frontier[:, 2], depth], 1)], 1).reshape(-1, 4)
        cboxes = left_right[:, :, CENTROIDS:CENTROIDS + 6].reshape(-1, 6)
    return np.concatenate(tasks), np.concatenate(task_cbox), made


#: Lanes of a side that hold minima (box lo, centroid lo): the others hold maxima.
_LOWER = np.array([True] * 3 + [False] * 3 + [True] * 3 + [False] * 3)


# ---------------------------------------------------------------------------- whole tree


@njit(cache=True)
def _new_nodes(capacity):
    """Room for ``capacity`` binary nodes, (capacity, BINARY_WIDTH) float32.  Allocated by
    Numba rather than NumPy: NumPy asks the kernel for huge pages (2 MiB) on large arrays, and
    a huge page becomes resident whole at its first write, so the ranges reserved for subtrees
    but never written would take memory too."""
    return np.empty((capacity, BINARY_WIDTH), np.float32)


@dataclass(frozen=True)
class BinaryBVH:
    """A binary BVH as the builder leaves it.

    Attributes
    ----------
    nodes : ndarray of float32, shape (2F - 1, BINARY_WIDTH)
        Binary node records; node 0 is the root.  The children of an internal node are adjacent
        records.  Records that no node reaches are left unwritten (each subtree's range is
        reserved for its worst case, and untouched memory costs nothing), so walk the tree from
        the root.
    depth : int
        Depth of the deepest leaf (the root has depth 0).
    top_count : int
        Nodes of the top phase: records 0 .. top_count - 1.  Below them are the subtrees built
        in parallel, whose nodes lie past the top records.
    largest_subtree : int
        Primitives in the largest of those subtrees.
    """

    nodes: np.ndarray
    depth: int
    top_count: int
    largest_subtree: int


_TOO_DEEP = "BVH deeper than MAX_DEPTH: the primitive bounds are degenerate"


def build_binary_bvh(prims, params):
    """Build a binary BVH over primitive records, reordering them into leaf order in place.

    Parameters
    ----------
    prims : ndarray of float32, shape (F, PRIM_WIDTH)
        Primitive records (:mod:`raycore.bvh.records`); on return, in leaf order.
    params : BuildParams

    Returns
    -------
    BinaryBVH

    Raises
    ------
    ValueError
        When the tree would be deeper than MAX_DEPTH (degenerate bounds).
    """
    n = len(prims)
    nodes = _new_nodes(max(2 * n - 1, 1))
    refs = nodes.view(np.int32)
    bins = int(params.bins)
    costs = np.array([params.max_leaf_size, params.traversal_cost, params.intersection_cost,
                      params.block_size], np.float64)
    task_size = max(-(-n // TASKS), MIN_TASK)
    if n <= task_size:
        # one subtree, the whole tree (a small mesh, a scene's objects): built on this thread,
        # in one call, so that a first build compiles neither parallel launcher
        deepest = _build_whole(prims, nodes, refs, bins, costs)
        if deepest < 0:
            raise ValueError(_TOO_DEEP)
        return BinaryBVH(nodes=nodes, depth=int(deepest), top_count=1, largest_subtree=n)
    tasks, task_cbox, made = _split_top(prims, nodes, refs, bins, params.block_size, task_size)
    if made < 0:
        raise ValueError(_TOO_DEEP)
    sizes = tasks[:, 2] - tasks[:, 1]  # two tasks or more: the top phase split the root
    schedule = np.argsort(-sizes, kind="stable")
    # a subtree over m primitives adds at most 2m - 2 nodes below its root
    base = made + np.concatenate([[0], np.cumsum(2 * sizes - 2)[:-1]]).astype(np.int64)
    deepest = np.empty(len(tasks), np.int64)
    with parallel_chunksize(1):
        _build_tasks(prims, nodes, refs, tasks, task_cbox, base, schedule, bins, costs, deepest)
    if np.any(deepest < 0):
        raise ValueError(_TOO_DEEP)
    return BinaryBVH(nodes=nodes, depth=int(deepest.max()), top_count=int(made),
                     largest_subtree=int(sizes.max()))
