"""Fixed-size float32 records the BVH builder works on, and rounding to float32.

Memory is what limits the meshes a machine can build, so the build keeps one 32-byte float32
record per primitive (its box and index, Embree's PrimRef) and partitions those records in
place; the binary nodes are 32-byte float32 records too.  Boxes are rounded outwards to float32,
so they stay conservative for a float64 scene.
"""

import numpy as np
from numba import njit, prange

#: Primitive record (float32, 32 bytes): box lo xyz, box hi xyz, then the primitive's index as
#: int32 bits and one unused slot.
PRIM_WIDTH = 8
PRIM_INDEX = 6
#: Binary node record (float32, 32 bytes): box lo xyz, hi xyz, then as int32 bits the first child
#: (the second is the next record) or the first primitive of a leaf, and the leaf's size (0 for
#: an internal node).
BINARY_WIDTH = 8
BINARY_REF, BINARY_COUNT = 6, 7

#: Most primitives one BVH holds: indices and node references are int32, and a binary tree over
#: F primitives has up to 2F - 1 nodes.
MAX_PRIMITIVES = 2**30

#: Records are clamped to finite float32 (a box beyond it is widened to infinity in the final
#: layout), so that centroids and extents never meet inf - inf.
FLOAT32_MAX = np.float32(np.finfo(np.float32).max)


@njit(cache=True, inline="always")
def round_down32(x):
    """Largest float32 <= ``x`` (float32 or float64), clamped to [-FLOAT32_MAX, FLOAT32_MAX]."""
    y = np.float32(x)
    if y > x:
        y = np.nextafter(y, np.float32(-np.inf))
    return min(max(y, -FLOAT32_MAX), FLOAT32_MAX)


@njit(cache=True, inline="always")
def round_up32(x):
    """Smallest float32 >= ``x`` (float32 or float64), clamped to [-FLOAT32_MAX, FLOAT32_MAX]."""
    y = np.float32(x)
    if y < x:
        y = np.nextafter(y, np.float32(np.inf))
    return min(max(y, -FLOAT32_MAX), FLOAT32_MAX)


@njit(cache=True, parallel=True)
def records_from_bounds(lo, hi):
    """Primitive records of boxes ``lo``, ``hi`` (float32 or float64, shape (F, 3)), rounded
    outwards to float32: an ndarray of float32, shape (F, PRIM_WIDTH)."""
    n = lo.shape[0]
    prims = np.empty((n, PRIM_WIDTH), np.float32)
    index = prims.view(np.int32)
    for p in prange(n):
        for a in range(3):
            prims[p, a] = round_down32(lo[p, a])
            prims[p, 3 + a] = round_up32(hi[p, a])
        index[p, PRIM_INDEX] = p
        index[p, PRIM_INDEX + 1] = 0
    return prims


def check_primitive_count(count):
    """Raise ``ValueError`` unless a BVH can hold ``count`` primitives."""
    if count == 0:
        raise ValueError("cannot build a BVH over zero primitives")
    if count > MAX_PRIMITIVES:
        raise ValueError(f"cannot build a BVH over {count} primitives: at most {MAX_PRIMITIVES}")
