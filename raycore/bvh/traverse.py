"""Compiled two-level traversal: closest hit, any hit, crossing counts and every crossing.

One routine serves every query (``mode``): the top-level BVH over objects (analytic shapes and
mesh instances) and, inside a mesh, the mesh's own BVH in object space, whose leaves are blocks
of eight float32 or four float64 triangles tested at once (:mod:`raycore.bvh.leaves`,
:func:`~raycore.bvh.simd.watertight_block`).  :func:`trace_range` traces a range of rays with
the scratch (traversal stacks, hit lists) of the thread that runs it; the caller owns the
scratch (:func:`new_scratch`) and keeps it between calls.

The kernels are compiled without Numba's reference counting (``_nrt=False``): every array they
touch is borrowed from the caller.  With reference counts, each helper's array arguments cost
an atomic update on entry and exit on counters that both threads share: a ray that missed the
mesh took 51 thread-ns instead of 15.  Helpers that loop are ordinary compiled calls, compiled
once; only the small ones are inlined.

Robustness (DESIGN.md, "Numerics"): a watertight triangle test behind a plain slab test still
leaks, so the box test is conservative (Ize 2013: the far distance is scaled by 1 + 2γ(n), and
the ray's bounds widened alike) and NaN-safe (a 0·inf slab distance, from a ray lying in a face
plane, never narrows the interval).  It runs in float32 for rays of either precision, with a
float64 ray's origin rounded outwards (:func:`_box_ray`).
"""

import math

import numpy as np
from numba import njit

from raycore._fp import gamma, like, unit_roundoff
from raycore._memory import LINE, empty_on_line
from raycore.bvh.build import MAX_DEPTH
from raycore.bvh.layout import COUNTS, REFS, WIDTH
from raycore.bvh.leaves import slot_face, slot_value
from raycore.bvh.simd import (
    MAX_LANES,
    block_lanes,
    enter8,
    lowest_set_bit,
    node_int,
    nonnegative,
    prefetch_block,
    prefetch_row,
    watertight_block,
)
from raycore.primitives.analytic import DISK, PLANE, table_hit
from raycore.primitives.triangle import WATERTIGHT, triangle_hit, watertight_setup

CLOSEST, ANY, COUNT, ALL, PARITY, LIST = 0, 1, 2, 3, 4, 5

#: Object kind of a mesh instance; analytic kinds are the codes of ``raycore.primitives.analytic``.
MESH = 16

#: Convex analytic shapes cross a ray at most twice (enter and leave).
MAX_ANALYTIC_HITS = 2

#: A wide node pushes at most WIDTH - 1 children, at most once per level.
STACK_SIZE = (WIDTH - 1) * MAX_DEPTH + 2

#: Crossings one ray may record in its thread's scratch before the query is re-run with more
#: room (COUNT and ALL modes); a ray through a closed mesh rarely crosses it more than a few times.
HIT_CAPACITY = 64

#: Scratch elements per thread besides the hit list: leaf lists and two stacks (integers); entry
#: distances, a leaf block's lanes' t, u, v, and the stacks' distances (reals).
INT_FIXED = 4 * WIDTH + 2 * STACK_SIZE
REAL_FIXED = WIDTH + 3 * MAX_LANES + 2 * STACK_SIZE

#: The least left unused after each thread's row: two threads' scratch never share a cache line
#: (that false sharing made a ray that misses the mesh three times slower), and each row starts
#: on a line, so that vector stores never straddle two.
SCRATCH_GAP = 2 * LINE


@njit(cache=True, inline="always")
def scratch_lengths(capacity):
    """Values in a thread's int and real scratch rows, for hit lists of ``capacity`` crossings:
    (INT_FIXED + 2 * capacity, REAL_FIXED + capacity)."""
    return INT_FIXED + 2 * capacity, REAL_FIXED + capacity


def new_scratch(threads, dtype, capacity=HIT_CAPACITY):
    """Scratch memory for :func:`trace_range`: one row per thread, in the rays' precision.

    Parameters
    ----------
    threads : int
    dtype : numpy float type
    capacity : int
        Crossings a ray may record (COUNT and ALL modes).

    Returns
    -------
    int_scratch : ndarray of int64, shape (threads, >= INT_FIXED + 2 * capacity)
    real_scratch : ndarray of dtype, shape (threads, >= REAL_FIXED + capacity)
        Rows start on cache lines.
    """
    ints, reals = scratch_lengths(capacity)
    return _line_rows(threads, ints, np.int64), _line_rows(threads, reals, dtype)


