"""Binned SAH BVH construction (compiled).

The builder works on axis-aligned bounds of abstract primitives, so one piece serves both levels:
the triangles of a mesh and the objects (instances, analytic shapes) of a scene.  It follows
pbrt-v4's ``BVHAggregate::buildRecursive`` (SAH buckets) with an explicit work stack instead of
recursion, and splits any node whose SAH cost beats making it a leaf (tinybvh's ``c_trav`` and
``c_int`` are the two cost parameters).
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

#: Deepest tree the build may produce; traversal stacks are sized from it.
MAX_DEPTH = 64


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
        Relative costs of visiting a node and of one primitive test (tinybvh's c_trav, c_int).
    """

    bins: int = 16
    max_leaf_size: int = 4
    traversal_cost: float = 1.0
    intersection_cost: float = 1.0

    def __post_init__(self):
        for name, low, high in (("bins", 2, 256), ("max_leaf_size", 1, 255)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            if not low <= value <= high:
                raise ValueError(f"{name} must be between {low} and {high}, got {value}")
        for name in ("traversal_cost", "intersection_cost"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float, np.integer, np.floating))
                    and not isinstance(value, bool) and np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive and finite, got {value!r}")


@njit(cache=True, inline="always")
def _half_area(lo, hi):
    dx = hi[0] - lo[0]
    dy = hi[1] - lo[1]
    dz = hi[2] - lo[2]
    return dx * dy + dy * dz + dz * dx


@njit(cache=True, inline="always")
def _bin_of(doubled_centroid, lo, scale, bins):
    return min(int((doubled_centroid - lo) * scale), bins - 1)


