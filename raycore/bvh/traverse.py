"""Compiled two-level traversal: closest hit, any hit, and every hit along a ray.

One routine serves every query (``mode``): the top-level BVH over objects (analytic shapes and
mesh instances) and, inside an instance, the mesh's own BVH in object space.  It traces a range of
rays with the scratch (traversal stacks) of the thread that runs it, allocated once per batch.

``trace_rays`` is compiled without Numba's reference counting (``_nrt=False``): every array it
touches is borrowed from its caller, which also allocates its scratch (:func:`new_scratch`).
With reference counts, each inlined helper's array arguments cost an atomic update on entry and
exit, about 22 per ray, on counters that both threads share: a ray that missed the mesh took 51
thread-ns instead of 15, and a camera batch 20 % longer.  The helpers that take arrays are
inlined by Numba (``inline="always"``), those that take scalars only by LLVM (``forceinline``),
which compiles them once.

Robustness (DESIGN.md, "Numerics"): a watertight triangle test behind a plain slab test still
leaks, so the box test is conservative (Ize 2013: the far distance is scaled by 1 + 2γ(n)) and
NaN-safe (a 0·inf slab distance, from a ray lying in a face plane, never narrows the interval).
"""

import numpy as np
from numba import njit

from raycore._fp import gamma, like
from raycore.bvh.build import MAX_DEPTH
from raycore.bvh.layout import COUNTS, REFS, WIDTH
from raycore.bvh.simd import enter8, lowest_set_bit
from raycore.primitives.analytic import analytic_hit
from raycore.primitives.triangle import triangle_hit, watertight_setup

CLOSEST, ANY, ALL = 0, 1, 2

#: Object kind of a mesh instance; analytic kinds are the codes of ``raycore.primitives.analytic``.
MESH = 16

#: Convex analytic shapes cross a ray at most twice (enter and leave).
MAX_ANALYTIC_HITS = 2

#: A wide node pushes at most WIDTH - 1 children, at most once per level.
STACK_SIZE = (WIDTH - 1) * MAX_DEPTH + 2


@njit(cache=True, forceinline=True, error_model="numpy")
def _ray_setup(ox, dx, dy, dz):
    """Reciprocal direction for near planes, and padded for far planes.

    The far distance is padded by 1 + 2γ(5): the γ(3) of Ize's analysis for the reciprocal, the
    subtraction and the product, plus two roundings for folding the pad into the reciprocal.
    """
    ix = like(ox, 1) / dx
    iy = like(ox, 1) / dy
    iz = like(ox, 1) / dz
    pad = like(ox, 1) + like(ox, 2) * gamma(5, ox)
    return ix, iy, iz, ix * pad, iy * pad, iz * pad


@njit(cache=True, inline="always", error_model="numpy")
def _descend(nodes, refs, row, row_base, ox, oy, oz, ix, iy, iz, fx, fy, fz, tmin, tmax, stack,
             stack_t, top, entry, leaf_first, leaf_count):
    """Test the ray against the children of wide node ``row``.

    Entered internal children go on the stack sorted so that the nearest is popped first, and
    the nearest of them is returned as the next row (-1 if none); entered leaves are listed in
    ``leaf_first`` / ``leaf_count``.

    Returns
    -------
    next_row, top, leaves
    """
    mask = enter8(nodes, row, ox, oy, oz, ix, iy, iz, fx, fy, fz, tmin, tmax, entry)
    leaves = 0
    base = top
    while mask:
        # visit the entered children only, without a branch per slot
        j = lowest_set_bit(mask)
        mask &= mask - 1
        ref = refs[row, REFS + j]
        count = refs[row, COUNTS + j]
        if count > 0:
            leaf_first[leaves] = ref
            leaf_count[leaves] = count
            leaves += 1
            continue
        # insertion into this node's run of the stack, farthest first
        t = entry[j]
        k = top
        while k > base and stack_t[k - 1] < t:
            stack[k] = stack[k - 1]
            stack_t[k] = stack_t[k - 1]
            k -= 1
        stack[k] = row_base + ref
        stack_t[k] = t
        top += 1
    if top > base:
        top -= 1
        return stack[top], top, leaves
    return -1, top, leaves


@njit(cache=True, inline="always")
def _pop(stack, stack_t, top, tmax):
    """Pop the next pending node whose entry distance can still beat ``tmax``; -1 when done."""
    while top > 0:
        top -= 1
        if stack_t[top] <= tmax:
            return stack[top], top
    return -1, top


