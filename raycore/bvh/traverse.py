"""Compiled two-level traversal: closest hit, any hit, and every hit along a ray.

One routine serves every query (``mode``): the top-level BVH over objects (analytic shapes and
mesh instances) and, inside an instance, the mesh's own BVH in object space.  It traces a range of
rays, so that the traversal stacks are allocated once per range.

Arrays are passed as plain arguments, never packed in tuples inside the per-ray code: Numba
reference-counts every array it unpacks, and those atomic updates, contended between threads,
cost more than the traversal itself.

Robustness (DESIGN.md, "Numerics"): a watertight triangle test behind a plain slab test still
leaks, so the box test is conservative (Ize 2013: the far distance is scaled by 1 + 2γ(n)) and
NaN-safe (a 0·inf slab distance, from a ray lying in a face plane, never narrows the interval).
"""

import numpy as np
from numba import njit

from raycore._fp import gamma, like
from raycore.bvh.build import MAX_DEPTH
from raycore.bvh.layout import LEFT_REF
from raycore.primitives.analytic import analytic_hit
from raycore.primitives.triangle import triangle_hit, watertight_setup

CLOSEST, ANY, ALL = 0, 1, 2

#: Object kind of a mesh instance; analytic kinds are the codes of ``raycore.primitives.analytic``.
MESH = 16

#: Convex analytic shapes cross a ray at most twice (enter and leave).
MAX_ANALYTIC_HITS = 2

STACK_SIZE = MAX_DEPTH + 2


@njit(cache=True, inline="always", error_model="numpy")
def _ray_setup(ox, dx, dy, dz):
    """Reciprocal direction for near planes and padded for far planes, and the near-plane
    offsets (0: lo, 3: hi).

    The far distance is padded by 1 + 2γ(5): the γ(3) of Ize's analysis for the reciprocal, the
    subtraction and the product, plus two roundings for folding the pad into the reciprocal.
    """
    ix = like(ox, 1) / dx
    iy = like(ox, 1) / dy
    iz = like(ox, 1) / dz
    pad = like(ox, 1) + like(ox, 2) * gamma(5, ox)
    return (ix, iy, iz, ix * pad, iy * pad, iz * pad,
            0 if ix >= 0 else 3, 0 if iy >= 0 else 3, 0 if iz >= 0 else 3)


@njit(cache=True, inline="always", error_model="numpy")
def _enter(nodes, row, base, ox, oy, oz, ix, iy, iz, fx, fy, fz, nx, ny, nz, tmin, tmax):
    """Entry distance of the ray into child box ``base`` (0 or 6) of node ``row``; inf on a miss.

    Written so that a NaN slab distance (0·inf) leaves the interval unchanged.
    """
    t_near = tmin
    t_far = tmax
    t = (nodes[row, base + nx] - ox) * ix
    if t > t_near:
        t_near = t
    t = (nodes[row, base + 3 - nx] - ox) * fx
    if t < t_far:
        t_far = t
    t = (nodes[row, base + 1 + ny] - oy) * iy
    if t > t_near:
        t_near = t
    t = (nodes[row, base + 4 - ny] - oy) * fy
    if t < t_far:
        t_far = t
    t = (nodes[row, base + 2 + nz] - oz) * iz
    if t > t_near:
        t_near = t
    t = (nodes[row, base + 5 - nz] - oz) * fz
    if t < t_far:
        t_far = t
    if t_near <= t_far:
        return t_near
    return like(ox, np.inf)


@njit(cache=True, inline="always", error_model="numpy")
def _descend(nodes, refs, row, row_base, ox, oy, oz, ix, iy, iz, fx, fy, fz, nx, ny, nz, tmin,
             tmax, stack, stack_t, top):
    """Test both children of ``row``: return the nearer internal child to visit next (-1 if
    none), pushing the farther one, and the children that are leaves, nearest first.

    A leaf's count is returned for an entered leaf only; internal children have count 0, so
    ``(first, count)`` pairs can be looped over directly.

    Returns
    -------
    next_row, top, first0, count0, first1, count1
        Leaf ranges have count 0 where absent.
    """
    t_left = _enter(nodes, row, 0, ox, oy, oz, ix, iy, iz, fx, fy, fz, nx, ny, nz, tmin, tmax)
    t_right = _enter(nodes, row, 6, ox, oy, oz, ix, iy, iz, fx, fy, fz, nx, ny, nz, tmin, tmax)
    # Which child is nearer is a coin toss for the branch predictor: order them with selects
    # and push with a conditional increment instead of branching.
    swap = t_right < t_left
    near_side = LEFT_REF + np.int64(swap)
    far_side = LEFT_REF + 1 - np.int64(swap)
    t_near = t_right if swap else t_left
    t_far = t_left if swap else t_right
    near_ref = refs[row, near_side]
    near_count = refs[row, near_side + 2]
    far_ref = refs[row, far_side]
    far_count = refs[row, far_side + 2]
    # the far child is entered only if the near one is (t_near <= t_far)
    near_hit = t_near != np.inf
    far_hit = t_far != np.inf
    stack[top] = row_base + far_ref
    stack_t[top] = t_far
    top += np.int64(far_hit and far_count == 0)
    next_row = row_base + near_ref if near_hit and near_count == 0 else -1
    return (next_row, top, near_ref, near_count if near_hit else 0, far_ref,
            far_count if far_hit else 0)


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
def _trace_mesh(mode, ox, oy, oz, dx, dy, dz, tmin, tmax, test, nodes, refs, tri_verts, root,
                tri0, stack, stack_t, obj, hits_t, hits_obj, hits_prim, begin, end, found):
    """Traverse one mesh's BVH (rows from ``root``, triangles from ``tri0``) with an
    object-space ray.

    Returns ``(t, prim, u, v, found)``: the closest hit below ``tmax`` (``prim`` is -1 if none;
    in ANY mode the first found) and, in ALL mode, the running hit count.
    """
    ix, iy, iz, fx, fy, fz, nx, ny, nz = _ray_setup(ox, dx, dy, dz)
    kx, ky, kz, sx, sy, sz = watertight_setup(dx, dy, dz)
    best_t = tmax
    best_prim = -1
    best_u = best_v = like(ox, 0)
    top = 0
    row = root
    while row >= 0:
        next_row, top, first0, count0, first1, count1 = _descend(
            nodes, refs, row, root, ox, oy, oz, ix, iy, iz, fx, fy, fz, nx, ny, nz, tmin, best_t,
            stack, stack_t, top)
        for leaf in range(2):
            first = tri0 + (first0 if leaf == 0 else first1)
            for p in range(first, first + (count0 if leaf == 0 else count1)):
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


