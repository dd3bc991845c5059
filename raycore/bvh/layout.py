"""Flat node layout for traversal, and tree-quality statistics.

The binary SAH tree is collapsed into a wide one (Wald et al. 2008, "Getting rid of packets"):
each node holds up to eight children, whose boxes are stored plane by plane so that one vector
instruction tests all eight (:mod:`raycore.bvh.simd`).  A wide node is one 256-byte row of
float32 (four cache lines)::

    [0:8] lo x   [8:16] lo y   [16:24] lo z   [24:32] hi x   [32:40] hi y   [40:48] hi z
    [48:56] refs   [56:64] counts   (int32 bit patterns)

A child with count 0 is an internal node whose row is ``ref``; a child with count > 0 is a leaf
holding primitives ``ref .. ref + count - 1`` in leaf order; an unused slot has an empty box
(lo = +inf, hi = -inf) that no ray enters.  Boxes are rounded outwards to float32, so a float64
scene keeps conservative boxes at half the memory.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from raycore.bvh.build import BuildParams, build_binary_bvh

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


def round_outwards(lo, hi):
    """Round float64 bounds to float32 so that the float32 box contains the float64 one."""
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32, hi32


def _half_areas(lo, hi):
    extent = np.maximum(hi - lo, 0.0)
    return extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 2] * extent[:, 0]


@njit(cache=True)
def _collapse(left, right, areas):
    """Group binary nodes into wide nodes of up to WIDTH children.

    From each wide node's binary node, the child of largest surface area that is an internal
    node is replaced by its two children until there are WIDTH of them (or only leaves).

    Returns
    -------
    children : ndarray of int64, shape (K, WIDTH)
        Binary node of each child slot, -1 where unused; row 0 is the root.
    child_row : ndarray of int64, shape (K, WIDTH)
        Wide row of each internal child (0 elsewhere).
    """
    n = len(left)
    children = np.full((max(n, 1), WIDTH), -1, np.int64)
    child_row = np.zeros((max(n, 1), WIDTH), np.int64)
    source = np.empty(max(n, 1), np.int64)  # binary node of each wide row
    source[0] = 0
    rows = 1
    row = 0
    while row < rows:
        node = source[row]
        if left[node] < 0:
            # a root leaf: a wide node with one child
            children[row, 0] = node
            row += 1
            continue
        children[row, 0] = left[node]
        children[row, 1] = right[node]
        size = 2
        while size < WIDTH:
            widest = -1
            for slot in range(size):
                child = children[row, slot]
                if left[child] >= 0 and (widest < 0 or areas[child] > areas[children[row, widest]]):
                    widest = slot
            if widest < 0:
                break
            child = children[row, widest]
            children[row, widest] = left[child]
            children[row, size] = right[child]
            size += 1
        for slot in range(size):
            child = children[row, slot]
            if left[child] >= 0:
                source[rows] = child
                child_row[row, slot] = rows
                rows += 1
        row += 1
    return children[:rows].copy(), child_row[:rows].copy()


def build_bvh(lo, hi, params=None):
    """Build a flat BVH over primitives with bounds ``lo``, ``hi`` (float64, shape (F, 3)),
    with :class:`BuildParams` (defaults when None)."""
    params = params or BuildParams()
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    hi = np.ascontiguousarray(hi, dtype=np.float64)
    if len(lo) == 0:
        raise ValueError("cannot build a BVH over zero primitives")
    order, node_lo, node_hi, left, right, first, count, depth = build_binary_bvh(
        lo, hi, int(params.bins), int(params.max_leaf_size),
        float(params.traversal_cost), float(params.intersection_cost),
    )
    is_leaf = count > 0
    areas = _half_areas(node_lo, node_hi)
    root_area = areas[0] if areas[0] > 0 else 1.0
    sah_cost = float(
        (params.traversal_cost * areas[~is_leaf].sum()
         + params.intersection_cost * (areas[is_leaf] * count[is_leaf]).sum()) / root_area
    )

    box_lo, box_hi = round_outwards(node_lo, node_hi)
    children, child_row = _collapse(left, right, areas)
    rows = len(children)
    nodes = np.zeros((rows, NODE_WIDTH), np.float32)
    refs = nodes.view(np.int32)
    real = children >= 0
    c = np.where(real, children, 0)
    for axis in range(3):
        nodes[:, axis * WIDTH:(axis + 1) * WIDTH] = np.where(real, box_lo[c, axis], np.inf)
        nodes[:, (axis + 3) * WIDTH:(axis + 4) * WIDTH] = np.where(real, box_hi[c, axis], -np.inf)
    leaf = real & is_leaf[c]
    refs[:, REFS:REFS + WIDTH] = np.where(leaf, first[c], np.where(real, child_row, 0))
    refs[:, COUNTS:COUNTS + WIDTH] = np.where(leaf, count[c], 0)
    return BVH(
        nodes=nodes,
        refs=refs,
        order=order,
        lo=node_lo[0].copy(),
        hi=node_hi[0].copy(),
        depth=int(depth),
        node_count=int(len(node_lo)),
        leaf_count=int(is_leaf.sum()),
        sah_cost=sah_cost,
    )