def _line_rows(threads, count, dtype):
    """Uninitialised (threads, >= count) array whose rows start on cache lines, SCRATCH_GAP
    bytes or more apart."""
    item = np.dtype(dtype).itemsize
    stride = -(-(count * item + SCRATCH_GAP) // LINE) * LINE // item
    return empty_on_line(threads * stride, dtype).reshape(threads, stride)


@njit(cache=True, forceinline=True)
def _wide(x):
    """Whether ``x`` is a float64 (a float64 ray's), which the float32 box test must round; a
    constant where compiled."""
    return unit_roundoff(x) < unit_roundoff(np.float32(0))


@njit(cache=True, forceinline=True)
def _float32_step(x):
    """More than a float32 ulp of ``x``: |x|·2^-23, or 2^-149 below the normal range, in
    ``x``'s precision (|x| capped, so that an infinite ``x`` stays infinite when moved)."""
    return min(abs(x), like(x, 2.0**128)) * like(x, 2.0**-23) + like(x, 2.0**-149)


@njit(cache=True, forceinline=True)
def _rounded32(x, step):
    """A float32 beyond ``x`` on the side of ``step``'s sign, within three float32 ulps of
    it; ``x`` itself for a float32.

    Without a branch or a library call (``np.nextafter`` is one): ``x`` is moved by ``step``
    (:func:`_float32_step`, either sign), then rounded to the nearest float32, which is at
    most half an ulp back; ``x``'s own precision rounds the move by 2^-29 of that margin.
    Chosen by comparing ``x`` with the float32 nearest it instead, the step was compiled as a
    branch, which float64 rays take at random: a ray that missed the mesh took 63 ns, against
    31 for a float32 ray (fandisk, one thread)."""
    if not _wide(x):
        return np.float32(x)
    return np.float32(x + step)


@njit(cache=True, forceinline=True)
def _bounds32(tmin, tmax):
    """The ray's bounds as the float32 box test takes them: widened by 2γ(6) of themselves in
    float32.  The test's near distance may exceed the exact one by a factor 1 + γ(6) (see
    :func:`_box_ray`); Ize's analysis pads the far distance for that, and a bound needs it too:
    a box entered exactly at tmax (a ray that ends on a face) was missed.

    A float64 bound is rounded to the nearest float32, which may be 2^-24 of it on the wrong
    side (or 2^-150 below the normal range, which 2^-149 more covers); with the two roundings
    of the widening, that leaves more than γ(6) of the 2γ(6).  Rounded outwards instead, by a
    comparison with the nearest float32, the bounds cost a branch taken at random, or, without
    the branch, their latency, at every hit that shortens a float64 ray: 12-27 % of a float64
    ray's time (one thread, framed cameras and random rays).
    """
    slack = np.float32(2) * gamma(6, np.float32(0))
    lo = np.float32(tmin)
    hi = np.float32(tmax)
    beyond = np.float32(0)
    if _wide(tmax):
        beyond = np.float32(2**-149)
    return lo - abs(lo) * slack - beyond, hi + abs(hi) * slack + beyond


@njit(cache=True, forceinline=True, error_model="numpy")
def _box_ray(ox, oy, oz, dx, dy, dz):
    """The ray as the float32 box test takes it (:func:`~raycore.bvh.simd.enter8`): per axis, the
    origin for near planes and for far planes, the reciprocal direction, and the reciprocal
    padded for far planes.

    Boxes are float32, and so is the test for rays of either precision: eight float64 lanes cost
    twice what eight float32 ones do.  A float64 origin is rounded outwards, to the float32 on
    the side that moves each slab distance the safe way (near distances down, far ones up), so
    that the rounded origin adds no error.  The far distance is then padded by 1 + 2γ(5) in
    float32: the γ(3) of Ize's analysis for the reciprocal, the subtraction and the product,
    plus two roundings for folding the pad into the reciprocal; a float64 ray's reciprocal is
    rounded once more, to float32, and takes γ(6).

    Returns
    -------
    tuple of 12 float32
        Near-plane origin (x, y, z), far-plane origin, reciprocal, padded reciprocal.
    """
    pad = np.float32(1) + np.float32(2) * gamma(5 + _wide(ox), np.float32(0))
    ix = np.float32(like(ox, 1) / dx)
    iy = np.float32(like(ox, 1) / dy)
    iz = np.float32(like(ox, 1) / dz)
    # forward along an axis (reciprocal >= 0, as enter8 decides): the near plane is the box's
    # low one, whose distance shrinks with the origin rounded up, and the far plane's grows
    # with it rounded down; backward, the other way round.  The reciprocal's sign moves the
    # rounding itself (a reciprocal of -0, which enter8 takes as forward, makes every slab
    # distance of its axis 0 or NaN, wherever the origin is): branches on the sign,
    # mispredicted half the time on random rays, took 15-20 % of a float64 random ray's time
    # (suzanne, one thread).
    sx = math.copysign(_float32_step(ox), ix)
    sy = math.copysign(_float32_step(oy), iy)
    sz = math.copysign(_float32_step(oz), iz)
    nx, ny, nz = _rounded32(ox, sx), _rounded32(oy, sy), _rounded32(oz, sz)
    fx, fy, fz = _rounded32(ox, -sx), _rounded32(oy, -sy), _rounded32(oz, -sz)
    if _wide(ox) and not _finite_box_ray(nx, ny, nz, fx, fy, fz, ix, iy, iz):
        # a float64 ray beyond float32's range (rare, so a branch rather than clamping every
        # ray on the way to its first box test: float64 sphere scenes took 11 % longer so)
        nx, ny, nz = _clamped32(nx), _clamped32(ny), _clamped32(nz)
        fx, fy, fz = _clamped32(fx), _clamped32(fy), _clamped32(fz)
        ix, iy, iz = _nonzero32(ix, dx), _nonzero32(iy, dy), _nonzero32(iz, dz)
    return (nx, ny, nz, fx, fy, fz, ix, iy, iz, ix * pad, iy * pad, iz * pad)


@njit(cache=True, forceinline=True)
def _finite_box_ray(nx, ny, nz, fx, fy, fz, ix, iy, iz):
    """Whether a float32 box ray's origins are finite and its reciprocals non-zero.

    An infinite origin less the infinite planes of a row's unused slots is NaN, and so is a
    reciprocal of 0 times them; a NaN slab distance enters every slot, the unused ones too,
    whose reference is the root: the stack overflowed and the process crashed (a float64 ray
    from 1e39 with a direction of 1e46, or any ray through an instance scaled by 1e-40)."""
    origins = abs(nx) + abs(ny) + abs(nz) + abs(fx) + abs(fy) + abs(fz)
    return (origins < np.float32(np.inf)) & (ix != 0) & (iy != 0) & (iz != 0)


@njit(cache=True, forceinline=True)
def _clamped32(x):
    """``x`` within float32's finite range."""
    largest = np.float32(np.finfo(np.float32).max)
    return min(max(x, -largest), largest)


@njit(cache=True, forceinline=True)
def _nonzero32(reciprocal, d):
    """A float32 reciprocal of ``d`` that underflowed to 0 as float32's least magnitude, of
    ``d``'s sign.  Such rays, beyond float32's range, may miss what they would hit; they no
    longer crash."""
    least = np.float32(math.copysign(2.0**-149, d))
    return reciprocal if reciprocal != 0 else least


@njit(cache=True, inline="always", error_model="numpy")
def _descend(nodes, refs, row, row_base, box, lo, hi, stack, stack_t, top, entry, leaf_first,
             leaf_count, ordered, blocks, block_base):
    """Test the ray (``box``, with float32 bounds ``lo``, ``hi`` from :func:`_bounds32`) against
    the children of wide node ``row``.

    Entered internal children go on the stack, and the last pushed is returned as the next row
    (-1 if none); entered leaves are listed in ``leaf_first`` / ``leaf_count``, and a mesh's
    leaf blocks (rows of ``blocks`` from ``block_base``; ``blocks`` is empty for the top-level
    tree, whose leaves are objects) are prefetched as their leaves are entered.  When
    ``ordered`` (closest hit), the children are sorted so that the nearest is visited first;
    the other queries visit every entered child or stop at any hit, and skip the sort, as
    Embree's occlusion traversal does.

    Returns
    -------
    next_row, top, leaves
    """
    row = nonnegative(row)
    mask = enter8(nodes, row, box, lo, hi, entry)
    leaves = 0
    base = top = nonnegative(top)
    while mask:
        # visit the entered children only, without a branch per slot
        j = lowest_set_bit(mask)
        mask &= mask - 1
        ref = node_int(refs, row, REFS + j)
        count = node_int(refs, row, COUNTS + j)
        if count > 0:
            if len(blocks):  # a mesh's leaf: its blocks load while the others are visited
                lanes = block_lanes(blocks)
                first = block_base + ref
                for block in range(first, first + (count + lanes - 1) // lanes):
                    prefetch_block(blocks, block)
            leaf_first[leaves] = ref
            leaf_count[leaves] = count
            leaves += 1
            continue
        # insertion into this node's run of the stack, farthest first
        t = entry[j]
        k = top
        while ordered and k > base and stack_t[nonnegative(k - 1)] < t:
            stack[nonnegative(k)] = stack[nonnegative(k - 1)]
            stack_t[nonnegative(k)] = stack_t[nonnegative(k - 1)]
            k -= 1
        k = nonnegative(k)
        stack[k] = row_base + ref
        stack_t[k] = t
        prefetch_row(nodes, row_base + ref)  # loaded while the siblings are visited
        top += 1
    if top > base:
        top -= 1
        return stack[top], top, leaves
    return -1, top, leaves


@njit(cache=True, inline="always")
def _pop(stack, stack_t, top, tmax):
    """Pop the next pending node whose entry distance can still beat ``tmax`` (the box test's
    far bound, :func:`_bounds32`: a computed entry distance may exceed the exact one by a
    factor 1 + γ(6)); -1 when done."""
    while top > 0:
        top -= 1
        if stack_t[top] <= tmax:
            return stack[top], top
    return -1, top


@njit(cache=True, inline="always")
def _record(hit_t, hit_obj, hit_prim, found, t, obj, prim):
    """COUNT and ALL modes: store crossing number ``found`` if the list has room, and count it
    either way (a count beyond the list's length asks for a re-run with more room)."""
    if found < len(hit_t):
        hit_t[found] = t
        hit_obj[found] = obj
        hit_prim[found] = prim
    return found + 1


@njit(cache=True, forceinline=True, error_model="numpy", _nrt=False)
def _trace_mesh(scene, mode, test, ox, oy, oz, dx, dy, dz, tmin, tmax, mesh, obj, int_row,
                real_row, hit_t, hit_obj, hit_prim, found):
    """Traverse mesh ``mesh``'s BVH with an object-space ray.

    Returns
    -------
    t, slot, u, v : the closest hit below ``tmax`` (``slot`` -1 if none; in ANY mode the first
        found)
    found : the running count of recorded crossings (COUNT and ALL modes)
    """
    nodes = scene.mesh_nodes
    refs = scene.mesh_refs
    blocks = scene.blocks
    root = scene.node_base[mesh]
    block0 = scene.block_base[mesh]
    leaf_first = int_row[2 * WIDTH:3 * WIDTH]
    leaf_count = int_row[3 * WIDTH:4 * WIDTH]
    stack = int_row[4 * WIDTH + STACK_SIZE:INT_FIXED]
    entry = real_row[:WIDTH]
    lanes = block_lanes(blocks)
    lane_tuv = real_row[WIDTH:WIDTH + 3 * MAX_LANES]  # a block's t, u, v, lane by lane
    stack_t = real_row[WIDTH + 3 * MAX_LANES + STACK_SIZE:REAL_FIXED]
    box = _box_ray(ox, oy, oz, dx, dy, dz)
    # the watertight set-up waits for the first leaf: most rays that miss never reach one
    sheared = False
    kx = ky = kz = 0
    sx = sy = sz = like(ox, 0)
    best_t = tmax
    # the box test's bounds, updated with best_t (rarely), not at every node
    lo, hi = _bounds32(tmin, best_t)
    best_slot = -1
    best_u = best_v = like(ox, 0)
    top = 0
    row = root
    while row >= 0:
        next_row, top, leaves = _descend(nodes, refs, row, root, box, lo, hi, stack, stack_t,
                                         top, entry, leaf_first, leaf_count, mode == CLOSEST,
                                         blocks, block0)
        if leaves and not sheared:
            kx, ky, kz, sx, sy, sz = watertight_setup(dx, dy, dz)
            sheared = True
        for leaf in range(leaves):
            first = block0 + leaf_first[leaf]
            count = leaf_count[leaf]
            for block in range(first, first + (count + lanes - 1) // lanes):
                if test == WATERTIGHT:
                    bits = watertight_block(blocks, block, ox, oy, oz, kx, ky, kz, sx, sy, sz,
                                            tmin, best_t, lane_tuv)
                    exact = bits >> lanes
                    hits = bits & ((1 << lanes) - 1)
                else:
                    # the leaf's triangles in this block, not its padding lanes
                    exact = (1 << min(lanes, count - (block - first) * lanes)) - 1
                    hits = 0
                # lanes the vector test could not settle (or a test without one): scalar tests
                while exact:
                    lane = lowest_set_bit(exact)
                    exact &= exact - 1
                    slot = lanes * block + lane
                    t, u, w = triangle_hit(
                        test, ox, oy, oz, dx, dy, dz, kx, ky, kz, sx, sy, sz, tmin, best_t,
                        slot_value(blocks, slot, 0), slot_value(blocks, slot, 1),
                        slot_value(blocks, slot, 2), slot_value(blocks, slot, 3),
                        slot_value(blocks, slot, 4), slot_value(blocks, slot, 5),
                        slot_value(blocks, slot, 6), slot_value(blocks, slot, 7),
                        slot_value(blocks, slot, 8))
                    if t < np.inf:
                        lane_tuv[lane] = t
                        lane_tuv[lanes + lane] = u
                        lane_tuv[2 * lanes + lane] = w
                        hits |= 1 << lane
                while hits:
                    lane = lowest_set_bit(hits)
                    hits &= hits - 1
                    t = lane_tuv[lane]
                    if mode >= COUNT:
                        found = _record(hit_t, hit_obj, hit_prim, found, t, obj,
                                        lanes * block + lane)
                        continue
                    if t <= best_t:
                        best_t = t
                        lo, hi = _bounds32(tmin, best_t)
                        best_slot = lanes * block + lane
                        best_u = lane_tuv[lanes + lane]
                        best_v = lane_tuv[2 * lanes + lane]
                        if mode == ANY:
                            return best_t, best_slot, best_u, best_v, found
        if next_row >= 0:
            row = next_row
        else:
            row, top = _pop(stack, stack_t, top, hi)
    return best_t, best_slot, best_u, best_v, found


@njit(cache=True, inline="always")
def _transform(m, r, x, y, z, w):
    """Apply row ``r`` of ``m`` (a 3x4 affine matrix, flattened) to (x, y, z, w)."""
    return (
        m[r, 0] * x + m[r, 1] * y + m[r, 2] * z + m[r, 3] * w,
        m[r, 4] * x + m[r, 5] * y + m[r, 6] * z + m[r, 7] * w,
        m[r, 8] * x + m[r, 9] * y + m[r, 10] * z + m[r, 11] * w,
    )


@njit(cache=True, forceinline=True, error_model="numpy", _nrt=False)
def trace_ray(scene, mode, test, sphere_method, ox, oy, oz, dx, dy, dz, tmin, tmax, int_row,
              real_row, hit_t, hit_obj, hit_prim):
    """Trace one ray through the scene.

    Parameters
    ----------
    scene : SceneArrays
    mode : int
        CLOSEST, ANY, COUNT, ALL, PARITY or LIST.
    test, sphere_method : int
        Triangle test and sphere method codes.
    ox, oy, oz, dx, dy, dz, tmin, tmax : float
        The ray, in the scene's precision.
    int_row, real_row : ndarray, shape (>= INT_FIXED,) and (>= REAL_FIXED,)
        The thread's scratch.
    hit_t, hit_obj, hit_prim : ndarray, shape (C,)
        COUNT and ALL: the crossings found, unsorted (mesh crossings by slot, analytic ones by
        surface part), as many as fit.

    Returns
    -------
    t, obj, prim, u, v, found
        CLOSEST and ANY: the hit (``obj`` -1 on a miss; ``prim`` a slot for meshes, the surface
        part for analytic shapes) and its barycentrics.  COUNT and ALL: ``found`` crossings.
    """
    kind = scene.kind
    direct = scene.direct
    top_order = scene.top_order
    top_nodes = scene.top_nodes
    leaf_first = int_row[:WIDTH]
    leaf_count = int_row[WIDTH:2 * WIDTH]
    stack = int_row[4 * WIDTH:4 * WIDTH + STACK_SIZE]
    entry = real_row[:WIDTH]
    stack_t = real_row[WIDTH + 3 * MAX_LANES:WIDTH + 3 * MAX_LANES + STACK_SIZE]
    no_blocks = scene.blocks[:0]  # the top-level tree's leaves are objects, not leaf blocks
    best_t = tmax
    best_obj = -1
    best_prim = -1
    best_u = best_v = like(ox, 0)
    found = np.int64(0)  # not a literal 0, which would compile _trace_mesh once more
    box = _box_ray(ox, oy, oz, dx, dy, dz)
    # The direct objects live outside the top-level BVH; they are processed first, as a leaf of
    # their own, so that they can shorten the ray before traversal.
    in_top = False
    leaf_first[0] = 0
    leaf_count[0] = len(direct)
    leaves = 1
    next_row = 0 if len(top_nodes) > 0 else -1
    top = 0
    while True:
        for leaf in range(leaves):
            first = leaf_first[leaf]
            for slot in range(first, first + leaf_count[leaf]):
                obj = top_order[slot] if in_top else direct[slot]
                k = kind[obj]
                if k == MESH:
                    r = scene.xform_row[obj]
                    mox, moy, moz, mdx, mdy, mdz = ox, oy, oz, dx, dy, dz
                    if r >= 0:
                        mox, moy, moz = _transform(scene.xforms, r, ox, oy, oz, like(ox, 1))
                        mdx, mdy, mdz = _transform(scene.xforms, r, dx, dy, dz, like(ox, 0))
                    t, p, u, v, found = _trace_mesh(
                        scene, mode, test, mox, moy, moz, mdx, mdy, mdz, tmin, best_t,
                        scene.mesh_of[obj], obj, int_row, real_row, hit_t, hit_obj, hit_prim,
                        found)
                    if p >= 0:
                        best_t, best_obj, best_prim, best_u, best_v = t, obj, p, u, v
                        if mode == ANY:
                            return best_t, best_obj, best_prim, best_u, best_v, found
                    continue
                t_from = tmin
                for _ in range(MAX_ANALYTIC_HITS if mode >= COUNT else 1):
                    t, part = table_hit(scene.params, scene.param_row[obj], k, ox, oy, oz, dx,
                                        dy, dz, t_from, best_t, sphere_method)
                    if t == np.inf:
                        break
                    if mode >= COUNT:
                        found = _record(hit_t, hit_obj, hit_prim, found, t, obj, part)
                        # the next root lies strictly beyond this one
                        t_from = np.nextafter(t, like(t, np.inf))
                        continue
                    best_t, best_obj, best_prim = t, obj, part
                    best_u = best_v = like(ox, 0)
                    if mode == ANY:
                        return best_t, best_obj, best_prim, best_u, best_v, found
        in_top = True
        lo, hi = _bounds32(tmin, best_t)
        if next_row >= 0:
            row = next_row
        else:
            row, top = _pop(stack, stack_t, top, hi)
            if row < 0:
                break
        next_row, top, leaves = _descend(top_nodes, scene.top_refs, row, 0, box, lo, hi, stack,
                                         stack_t, top, entry, leaf_first, leaf_count,
                                         mode == CLOSEST, no_blocks, np.int64(0))
    return best_t, best_obj, best_prim, best_u, best_v, found


@njit(cache=True, inline="always")
def _share_vertex(blocks, p, q):
    """Whether the triangles in slots p and q share a vertex (exactly equal coordinates)."""
    for a in range(3):
        for b in range(3):
            if (slot_value(blocks, p, 3 * a) == slot_value(blocks, q, 3 * b)
                    and slot_value(blocks, p, 3 * a + 1) == slot_value(blocks, q, 3 * b + 1)
                    and slot_value(blocks, p, 3 * a + 2) == slot_value(blocks, q, 3 * b + 2)):
                return True
    return False


@njit(cache=True, forceinline=True, error_model="numpy", _nrt=False)
def merge_crossings(scene, hit_t, hit_obj, hit_prim, count):
    """Sort one ray's ``count`` crossings by t and merge those of one surface reported twice.

    A ray through a shared edge or vertex hits every triangle around it (that is what makes the
    watertight test watertight); those hits are one crossing.  Two hits merge when they belong
    to the same mesh object, their triangles share a vertex and their distances agree to within
    √u relative (u the unit roundoff).  The kept crossings are moved to the front.

    Returns
    -------
    int
        Crossings kept.
    """
    if count == 0:
        return 0
    tol = np.sqrt(unit_roundoff(hit_t[0]))
    # insertion sort: a ray has few crossings
    for j in range(1, count):
        t = hit_t[j]
        obj = hit_obj[j]
        prim = hit_prim[j]
        k = j - 1
        while k >= 0 and hit_t[k] > t:
            hit_t[k + 1] = hit_t[k]
            hit_obj[k + 1] = hit_obj[k]
            hit_prim[k + 1] = hit_prim[k]
            k -= 1
        hit_t[k + 1] = t
        hit_obj[k + 1] = obj
        hit_prim[k + 1] = prim
    kept = 0
    for j in range(count):
        duplicate = False
        if scene.kind[hit_obj[j]] == MESH:
            k = kept - 1
            while k >= 0 and hit_t[j] - hit_t[k] <= tol * abs(hit_t[j]):
                if hit_obj[k] == hit_obj[j] and _share_vertex(scene.blocks, hit_prim[k],
                                                              hit_prim[j]):
                    duplicate = True
                    break
                k -= 1
        if not duplicate:
            hit_t[kept] = hit_t[j]
            hit_obj[kept] = hit_obj[j]
            hit_prim[kept] = hit_prim[j]
            kept += 1
    return kept


@njit(cache=True, inline="always")
def _odd_crossings(scene, hit_obj, count):
    """PARITY: whether the ray crosses some closed object (any but planes and disks) an odd
    number of times, among its ``count`` merged crossings."""
    for j in range(count):
        obj = hit_obj[j]
        if scene.kind[obj] == PLANE or scene.kind[obj] == DISK:
            continue
        crossings = 0
        for k in range(count):
            crossings += hit_obj[k] == obj
        if crossings % 2 == 1:
            return True
    return False


@njit(cache=True, inline="always")
def _face_id(scene, obj, prim):
    """The primitive id users see: the face index for a mesh hit (``prim`` is a slot), the
    surface part's row 0 for an analytic shape."""
    if scene.kind[obj] == MESH:
        return slot_face(scene.blocks, prim)
    return np.int64(0)


@njit(cache=True, inline="always")
def _plus_zero(t):
    """``t``, with -0 made +0: a ray that starts on a surface and heads into it hits it at
    t = -0 (a plane's or a triangle's distance is a zero numerator over a signed denominator),
    which is the right distance, but printed or sent as JSON it reads as a negative one.  An
    added +0 changes no other value."""
    return t + like(t, 0)


@njit(cache=True, forceinline=True, _nrt=False)
def _list(scene, hit_t, hit_obj, hit_prim, kept, hits_t, hits_obj, hits_prim, at):
    """ALL and LIST modes: copy a ray's ``kept`` merged crossings to the hit buffers from
    ``at`` on, with face ids for mesh hits."""
    for j in range(kept):
        hits_t[at + j] = _plus_zero(hit_t[j])
        hits_obj[at + j] = hit_obj[j]
        hits_prim[at + j] = _face_id(scene, hit_obj[j], hit_prim[j])


@njit(cache=True, inline="always")
def _bad_ray(origins, directions, i, lo, hi):
    """Whether ray ``i``, with bounds ``lo``, ``hi``, is one the library refuses: a non-finite
    coordinate, a zero direction, or a NaN bound (the caller finds out which and says so)."""
    fine = True
    nonzero = False
    for a in range(3):
        fine &= np.isfinite(origins[i, a]) and np.isfinite(directions[i, a])
        nonzero |= directions[i, a] != 0
    return not (fine and nonzero and lo == lo and hi == hi)


@njit(cache=True, error_model="numpy", _nrt=False)
def trace_range(scene, mode, test, sphere_method, origins, directions, tmin, tmax, start, stop,
                out_t, out_obj, out_prim, out_hit, out_u, out_v, out_slot, offsets, hits_t,
                hits_obj, hits_prim, int_row, real_row, capacity):
    """Trace rays ``start .. stop - 1``, checking each first.

    Parameters
    ----------
    scene : SceneArrays
    mode, test, sphere_method : int
    origins, directions : ndarray, shape (N, 3)
    tmin, tmax : ndarray, shape (N,) or (1,)
        Per-ray bounds, or one for every ray (each on its own).
    start, stop : int
    out_t, out_obj, out_prim : ndarray, shape (N,) or (0,)
        CLOSEST: t (inf on a miss), object (-1 on a miss) and primitive id (face index, or 0 for
        an analytic shape; -1 on a miss).  COUNT, ALL, PARITY and LIST: ``out_obj`` receives
        each ray's crossing count, or minus the crossings found when the hit list was too short.
    out_hit : ndarray of bool, shape (N,) or (0,)
        ANY: whether the ray hits something.  PARITY: whether it crosses a closed object an
        odd number of times.
    out_u, out_v, out_slot : ndarray, shape (N,) or (0,)
        CLOSEST, when not empty: barycentrics and the slot of mesh hits (surface fields).
    offsets, hits_t, hits_obj, hits_prim : ndarray
        ALL: ray i's crossings go to ``[offsets[i], offsets[i + 1])`` of the hit buffers.
        LIST: the hit buffers hold K = len(hits_t) // N crossings a ray, and rays ``start ..
        stop - 1`` list theirs one after another in ``[K * start, K * stop)``; ``offsets[i]``
        ((N,)) receives where ray i's begin, or -1 when they did not fit (nor are listed).
    int_row, real_row : ndarray
        The thread's scratch row (:func:`new_scratch`).
    capacity : int
        Length of the hit list in the scratch row.

    Returns
    -------
    int
        The first refused ray, or N if none (refused rays are not traced).
    """
    lone = _lone_mesh(scene)
    # two copies of the loop, each compiled for its kind of scene: the check made once, not per
    # ray, and the lone mesh's loop free of the code of every other scene
    if lone >= 0:
        return _trace_each(scene, mode, test, sphere_method, origins, directions, tmin, tmax,
                           start, stop, out_t, out_obj, out_prim, out_hit, out_u, out_v,
                           out_slot, offsets, hits_t, hits_obj, hits_prim, int_row, real_row,
                           capacity, lone, True)
    return _trace_each(scene, mode, test, sphere_method, origins, directions, tmin, tmax, start,
                       stop, out_t, out_obj, out_prim, out_hit, out_u, out_v, out_slot, offsets,
                       hits_t, hits_obj, hits_prim, int_row, real_row, capacity, lone, False)


@njit(inline="always")
def _lone_mesh(scene):
    """The object of a scene that is one untransformed mesh (the common case), whose rays go
    straight into the mesh's BVH; -1 for any other scene.  The loop over objects costs 13-15 %
    on camera rays, most of which miss (bunny)."""
    direct = scene.direct
    if len(scene.top_nodes) == 0 and len(direct) == 1 and scene.kind[direct[0]] == MESH and \
            scene.xform_row[direct[0]] < 0:
        return direct[0]
    return np.int64(-1)


@njit(forceinline=True, error_model="numpy", _nrt=False)
def _trace_each(scene, mode, test, sphere_method, origins, directions, tmin, tmax, start, stop,
                out_t, out_obj, out_prim, out_hit, out_u, out_v, out_slot, offsets, hits_t,
                hits_obj, hits_prim, int_row, real_row, capacity, lone, straight):
    """:func:`trace_range`'s loop; ``straight`` (a constant where it is inlined): every ray goes
    straight into the BVH of ``lone``, the scene's one mesh (:func:`_lone_mesh`)."""
    n = len(origins)
    lo_step = 1 if len(tmin) == n else 0
    hi_step = 1 if len(tmax) == n else 0
    hit_obj = int_row[INT_FIXED:INT_FIXED + capacity]
    hit_prim = int_row[INT_FIXED + capacity:INT_FIXED + 2 * capacity]
    hit_t = real_row[REAL_FIXED:REAL_FIXED + capacity]
    barycentrics = len(out_u) > 0
    room = len(hits_t) // n if mode == LIST else 0
    listed, end = room * start, room * stop
    first_bad = n
    for i in range(start, stop):
        lo = tmin[i * lo_step]
        hi = tmax[i * hi_step]
        if _bad_ray(origins, directions, i, lo, hi):
            first_bad = min(first_bad, i)
            continue
        if straight:
            t, prim, u, v, found = _trace_mesh(
                scene, mode, test, origins[i, 0], origins[i, 1], origins[i, 2], directions[i, 0],
                directions[i, 1], directions[i, 2], lo, hi, scene.mesh_of[lone], lone, int_row,
                real_row, hit_t, hit_obj, hit_prim, np.int64(0))
            obj = lone if prim >= 0 else -1
        else:
            t, obj, prim, u, v, found = trace_ray(
                scene, mode, test, sphere_method, origins[i, 0], origins[i, 1], origins[i, 2],
                directions[i, 0], directions[i, 1], directions[i, 2], lo, hi, int_row, real_row,
                hit_t, hit_obj, hit_prim)
        if mode == ANY:
            out_hit[i] = obj >= 0
        elif mode == CLOSEST:
            out_t[i] = _plus_zero(t) if obj >= 0 else like(t, np.inf)
            out_obj[i] = obj
            out_prim[i] = _face_id(scene, obj, prim) if obj >= 0 else -1
            if barycentrics:
                out_u[i] = u
                out_v[i] = v
                out_slot[i] = prim
        elif found > capacity:
            out_obj[i] = -found
        else:
            kept = merge_crossings(scene, hit_t, hit_obj, hit_prim, found)
            out_obj[i] = kept
            if mode == ALL:
                _list(scene, hit_t, hit_obj, hit_prim, kept, hits_t, hits_obj, hits_prim,
                      offsets[i])
            elif mode == LIST:
                fits = listed + kept <= end
                offsets[i] = listed if fits else -1
                if fits:
                    _list(scene, hit_t, hit_obj, hit_prim, kept, hits_t, hits_obj, hits_prim,
                          listed)
                    listed += kept
            elif mode == PARITY:
                out_hit[i] = _odd_crossings(scene, hit_obj, kept)
    return first_bad