@njit(cache=True, error_model="numpy")
def trace_rays(mode, start, stop, origins, directions, tmin, tmax, test, sphere_method,
               top_nodes, top_refs, top_order, unbounded,
               kind, param_row, mesh_of, xform_row, params, xforms,
               mesh_nodes, mesh_refs, tri_verts, node_base, tri_base,
               out_t, out_obj, out_prim, out_u, out_v, offsets, hits_t, hits_obj, hits_prim):
    """Trace rays ``start .. stop - 1`` through a scene.

    Parameters
    ----------
    mode : int
        CLOSEST, ANY or ALL.
    origins, directions : ndarray, shape (N, 3); tmin, tmax : ndarray, shape (N,)
        The rays, in the scene's precision.
    test, sphere_method : int
        Triangle test and sphere method codes.
    top_nodes, top_refs, top_order, unbounded
        Top-level BVH over bounded objects, and the unbounded objects (planes) tested first.
    kind, param_row, mesh_of, xform_row, params, xforms
        Per-object kind, analytic parameter row, mesh, inverse-transform row (-1: identity);
        the (P, 20) parameter table and the (T, 12) object-from-world matrices.
    mesh_nodes, mesh_refs, tri_verts, node_base, tri_base
        Every mesh's BVH rows and leaf-order triangles (T, 9), concatenated, with each mesh's
        first row and first triangle.
    out_t, out_obj, out_prim, out_u, out_v : ndarray, shape (N,)
        CLOSEST and ANY: the hit's t (inf on a miss), object (-1 on a miss), primitive (leaf-order
        triangle, or the analytic shape's surface part) and barycentrics.  ALL: ``out_obj``
        receives each ray's hit count.
    offsets, hits_t, hits_obj, hits_prim : ndarray
        ALL mode: ray i's hits go to ``[offsets[i], offsets[i + 1])`` of the hit buffers, which
        may be empty to only count them.
    """
    stack = np.empty(STACK_SIZE, np.int64)
    stack_t = np.empty(STACK_SIZE, origins.dtype)
    mesh_stack = np.empty(STACK_SIZE, np.int64)
    mesh_stack_t = np.empty(STACK_SIZE, origins.dtype)
    has_top = len(top_nodes) > 0
    store = len(hits_t) > 0
    for i in range(start, stop):
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        t_lo = tmin[i]
        ix, iy, iz, fx, fy, fz, nx, ny, nz = _ray_setup(ox, dx, dy, dz)
        begin = offsets[i] if store else 0
        end = offsets[i + 1] if store else 0

        best_t = tmax[i]
        best_obj = -1
        best_prim = -1
        best_u = best_v = like(ox, 0)
        found = 0
        done = False
        # The unbounded objects (planes) live outside the top-level BVH; they are processed
        # first, as a leaf of their own, so that they can shorten the ray before traversal.
        in_top = False
        first0, count0, first1, count1 = 0, len(unbounded), 0, 0
        next_row = 0 if has_top else -1
        top = 0
        while True:
            for leaf in range(2):
                first = first0 if leaf == 0 else first1
                for slot in range(first, first + (count0 if leaf == 0 else count1)):
                    if done:
                        break
                    obj = top_order[slot] if in_top else unbounded[slot]
                    k = kind[obj]
                    if k == MESH:
                        r = xform_row[obj]
                        if r < 0:
                            mox, moy, moz, mdx, mdy, mdz = ox, oy, oz, dx, dy, dz
                        else:
                            mox, moy, moz = _transform(xforms, r, ox, oy, oz, like(ox, 1))
                            mdx, mdy, mdz = _transform(xforms, r, dx, dy, dz, like(ox, 0))
                        m = mesh_of[obj]
                        t, p, u, v, found = _trace_mesh(
                            mode, mox, moy, moz, mdx, mdy, mdz, t_lo, best_t, test, mesh_nodes,
                            mesh_refs, tri_verts, node_base[m], tri_base[m], mesh_stack,
                            mesh_stack_t, obj, hits_t, hits_obj, hits_prim, begin, end, found)
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
            next_row, top, first0, count0, first1, count1 = _descend(
                top_nodes, top_refs, row, 0, ox, oy, oz, ix, iy, iz, fx, fy, fz, nx, ny, nz, t_lo,
                best_t, stack, stack_t, top)
        if mode == ALL:
            out_obj[i] = found
            continue
        out_t[i] = best_t if best_obj >= 0 else like(ox, np.inf)
        out_obj[i] = best_obj
        out_prim[i] = best_prim
        out_u[i] = best_u
        out_v[i] = best_v
