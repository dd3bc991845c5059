"""Flat node layout for traversal, and tree-quality statistics.

Each internal node is one 64-byte row of float32 holding the boxes of *both* children and their
references (Aila & Laine 2009's layout, as in tinybvh's ``BVH_GPU``): one cache line is fetched
per visited node, and both children are tested before choosing which to visit first.

Row layout (16 × 4 bytes)::

    [0:3]  left child lo    [3:6]  left child hi
    [6:9]  right child lo   [9:12] right child hi
    [12] left ref   [13] right ref   [14] left count   [15] right count   (int32 bit patterns)

A child with count 0 is an internal node whose row is ``ref``; a child with count > 0 is a leaf
holding primitives ``ref .. ref + count - 1`` in leaf order.  Boxes are rounded outwards to float32,
so a float64 scene keeps conservative boxes at half the memory.
"""

from dataclasses import dataclass

import numpy as np

from raycore.bvh.build import BuildParams, build_binary_bvh

NODE_WIDTH = 16
LEFT_REF, RIGHT_REF, LEFT_COUNT, RIGHT_COUNT = 12, 13, 14, 15


@dataclass(frozen=True)
class BVH:
    """A built BVH in flat form.

    Attributes
    ----------
    nodes : ndarray of float32, shape (K, 16)
        Child-pair rows (see the module docstring); row 0 holds the root's children.
    refs : ndarray of int32, shape (K, 16)
        The same memory viewed as int32, for the references and counts.
    order : ndarray of int64, shape (F,)
        Primitive indices in leaf order.
    lo, hi : ndarray of float64, shape (3,)
        Bounds of everything.
    depth, node_count, leaf_count : int
    sah_cost : float
        Expected cost of a random ray hitting the root (MacDonald & Booth 1990), with the
        build's traversal and intersection costs.
    """

    nodes: np.ndarray
    refs: np.ndarray
    order: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    depth: int
    node_count: int
    leaf_count: int
    sah_cost: float

    @property
    def nbytes(self):
        return self.nodes.nbytes + self.order.nbytes


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

    if is_leaf[0]:
        # a root leaf still needs a row: pair it with an empty box that no ray enters
        internal = np.zeros(1, np.int64)
        children = np.array([[0, -1]])
    else:
        internal = np.flatnonzero(~is_leaf)
        children = np.stack([left[internal], right[internal]], axis=1)
    row_of = np.full(len(node_lo), -1, np.int64)
    row_of[internal] = np.arange(len(internal))

    box_lo, box_hi = round_outwards(node_lo, node_hi)
    nodes = np.zeros((len(internal), NODE_WIDTH), np.float32)
    refs = nodes.view(np.int32)
    for side, child in enumerate(children.T):
        real = child >= 0
        c = np.where(real, child, 0)
        nodes[:, 6 * side:6 * side + 3] = np.where(real[:, None], box_lo[c], np.inf)
        nodes[:, 6 * side + 3:6 * side + 6] = np.where(real[:, None], box_hi[c], -np.inf)
        leaf = real & is_leaf[c]
        refs[:, LEFT_REF + side] = np.where(leaf, first[c], np.where(real, row_of[c], 0))
        refs[:, LEFT_COUNT + side] = np.where(leaf, count[c], 0)
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
