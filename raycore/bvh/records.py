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


#: Primitives from which records are made on all cores; fewer are made on the calling thread
#: (as a mesh's bounds are, up to a chunk of faces: :func:`raycore.mesh.referenced_bounds`).
#: Between builds the threads sleep, and waking them took 30-80 us of a small build (suzanne,
#: 968 triangles: 757 -> 596 us with the three passes on one thread; a triangle's record takes
#: 6 ns), as long as the records of some 10,000 triangles.  The same count as the build's
#: MIN_TASK, below which the tree is built on one thread too.
PARALLEL_FROM = 16384


@njit(cache=True, inline="always")
def _box_record(lo, hi, prims, index, p):
    """Write the record of box ``p`` of ``lo``, ``hi`` into ``prims`` (and its int32 view
    ``index``)."""
    for a in range(3):
        prims[p, a] = round_down32(lo[p, a])
        prims[p, 3 + a] = round_up32(hi[p, a])
    index[p, PRIM_INDEX] = p
    index[p, PRIM_INDEX + 1] = 0


@njit(cache=True, parallel=True)
def _records(lo, hi, on_all_cores):
    prims = np.empty((lo.shape[0], PRIM_WIDTH), np.float32)
    index = prims.view(np.int32)
    if on_all_cores:
        for p in prange(lo.shape[0]):
            _box_record(lo, hi, prims, index, p)
    else:  # a loop of range, not prange: no parallel region, no thread woken
        for p in range(lo.shape[0]):
            _box_record(lo, hi, prims, index, p)
    return prims


def records_from_bounds(lo, hi):
    """Primitive records of boxes ``lo``, ``hi`` (float32 or float64, shape (F, 3)), rounded
    outwards to float32: an ndarray of float32, shape (F, PRIM_WIDTH); on all cores from
    PARALLEL_FROM boxes."""
    return _records(lo, hi, len(lo) >= PARALLEL_FROM)


def check_primitive_count(count):
    """Raise ``ValueError`` unless a BVH can hold ``count`` primitives."""
    if count == 0:
        raise ValueError("cannot build a BVH over zero primitives")
    if count > MAX_PRIMITIVES:
        raise ValueError(f"cannot build a BVH over {count} primitives: at most {MAX_PRIMITIVES}")
