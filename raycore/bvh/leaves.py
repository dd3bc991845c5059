"""Leaf triangles stored in blocks, plane by plane, for the vector triangle test.

A mesh's leaves are packed into blocks of L triangles, as many as a 256-bit vector holds
coordinates in the scene's precision (eight float32 or four float64:
:func:`~raycore.bvh.simd.lanes_for`).  A block is one row of BLOCK_PLANES * L values: the x of
the L first vertices, then their y and z, then the second and third vertices alike (Embree's
Triangle8v and Triangle4v), then the triangles' face indices, as int32 at the start of a plane
of their own (its other half unused in float64).  One vector instruction then works on a
block's triangles (:func:`raycore.bvh.simd.watertight_block`), and the face index of a hit
lies in the lines its test loaded: read from a table of its own, it was a cache miss sampled
at about 5 % of a random ray's time.  A leaf of ``count`` triangles takes ``ceil(count / L)``
consecutive blocks; the lanes left over are NaN, which no ray hits, with face index -1.

A triangle's *slot* is ``L * block + lane``.  Degenerate triangles (the cross product of their
edges is exactly zero in the scene's precision, which every triangle test rejects) are stored
as NaN too: the test need not look for them.
"""

import numpy as np
from numba import njit

from raycore._memory import empty_on_line
from raycore.bvh.layout import COUNTS, REFS, WIDTH
from raycore.bvh.simd import (
    FACE_PLANE,
    VECTOR_BYTES,
    block_face,
    block_lanes,
    block_width,
    lanes_for,
    nonnegative,
)

#: Where a block's face indices start in its row viewed as int32 (:func:`face_ints`).
FACE_COLUMN = FACE_PLANE * VECTOR_BYTES // 4


def face_ints(blocks):
    """The leaf blocks ``blocks`` (B, BLOCK_PLANES * L) viewed as int32: the face index of lane
    ``lane`` of block ``b`` is at ``[b, FACE_COLUMN + lane]``."""
    return blocks.view(np.int32)


@njit(cache=True, inline="always")
def slot_index(blocks, slot, value):
    """Where value ``value`` (0..8: a.x, a.y, a.z, b.x, ..., c.z) of the triangle in ``slot``
    lies in ``blocks``: (row, column)."""
    lanes = block_lanes(blocks)
    slot = nonnegative(slot)
    return slot // lanes, value * lanes + slot % lanes


@njit(cache=True, inline="always")
def slot_value(blocks, slot, value):
    """Value ``value`` (0..8: a.x, a.y, a.z, b.x, ..., c.z) of the triangle in ``slot``."""
    return blocks[slot_index(blocks, slot, value)]


@njit(cache=True, inline="always")
def slot_face(blocks, slot):
    """Face index of the triangle in ``slot`` (-1 for a padding lane)."""
    slot = nonnegative(slot)
    lanes = block_lanes(blocks)
    return block_face(blocks, slot // lanes, slot % lanes)


@njit(cache=True)
def _fill_blocks(vertices, faces, order, leaf_first, leaf_count, leaf_block, blocks, ints):
    lanes = block_lanes(blocks)
    for leaf in range(len(leaf_first)):
        for k in range(leaf_count[leaf]):
            face = order[leaf_first[leaf] + k]
            slot = lanes * leaf_block[leaf] + k
            ints[slot // lanes, FACE_COLUMN + slot % lanes] = face
            for vertex in range(3):
                for axis in range(3):
                    blocks[slot_index(blocks, slot, 3 * vertex + axis)] = vertices[
                        faces[face, vertex], axis]
            # the edges' cross product as the triangle tests compute it, in the scene's precision
            ax, ay, az = (slot_value(blocks, slot, 0), slot_value(blocks, slot, 1),
                          slot_value(blocks, slot, 2))
            e1x, e1y, e1z = (slot_value(blocks, slot, 3) - ax, slot_value(blocks, slot, 4) - ay,
                             slot_value(blocks, slot, 5) - az)
            e2x, e2y, e2z = (slot_value(blocks, slot, 6) - ax, slot_value(blocks, slot, 7) - ay,
                             slot_value(blocks, slot, 8) - az)
            if (e1y * e2z - e1z * e2y == 0 and e1z * e2x - e1x * e2z == 0
                    and e1x * e2y - e1y * e2x == 0):
                for j in range(9):
                    blocks[slot_index(blocks, slot, j)] = np.nan


def pack_leaves(nodes, refs, order, vertices, faces, dtype):
    """Pack a mesh's leaf triangles into blocks, and point its BVH's leaves at them.

    Parameters
    ----------
    nodes, refs : ndarray, shape (K, 64)
        The mesh's wide BVH rows (float32 and their int32 view), whose leaf children reference
        ``order[ref:ref + count]``.  Changed in place: leaf children then reference their first
        block (the count stays the number of triangles).
    order : ndarray of int, shape (F,)
        Face indices in leaf order.
    vertices : ndarray of float64, shape (V, 3)
    faces : ndarray of int64, shape (F, 3)
    dtype : numpy float type
        The scene's precision.

    Returns
    -------
    blocks : ndarray of dtype, shape (B, BLOCK_PLANES * L)
        L = :func:`~raycore.bvh.simd.lanes_for` (dtype); starting on a cache line.
    """
    counts = refs[:, COUNTS:COUNTS + WIDTH]
    firsts = refs[:, REFS:REFS + WIDTH]
    is_leaf = counts > 0
    leaf_first = firsts[is_leaf].astype(np.int64)
    leaf_count = counts[is_leaf].astype(np.int64)
    # blocks are laid out in leaf order, so that a subtree's triangles stay together in memory
    by_first = np.argsort(leaf_first, kind="stable")
    lanes = lanes_for(dtype)
    sizes = -(-leaf_count[by_first] // lanes)
    leaf_block = np.empty_like(leaf_first)
    leaf_block[by_first] = np.cumsum(sizes) - sizes
    block_count = int(sizes.sum())
    blocks = empty_blocks(block_count, dtype)
    blocks[:] = np.nan
    ints = face_ints(blocks)
    ints[:, FACE_COLUMN:] = -1
    _fill_blocks(vertices, faces, order, leaf_first, leaf_count, leaf_block, blocks, ints)
    firsts[is_leaf] = leaf_block
    return blocks


def empty_blocks(count, dtype):
    """Uninitialised room for ``count`` leaf blocks in precision ``dtype``, starting on a cache
    line: each block then takes five lines, not six (as :func:`~raycore.bvh.simd.prefetch_block`
    asks for them)."""
    width = block_width(dtype)
    return empty_on_line(count * width, dtype).reshape(count, width)
