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
from numba import njit, prange

from raycore.bvh.build import (
    BINARY_COUNT,
    BINARY_REF,
    FLOAT32_MAX,
    MAX_DEPTH,
    PRIM_INDEX,
    BuildParams,
    build_binary_bvh,
    records_from_bounds,
)

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
    order : ndarray of int64, shape (F,)
        Primitive indices in leaf order.
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


@njit(cache=True, inline="always")
def _half_area(nodes, node):
    box = nodes[node]
    dx = np.float64(box[3]) - np.float64(box[0])
    dy = np.float64(box[4]) - np.float64(box[1])
    dz = np.float64(box[5]) - np.float64(box[2])
    return dx * dy + dy * dz + dz * dx


@njit(cache=True)
def _collapse(nodes, refs, capacity):
    """Group binary nodes into wide nodes of up to WIDTH children.

    From each wide node's binary node, the child of largest surface area that is an internal
    node is replaced by its two children until there are WIDTH of them (or only leaves).

    Parameters
    ----------
    nodes, refs : ndarray, shape (M, BINARY_WIDTH)
        Binary node records (float32 and their int32 view), from ``build_binary_bvh``.
    capacity : int
        At least the number of wide nodes (the primitive count will do).

    Returns
    -------
    children : ndarray of int32, shape (capacity, WIDTH)
        Binary node of each child slot, -1 where unused; row 0 is the root.
    child_row : ndarray of int32, shape (capacity, WIDTH)
        Wide row of each internal child.
    rows : int
        Wide nodes made: rows past it are unwritten.
    """
    children = np.empty((capacity, WIDTH), np.int32)
    child_row = np.empty((capacity, WIDTH), np.int32)
    source = np.empty(capacity, np.int32)  # binary node of each wide row
    source[0] = 0
    rows = 1
    row = 0
    while row < rows:
        node = source[row]
        children[row] = -1
        child_row[row] = 0
        if refs[node, BINARY_COUNT] > 0:
            # a root leaf: a wide node with one child
            children[row, 0] = node
            row += 1
            continue
        children[row, 0] = refs[node, BINARY_REF]
        children[row, 1] = refs[node, BINARY_REF] + 1
        size = 2
        while size < WIDTH:
            widest = -1
            widest_area = 0.0
            for slot in range(size):
                child = children[row, slot]
                if refs[child, BINARY_COUNT] == 0:
                    area = _half_area(nodes, child)
                    if widest < 0 or area > widest_area:
                        widest = slot
                        widest_area = area
            if widest < 0:
                break
            child = children[row, widest]
            children[row, widest] = refs[child, BINARY_REF]
            children[row, size] = refs[child, BINARY_REF] + 1
            size += 1
        for slot in range(size):
            child = children[row, slot]
            if refs[child, BINARY_COUNT] == 0:
                source[rows] = child
                child_row[row, slot] = rows
                rows += 1
        row += 1
    return children, child_row, rows


@njit(cache=True, parallel=True)
def _wide_nodes(nodes, refs, children, child_row, rows):
    """Wide rows (rows, NODE_WIDTH) float32 from the collapsed tree.  A box that reaches the
    clamp of the primitive records (+-FLOAT32_MAX) is widened to infinity there, so that it still
    contains a primitive beyond float32's range."""
    wide = np.empty((rows, NODE_WIDTH), np.float32)
    wide_refs = wide.view(np.int32)
    for row in prange(rows):
        for slot in range(WIDTH):
            child = children[row, slot]
            if child < 0:
                for axis in range(3):
                    wide[row, axis * WIDTH + slot] = np.inf
                    wide[row, (axis + 3) * WIDTH + slot] = -np.inf
                wide_refs[row, REFS + slot] = 0
                wide_refs[row, COUNTS + slot] = 0
                continue
            for axis in range(3):
                lo = nodes[child, axis]
                hi = nodes[child, 3 + axis]
                wide[row, axis * WIDTH + slot] = -np.inf if lo == -FLOAT32_MAX else lo
                wide[row, (axis + 3) * WIDTH + slot] = np.inf if hi == FLOAT32_MAX else hi
            count = refs[child, BINARY_COUNT]
            wide_refs[row, REFS + slot] = refs[child, BINARY_REF] if count > 0 else child_row[
                row, slot]
            wide_refs[row, COUNTS + slot] = count
    return wide


@njit(cache=True)
def _tree_stats(nodes, refs, traversal_cost, intersection_cost):
    """(sah_cost, node_count, leaf_count) of the binary tree, walked from the root."""
    stack = np.empty(MAX_DEPTH + 2, np.int64)
    stack[0] = 0
    top = 1
    internal_area = 0.0
    leaf_area = 0.0
    node_count = 0
    leaf_count = 0
    while top > 0:
        top -= 1
        node = stack[top]
        node_count += 1
        count = refs[node, BINARY_COUNT]
        if count > 0:
            leaf_count += 1
            leaf_area += _half_area(nodes, node) * count
        else:
            internal_area += _half_area(nodes, node)
            stack[top] = refs[node, BINARY_REF]
            stack[top + 1] = refs[node, BINARY_REF] + 1
            top += 2
    root_area = _half_area(nodes, 0)
    if not root_area > 0:
        root_area = 1.0
    sah = (traversal_cost * internal_area + intersection_cost * leaf_area) / root_area
    return sah, node_count, leaf_count


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
    if len(prims) == 0:
        raise ValueError("cannot build a BVH over zero primitives")
    binary, depth = build_binary_bvh(
        prims, int(params.bins), int(params.max_leaf_size), float(params.traversal_cost),
        float(params.intersection_cost))
    binary_refs = binary.view(np.int32)
    sah_cost, node_count, leaf_count = _tree_stats(
        binary, binary_refs, float(params.traversal_cost), float(params.intersection_cost))
    children, child_row, rows = _collapse(binary, binary_refs, len(prims))
    nodes = _wide_nodes(binary, binary_refs, children, child_row, rows)
    del binary, binary_refs, children, child_row
    return BVH(
        nodes=nodes,
        refs=nodes.view(np.int32),
        order=prims.view(np.int32)[:, PRIM_INDEX].astype(np.int64),
        lo=np.asarray(lo, np.float64).copy(),
        hi=np.asarray(hi, np.float64).copy(),
        depth=int(depth),
        node_count=int(node_count),
        leaf_count=int(leaf_count),
        sah_cost=float(sah_cost),
    )


def build_bvh(lo, hi, params=None):
    """Build a flat BVH over primitives with bounds ``lo``, ``hi`` (float, shape (F, 3)),
    with :class:`BuildParams` (defaults when None)."""
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    hi = np.ascontiguousarray(hi, dtype=np.float64)
    if len(lo) == 0:
        raise ValueError("cannot build a BVH over zero primitives")
    return build_bvh_from_records(records_from_bounds(lo, hi), lo.min(axis=0), hi.max(axis=0),
                                  params)