@njit(cache=True)
def build_binary_bvh(lo, hi, bins, max_leaf_size, traversal_cost, intersection_cost):
    """Build a binary BVH over primitives given by their bounds.

    Primitive records (bounds and index) are partitioned in place, so every pass reads memory in
    order.  Each node costs one pass that bins its primitives on all three axes and one partition
    pass; the bins give the children's bounds and the partition their centroid bounds.
    Centroids are kept doubled (lo + hi) to save a multiplication.

    Parameters
    ----------
    lo, hi : ndarray of float64, shape (F, 3)
        Bounds of each primitive (finite).
    bins, max_leaf_size : int
    traversal_cost, intersection_cost : float

    Returns
    -------
    order : ndarray of int64, shape (F,)
        Primitive indices in leaf order: a leaf holds ``order[first:first + count]``.
    node_lo, node_hi : ndarray of float64, shape (M, 3)
        Node bounds; node 0 is the root.
    left, right : ndarray of int64, shape (M,)
        Children of internal nodes (siblings are adjacent: ``right == left + 1``); -1 for leaves.
    first, count : ndarray of int64, shape (M,)
        Primitive range of leaves (``count == 0`` for internal nodes).
    depth : int
        Depth of the deepest leaf (the root has depth 0).
    """
    n = lo.shape[0]
    prims = np.empty((n, 8))  # lo(3), hi(3), index, padding to 64 bytes
    prims[:, 0:3] = lo
    prims[:, 3:6] = hi
    prims[:, 6] = np.arange(n)
    capacity = max(2 * n - 1, 1)
    node_lo = np.empty((capacity, 3))
    node_hi = np.empty((capacity, 3))
    left = np.full(capacity, -1, np.int64)
    right = np.full(capacity, -1, np.int64)
    first = np.zeros(capacity, np.int64)
    count = np.zeros(capacity, np.int64)

    bin_count = np.zeros((3, bins), np.int64)
    bin_box = np.empty((3 * bins, 6))  # row a * bins + b: bounds of bucket b on axis a
    suffix_box = np.empty((bins, 6))
    suffix_count = np.empty(bins, np.int64)
    acc = np.empty(6)
    box = np.empty(12)

    # work stack: (node, start, end, depth) and the node's bounds and doubled-centroid bounds
    stack = np.empty((MAX_DEPTH + 2, 4), np.int64)
    stack_box = np.empty((MAX_DEPTH + 2, 12))
    stack_box[0, 0:3] = np.inf
    stack_box[0, 3:6] = -np.inf
    stack_box[0, 6:9] = np.inf
    stack_box[0, 9:12] = -np.inf
    for p in range(n):
        for a in range(3):
            c = prims[p, a] + prims[p, 3 + a]
            stack_box[0, a] = min(stack_box[0, a], prims[p, a])
            stack_box[0, 3 + a] = max(stack_box[0, 3 + a], prims[p, 3 + a])
            stack_box[0, 6 + a] = min(stack_box[0, 6 + a], c)
            stack_box[0, 9 + a] = max(stack_box[0, 9 + a], c)
    stack[0, 0] = 0
    stack[0, 1] = 0
    stack[0, 2] = n
    stack[0, 3] = 0
    top = 1
    nodes = 1
    max_depth = 0
    scale = np.empty(3)
    while top > 0:
        top -= 1
        node, start, end, level = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        box[:] = stack_box[top]
        max_depth = max(max_depth, level)
        node_lo[node] = box[0:3]
        node_hi[node] = box[3:6]
        size = end - start

        best_axis = -1
        best_bucket = -1
        best_cost = np.inf
        if size > 1:
            # bin every primitive on all three axes in one pass
            for a in range(3):
                extent = box[9 + a] - box[6 + a]
                scale[a] = bins / extent if extent > 0 else 0.0
            bin_count[:] = 0
            bin_box[:, 0:3] = np.inf
            bin_box[:, 3:6] = -np.inf
            for i in range(start, end):
                plox, ploy, ploz = prims[i, 0], prims[i, 1], prims[i, 2]
                phix, phiy, phiz = prims[i, 3], prims[i, 4], prims[i, 5]
                for a in range(3):
                    if scale[a] == 0.0:
                        continue
                    b = _bin_of(prims[i, a] + prims[i, 3 + a], box[6 + a], scale[a], bins)
                    bin_count[a, b] += 1
                    r = a * bins + b
                    bin_box[r, 0] = min(bin_box[r, 0], plox)
                    bin_box[r, 1] = min(bin_box[r, 1], ploy)
                    bin_box[r, 2] = min(bin_box[r, 2], ploz)
                    bin_box[r, 3] = max(bin_box[r, 3], phix)
                    bin_box[r, 4] = max(bin_box[r, 4], phiy)
                    bin_box[r, 5] = max(bin_box[r, 5], phiz)
            for a in range(3):
                if scale[a] == 0.0:
                    continue
                # suffix unions, then a prefix sweep that prices each split plane
                acc[0:3] = np.inf
                acc[3:6] = -np.inf
                total = 0
                for b in range(bins - 1, 0, -1):
                    r = a * bins + b
                    for k in range(3):
                        acc[k] = min(acc[k], bin_box[r, k])
                        acc[3 + k] = max(acc[3 + k], bin_box[r, 3 + k])
                    total += bin_count[a, b]
                    suffix_box[b] = acc
                    suffix_count[b] = total
                acc[0:3] = np.inf
                acc[3:6] = -np.inf
                total = 0
                for b in range(1, bins):
                    r = a * bins + b - 1
                    for k in range(3):
                        acc[k] = min(acc[k], bin_box[r, k])
                        acc[3 + k] = max(acc[3 + k], bin_box[r, 3 + k])
                    total += bin_count[a, b - 1]
                    if total == 0 or suffix_count[b] == 0:
                        continue
                    cost = (_half_area(acc[0:3], acc[3:6]) * total
                            + _half_area(suffix_box[b, 0:3], suffix_box[b, 3:6]) * suffix_count[b])
                    if cost < best_cost:
                        best_cost = cost
                        best_axis = a
                        best_bucket = b

        area = _half_area(box[0:3], box[3:6])
        leaf_cost = intersection_cost * size
        split_cost = traversal_cost + intersection_cost * best_cost / area if area > 0 else np.inf
        make_leaf = size == 1 or (size <= max_leaf_size and leaf_cost <= split_cost)
        if make_leaf or (best_axis < 0 and size <= max_leaf_size):
            first[node] = start
            count[node] = size
            continue

        left_box = stack_box[top + 1]  # the left child goes on top of the stack
        right_box = stack_box[top]
        if best_axis >= 0:
            a = best_axis
            i = start
            j = end - 1
            while i <= j:
                if _bin_of(prims[i, a] + prims[i, 3 + a], box[6 + a], scale[a], bins) < best_bucket:
                    i += 1
                else:
                    for k in range(7):
                        prims[i, k], prims[j, k] = prims[j, k], prims[i, k]
                    j -= 1
            mid = i
        else:
            # all centroids coincide but the node is too big for a leaf: split by count
            mid = (start + end) // 2
        # children's bounds and doubled-centroid bounds
        for child_box, lo_i, hi_i in ((left_box, start, mid), (right_box, mid, end)):
            child_box[0:3] = np.inf
            child_box[3:6] = -np.inf
            child_box[6:9] = np.inf
            child_box[9:12] = -np.inf
            for i in range(lo_i, hi_i):
                for k in range(3):
                    c = prims[i, k] + prims[i, 3 + k]
                    child_box[k] = min(child_box[k], prims[i, k])
                    child_box[3 + k] = max(child_box[3 + k], prims[i, 3 + k])
                    child_box[6 + k] = min(child_box[6 + k], c)
                    child_box[9 + k] = max(child_box[9 + k], c)

        child = nodes
        nodes += 2
        left[node] = child
        right[node] = child + 1
        if level + 1 >= MAX_DEPTH:
            raise ValueError("BVH deeper than MAX_DEPTH: the primitive bounds are degenerate")
        # the left child is popped first, so that subtrees stay contiguous in memory
        stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = child + 1, mid, end, level + 1
        stack[top + 1, 0], stack[top + 1, 1], stack[top + 1, 2], stack[top + 1, 3] = (
            child, start, mid, level + 1)
        top += 2

    order = prims[:, 6].astype(np.int64)
    return (
        order,
        node_lo[:nodes].copy(),
        node_hi[:nodes].copy(),
        left[:nodes].copy(),
        right[:nodes].copy(),
        first[:nodes].copy(),
        count[:nodes].copy(),
        max_depth,
    )