@njit(cache=True, inline="always")
def _record(hits_t, hits_obj, hits_prim, begin, end, found, t, obj, prim):
    """ALL mode: store the ray's hit number ``found`` at ``begin + found`` if that is before
    ``end``, and count it either way."""
    if begin + found < end:
        hits_t[begin + found] = t
        hits_obj[begin + found] = obj
        hits_prim[begin + found] = prim
    return found + 1


@njit(cache=True, inline="always", error_model="numpy")
def _trace_mesh(mode, test, ray, slabs, tmin, tmax, nodes, refs, tri_verts, root, tri0, stack,
                stack_t, entry, leaf_first, leaf_count, obj, hits_t, hits_obj, hits_prim, begin,
                end, found):
    """Traverse one mesh's BVH (rows from ``root``, triangles from ``tri0``) with an
    object-space ray ``(ox, oy, oz, dx, dy, dz)`` and its ``_ray_setup`` values ``slabs``;
    ``entry``, ``leaf_first``, ``leaf_count`` are (WIDTH,) scratch arrays.

    Returns ``(t, prim, u, v, found)``: the closest hit below ``tmax`` (``prim`` is -1 if none;
    in ANY mode the first found) and, in ALL mode, the running hit count.
    """
    ox, oy, oz, dx, dy, dz = ray
    ix, iy, iz, fx, fy, fz = slabs
    # the watertight set-up waits for the first leaf: most rays that miss never reach one
    sheared = False
    kx = ky = kz = 0
    sx = sy = sz = like(ox, 0)
    best_t = tmax
    best_prim = -1
    best_u = best_v = like(ox, 0)
    top = 0
    row = root
    while row >= 0:
        next_row, top, leaves = _descend(nodes, refs, row, root, ox, oy, oz, ix, iy, iz, fx, fy,
                                         fz, tmin, best_t, stack, stack_t, top, entry,
                                         leaf_first, leaf_count)
        if leaves and not sheared:
            kx, ky, kz, sx, sy, sz = watertight_setup(dx, dy, dz)
            sheared = True
        for leaf in range(leaves):
            first = tri0 + leaf_first[leaf]
            for p in range(first, first + leaf_count[leaf]):
                t, u, w = triangle_hit(test, ox, oy, oz, dx, dy, dz, kx, ky, kz, sx, sy, sz,
                                       tmin, best_t, tri_verts[p, 0], tri_verts[p, 1],
                                       tri_verts[p, 2], tri_verts[p, 3], tri_verts[p, 4],
                                       tri_verts[p, 5], tri_verts[p, 6], tri_verts[p, 7],
                                       tri_verts[p, 8])
                if t == np.inf:
                    continue
                if mode == ALL:
                    found = _record(hits_t, hits_obj, hits_prim, begin, end, found, t, obj, p)
                    continue
                best_t, best_prim, best_u, best_v = t, p, u, w
                if mode == ANY:
                    return best_t, best_prim, best_u, best_v, found
        if next_row >= 0:
            row = next_row
        else:
            row, top = _pop(stack, stack_t, top, best_t)
    return best_t, best_prim, best_u, best_v, found


@njit(cache=True, inline="always")
def _transform(m, r, x, y, z, w):
    """Apply row ``r`` of ``m`` (a 3x4 affine matrix, flattened) to (x, y, z, w)."""
    return (
        m[r, 0] * x + m[r, 1] * y + m[r, 2] * z + m[r, 3] * w,
        m[r, 4] * x + m[r, 5] * y + m[r, 6] * z + m[r, 7] * w,
        m[r, 8] * x + m[r, 9] * y + m[r, 10] * z + m[r, 11] * w,
    )


#: Elements of each thread's scratch row: the leaf lists and two stacks (integers), or the entry
#: distances and the stacks' distances (reals).
INT_SCRATCH = 4 * WIDTH + 2 * STACK_SIZE
REAL_SCRATCH = WIDTH + 2 * STACK_SIZE

#: Bytes of a cache line, and the least left unused after each thread's row: two threads' scratch
#: never share a line (that false sharing made a ray that misses the mesh three times slower),
#: and each row starts on a line, so that the vector store of entry distances never straddles two.
LINE = 64
SCRATCH_GAP = 2 * LINE


