"""Batch ray queries over a packed scene: compiled loops in parallel over rays.

Each loop hands rays to :func:`raycore.bvh.traverse.trace_rays` in chunks, with the scratch
(traversal stacks) of the thread that runs the chunk: nothing is allocated, nor
reference-counted, per ray.
"""

import numpy as np
from numba import get_num_threads, get_thread_id, njit, parallel_chunksize, prange

from raycore._fp import like, unit_roundoff
from raycore.bvh.traverse import ALL, ANY, CLOSEST, MESH, new_scratch, trace_rays
from raycore.primitives.analytic import analytic_surface
from raycore.primitives.triangle import triangle_normal

#: Rays per parallel work item: enough to amortise a call's set-up, few enough to balance cores.
CHUNK = 1024


@njit(cache=True, parallel=True, _nrt=False)
def _trace_parallel(mode, origins, directions, tmin, tmax, test, sphere_method,
                    top_nodes, top_refs, top_order, direct,
                    kind, param_row, mesh_of, xform_row, params, xforms,
                    mesh_nodes, mesh_refs, tri_verts, node_base, tri_base,
                    out_t, out_obj, out_prim, out_u, out_v, offsets, hits_t, hits_obj, hits_prim,
                    int_scratch, real_scratch):
    n = len(origins)
    for chunk in prange((n + CHUNK - 1) // CHUNK):
        thread = get_thread_id()
        trace_rays(mode, chunk * CHUNK, min(n, (chunk + 1) * CHUNK), origins, directions, tmin,
                   tmax, test, sphere_method, top_nodes, top_refs, top_order, direct, kind,
                   param_row, mesh_of, xform_row, params, xforms, mesh_nodes, mesh_refs,
                   tri_verts, node_base, tri_base, out_t, out_obj, out_prim, out_u, out_v,
                   offsets, hits_t, hits_obj, hits_prim, int_scratch[thread],
                   real_scratch[thread])


def _trace(mode, origins, directions, tmin, tmax, test, sphere_method, scene, outputs=None,
           offsets=None, hits=None, barycentrics=False):
    """Run :func:`trace_rays` over all rays in parallel; ``scene`` is the packed tuple of
    arrays of ``Scene``.  Returns ``outputs``, allocated when not given, whose u and v are
    empty unless ``barycentrics``."""
    n = len(origins)
    if outputs is None:
        kept = n if barycentrics else 0
        outputs = (np.empty(n, origins.dtype), np.empty(n, np.int64), np.empty(n, np.int64),
                   np.empty(kept, origins.dtype), np.empty(kept, origins.dtype))
    if hits is None:
        hits = (np.empty(0, origins.dtype), np.empty(0, np.int64), np.empty(0, np.int64))
        offsets = np.zeros(1, np.int64)
    # one chunk of CHUNK rays per scheduling step: rays cost very different amounts (a miss is
    # ten times cheaper than a hit), and static halves would leave one core idle
    with parallel_chunksize(1):
        _trace_parallel(mode, origins, directions, tmin, tmax, test, sphere_method, *scene,
                        *outputs, offsets, *hits, *new_scratch(get_num_threads(), origins.dtype))
    return outputs


def closest_hits(origins, directions, tmin, tmax, test, sphere_method, scene, barycentrics):
    """Closest hit of each ray.

    Returns
    -------
    t : ndarray, shape (N,)
        inf on a miss.
    obj, prim : ndarray of int64, shape (N,)
        Object (geometry id) and leaf-order triangle or analytic surface part; -1 on a miss.
    u, v : ndarray, shape (N,), or (0,) unless ``barycentrics``
        Barycentrics of triangle hits.
    """
    return _trace(CLOSEST, origins, directions, tmin, tmax, test, sphere_method, scene,
                  barycentrics=barycentrics)


def any_hits(origins, directions, tmin, tmax, test, sphere_method, scene):
    """(N,) bool: whether each ray hits anything in [tmin, tmax], stopping at the first hit."""
    return _trace(ANY, origins, directions, tmin, tmax, test, sphere_method, scene)[1] >= 0


@njit(cache=True, inline="always")
def _share_vertex(tri_verts, p, q):
    """Whether leaf-order triangles p and q share a vertex (exactly equal coordinates)."""
    for a in range(3):
        for b in range(3):
            if (tri_verts[p, 3 * a] == tri_verts[q, 3 * b]
                    and tri_verts[p, 3 * a + 1] == tri_verts[q, 3 * b + 1]
                    and tri_verts[p, 3 * a + 2] == tri_verts[q, 3 * b + 2]):
                return True
    return False


@njit(cache=True, parallel=True, error_model="numpy")
def _sort_and_merge(offsets, hits_t, hits_obj, hits_prim, kind, tri_verts, counts):
    """Sort each ray's hits by t and merge crossings of one surface reported twice.

    A ray through a shared edge or vertex hits every triangle around it (that is what makes the
    watertight test watertight); those hits are one crossing.  Two hits merge when they belong to
    the same mesh object, their triangles share a vertex and their distances agree to within
    √u relative (u the unit roundoff).  ``counts`` receives the merged counts; each ray's kept
    hits are moved to the front of its range.
    """
    tol = np.sqrt(unit_roundoff(hits_t[0]))
    for i in prange(len(offsets) - 1):
        start = offsets[i]
        stop = offsets[i + 1]
        # insertion sort: a ray has few hits
        for j in range(start + 1, stop):
            t = hits_t[j]
            obj = hits_obj[j]
            prim = hits_prim[j]
            k = j - 1
            while k >= start and hits_t[k] > t:
                hits_t[k + 1] = hits_t[k]
                hits_obj[k + 1] = hits_obj[k]
                hits_prim[k + 1] = hits_prim[k]
                k -= 1
            hits_t[k + 1] = t
            hits_obj[k + 1] = obj
            hits_prim[k + 1] = prim
        kept = start
        for j in range(start, stop):
            duplicate = False
            if kind[hits_obj[j]] == MESH:
                k = kept - 1
                while k >= start and hits_t[j] - hits_t[k] <= tol * abs(hits_t[j]):
                    if hits_obj[k] == hits_obj[j] and _share_vertex(tri_verts, hits_prim[k],
                                                                    hits_prim[j]):
                        duplicate = True
                        break
                    k -= 1
            if not duplicate:
                hits_t[kept] = hits_t[j]
                hits_obj[kept] = hits_obj[j]
                hits_prim[kept] = hits_prim[j]
                kept += 1
        counts[i] = kept - start


def all_hits(origins, directions, tmin, tmax, test, sphere_method, scene):
    """Every hit of each ray, sorted by t, one per surface crossing.

    Returns
    -------
    counts : ndarray of int64, shape (N,)
    t : ndarray, shape (H,)
    obj, prim : ndarray of int64, shape (H,)
        Hits of ray i are at ``[offsets[i], offsets[i + 1])`` with offsets the cumulative counts;
        ``prim`` as in :func:`closest_hits`.
    """
    n = len(origins)
    # first pass counts, second pass fills exactly-sized buffers
    outputs = _trace(ALL, origins, directions, tmin, tmax, test, sphere_method, scene)
    counts = outputs[1]
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    total = int(offsets[-1])
    hits = (np.empty(total, origins.dtype), np.empty(total, np.int64), np.empty(total, np.int64))
    if total:
        _trace(ALL, origins, directions, tmin, tmax, test, sphere_method, scene, outputs,
               offsets, hits)
        kind = scene[4]
        tri_verts = scene[12]
        _sort_and_merge(offsets, *hits, kind, tri_verts, counts)
    keep = np.repeat(offsets[:-1], counts) + _ranks_within(counts)
    return counts, hits[0][keep], hits[1][keep], hits[2][keep]


@njit(cache=True, parallel=True)
def face_ids(obj, prim, kind, leaf_face):
    """(N,) int64 primitive ids as users see them: the face index for a mesh hit (``prim`` is
    a leaf-order triangle, ``leaf_face`` maps it back), 0 for an analytic shape, -1 for a miss."""
    out = np.empty(len(obj), np.int64)
    for i in prange(len(obj)):
        if obj[i] < 0:
            out[i] = -1
        elif kind[obj[i]] == MESH:
            out[i] = leaf_face[prim[i]]
        else:
            out[i] = 0
    return out


def _ranks_within(counts):
    """(sum(counts),) int64: 0, 1, ..., counts[i] - 1 for each ray in turn."""
    total = int(counts.sum())
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    return np.arange(total, dtype=np.int64) - starts


@njit(cache=True, parallel=True, error_model="numpy")
def surface_fields(origins, directions, t, obj, prim, u, v, kind, param_row, xform_row, params,
                   xforms, tri_verts, want_uv, want_normal, want_point):
    """Surface data of closest hits, computed after traversal and only for the asked fields.

    Returns
    -------
    uv : ndarray, shape (N, 2) or (0, 2)
    normal, point : ndarray, shape (N, 3) or (0, 3)
        NaN rows for misses; empty when not asked for.
    """
    n = len(t)
    nan = like(t[0], np.nan) if n else np.nan
    uv = np.empty((n if want_uv else 0, 2), t.dtype)
    normal = np.empty((n if want_normal else 0, 3), t.dtype)
    point = np.empty((n if want_point else 0, 3), t.dtype)
    for i in prange(n):
        o = origins[i]
        d = directions[i]
        if obj[i] < 0:
            if want_uv:
                uv[i, :] = nan
            if want_normal:
                normal[i, :] = nan
            if want_point:
                point[i, :] = nan
            continue
        if want_point:
            for a in range(3):
                point[i, a] = o[a] + t[i] * d[a]
        k = kind[obj[i]]
        if k == MESH:
            if want_uv:
                uv[i, 0] = u[i]
                uv[i, 1] = v[i]
            if want_normal:
                w = tri_verts[prim[i]]
                nx, ny, nz = triangle_normal(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7],
                                             w[8])
                r = xform_row[obj[i]]
                if r >= 0:
                    # normals transform by the inverse transpose; xforms hold the inverse
                    m = xforms[r]
                    nx, ny, nz = (m[0] * nx + m[4] * ny + m[8] * nz,
                                  m[1] * nx + m[5] * ny + m[9] * nz,
                                  m[2] * nx + m[6] * ny + m[10] * nz)
                    length = np.sqrt(nx * nx + ny * ny + nz * nz)
                    nx, ny, nz = nx / length, ny / length, nz / length
                normal[i, 0] = nx
                normal[i, 1] = ny
                normal[i, 2] = nz
            continue
        nx, ny, nz, su, sv = analytic_surface(k, params[param_row[obj[i]]], o[0], o[1], o[2],
                                              d[0], d[1], d[2], t[i], prim[i])
        if want_uv:
            uv[i, 0] = su
            uv[i, 1] = sv
        if want_normal:
            normal[i, 0] = nx
            normal[i, 1] = ny
            normal[i, 2] = nz
    return uv, normal, point