def new_scratch(threads, dtype):
    """Scratch memory for :func:`trace_rays`: one row per thread, in the rays' precision.

    Returns
    -------
    int_scratch : ndarray of int64, shape (threads, >= INT_SCRATCH)
    real_scratch : ndarray of dtype, shape (threads, >= REAL_SCRATCH)
        Rows start on cache lines.
    """
    return _line_rows(threads, INT_SCRATCH, np.int64), _line_rows(threads, REAL_SCRATCH, dtype)


def _line_rows(threads, count, dtype):
    """Uninitialised (threads, >= count) array whose rows start on cache lines, SCRATCH_GAP
    bytes or more apart."""
    item = np.dtype(dtype).itemsize
    stride = -(-(count * item + SCRATCH_GAP) // LINE) * LINE // item
    memory = np.empty(threads * stride + LINE // item, dtype)
    start = -memory.ctypes.data % LINE // item
    return memory[start:start + threads * stride].reshape(threads, stride)


@njit(cache=True, error_model="numpy", _nrt=False)
def trace_rays(mode, start, stop, origins, directions, tmin, tmax, test, sphere_method,
               top_nodes, top_refs, top_order, direct,
               kind, param_row, mesh_of, xform_row, params, xforms,
               mesh_nodes, mesh_refs, tri_verts, node_base, tri_base,
               out_t, out_obj, out_prim, out_u, out_v, offsets, hits_t, hits_obj, hits_prim,
               int_scratch, real_scratch):
    """Trace rays ``start .. stop - 1`` through a scene.

    Parameters
    ----------
    mode : int
        CLOSEST, ANY or ALL.
    origins, directions : ndarray, shape (N, 3); tmin, tmax : ndarray, shape (N,)
        The rays, in the scene's precision.
    test, sphere_method : int
        Triangle test and sphere method codes.
    top_nodes, top_refs, top_order, direct
        Top-level BVH over bounded objects, and the objects tested directly, before it: the
        unbounded ones (planes), and the only bounded one when there is just one.
    kind, param_row, mesh_of, xform_row, params, xforms
        Per-object kind, analytic parameter row, mesh, inverse-transform row (-1: identity);
        the (P, 20) parameter table and the (T, 12) object-from-world matrices.
    mesh_nodes, mesh_refs, tri_verts, node_base, tri_base
        Every mesh's BVH rows and leaf-order triangles (T, 9), concatenated, with each mesh's
        first row and first triangle.
    out_t, out_obj, out_prim, out_u, out_v : ndarray, shape (N,)
        CLOSEST and ANY: the hit's t (inf on a miss), object (-1 on a miss), primitive (leaf-order
        triangle, or the analytic shape's surface part) and barycentrics (skipped when ``out_u``
        is empty).  ALL: ``out_obj`` receives each ray's hit count.
    offsets, hits_t, hits_obj, hits_prim : ndarray
        ALL mode: ray i's hits go to ``[offsets[i], offsets[i + 1])`` of the hit buffers, which
        may be empty to only count them.
    int_scratch, real_scratch : ndarray, shape (>= INT_SCRATCH,) and (>= REAL_SCRATCH,)
        Scratch: a row of each of :func:`new_scratch`'s arrays.
    """
    leaf_first = int_scratch[:WIDTH]
    leaf_count = int_scratch[WIDTH:2 * WIDTH]
    mesh_leaf_first = int_scratch[2 * WIDTH:3 * WIDTH]
    mesh_leaf_count = int_scratch[3 * WIDTH:4 * WIDTH]
    stack = int_scratch[4 * WIDTH:4 * WIDTH + STACK_SIZE]
    mesh_stack = int_scratch[4 * WIDTH + STACK_SIZE:INT_SCRATCH]
    entry = real_scratch[:WIDTH]
    stack_t = real_scratch[WIDTH:WIDTH + STACK_SIZE]
    mesh_stack_t = real_scratch[WIDTH + STACK_SIZE:REAL_SCRATCH]
    has_top = len(top_nodes) > 0
    store = len(hits_t) > 0
    barycentrics = len(out_u) > 0
    # A scene of one untransformed mesh, the common case, goes straight into the mesh's BVH:
    # the general loop over objects costs about 15 % on coherent rays.
    lone_mesh = (not has_top and len(direct) == 1 and kind[direct[0]] == MESH
                 and xform_row[direct[0]] < 0)
    lone_obj = direct[0] if lone_mesh else -1
    lone_root = node_base[mesh_of[lone_obj]] if lone_mesh else 0
    lone_tri0 = tri_base[mesh_of[lone_obj]] if lone_mesh else 0
    for i in range(start, stop):
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        t_lo = tmin[i]
        slabs = _ray_setup(ox, dx, dy, dz)
        ix, iy, iz, fx, fy, fz = slabs
        begin = offsets[i] if store else 0
        end = offsets[i + 1] if store else 0

        best_t = tmax[i]
        best_obj = -1
        best_prim = -1
        best_u = best_v = like(ox, 0)
        found = 0
        done = False
        if lone_mesh:
            t, p, u, v, found = _trace_mesh(
                mode, test, (ox, oy, oz, dx, dy, dz), slabs, t_lo, best_t, mesh_nodes, mesh_refs,
                tri_verts, lone_root, lone_tri0, mesh_stack, mesh_stack_t, entry,
                mesh_leaf_first, mesh_leaf_count, lone_obj, hits_t, hits_obj, hits_prim, begin,
                end, found)
            if p >= 0:
                best_t, best_obj, best_prim, best_u, best_v = t, lone_obj, p, u, v
        else:
            # The direct objects live outside the top-level BVH; they are processed first, as a
            # leaf of their own, so that they can shorten the ray before traversal.
            in_top = False
            leaf_first[0] = 0
            leaf_count[0] = len(direct)
            leaves = 1
            next_row = 0 if has_top else -1
            top = 0
            while True:
                for leaf in range(leaves):
                    first = leaf_first[leaf]
                    for slot in range(first, first + leaf_count[leaf]):
                        if done:
                            break
                        obj = top_order[slot] if in_top else direct[slot]
                        k = kind[obj]
                        if k == MESH:
                            r = xform_row[obj]
                            if r < 0:
                                mesh_ray = (ox, oy, oz, dx, dy, dz)
                                mesh_slabs = slabs
                            else:
                                mox, moy, moz = _transform(xforms, r, ox, oy, oz, like(ox, 1))
                                mdx, mdy, mdz = _transform(xforms, r, dx, dy, dz, like(ox, 0))
                                mesh_ray = (mox, moy, moz, mdx, mdy, mdz)
                                mesh_slabs = _ray_setup(mox, mdx, mdy, mdz)
                            m = mesh_of[obj]
                            t, p, u, v, found = _trace_mesh(
                                mode, test, mesh_ray, mesh_slabs, t_lo, best_t, mesh_nodes,
                                mesh_refs, tri_verts, node_base[m], tri_base[m], mesh_stack,
                                mesh_stack_t, entry, mesh_leaf_first, mesh_leaf_count, obj, hits_t,
                                hits_obj, hits_prim, begin, end, found)
                            if p >= 0:
                                best_t, best_obj, best_prim, best_u, best_v = t, obj, p, u, v
                                done = mode == ANY
                            continue
                        t_from = t_lo
                        for _ in range(MAX_ANALYTIC_HITS if mode == ALL else 1):
                            t, part = analytic_hit(k, params[param_row[obj]], ox, oy, oz, dx, dy,
                                                   dz, t_from, best_t, sphere_method)
                            if t == np.inf:
                                break
                            if mode == ALL:
                                found = _record(hits_t, hits_obj, hits_prim, begin, end, found, t,
                                                obj, part)
                                # the next root lies strictly beyond this one
                                t_from = np.nextafter(t, like(t, np.inf))
                                continue
                            best_t, best_obj, best_prim = t, obj, part
                            best_u = best_v = like(ox, 0)
                            done = mode == ANY
                if done:
                    break
                in_top = True
                if next_row >= 0:
                    row = next_row
                else:
                    row, top = _pop(stack, stack_t, top, best_t)
                    if row < 0:
                        break
                next_row, top, leaves = _descend(top_nodes, top_refs, row, 0, ox, oy, oz, ix, iy,
                                                 iz, fx, fy, fz, t_lo, best_t, stack, stack_t,
                                                 top, entry, leaf_first, leaf_count)
        if mode == ALL:
            out_obj[i] = found
            continue
        out_t[i] = best_t if best_obj >= 0 else like(ox, np.inf)
        out_obj[i] = best_obj
        out_prim[i] = best_prim
        if barycentrics:
            out_u[i] = best_u
            out_v[i] = best_v
