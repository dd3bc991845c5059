"""Shading normals: mesh vertex normals interpolated with the hits' barycentrics.

A mesh's vertex normals are the area-weighted mean of the geometric normals of the faces around
each vertex (the sum of their unnormalised cross products), so that they point the way the
faces' own normals do.  Analytic shapes are smooth already: their shading normal is their
geometric normal.
"""

import numpy as np
from numba import njit, prange

from raycore._memory import empty_aligned
from raycore.bvh.traverse import MESH


@njit(cache=True)
def vertex_normals(vertices, faces):
    """Unit area-weighted vertex normals.

    Parameters
    ----------
    vertices : ndarray of float64, shape (V, 3)
    faces : ndarray of int64, shape (F, 3)
        Counter-clockwise seen from the side the normals point to.

    Returns
    -------
    ndarray of float64, shape (V, 3)
        Zero rows for vertices that no face of non-zero area uses.
    """
    normals = np.zeros((len(vertices), 3))
    # serial: faces scatter into shared vertices
    for f in range(len(faces)):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        e1 = vertices[b] - vertices[a]
        e2 = vertices[c] - vertices[a]
        n = np.cross(e1, e2)
        for corner in (a, b, c):
            normals[corner] += n
    for i in range(len(normals)):
        length = np.sqrt(normals[i, 0] ** 2 + normals[i, 1] ** 2 + normals[i, 2] ** 2)
        if length > 0:
            normals[i] /= length
    return normals


@njit(cache=True, parallel=True, _nrt=False)
def _interpolate(geom_id, prim_id, u, v, normal, kind, mesh_of, xform_row, xforms, face_base,
                 faces, normals, out):
    for i in prange(len(geom_id)):
        g = geom_id[i]
        if g < 0 or kind[g] != MESH:
            for k in range(3):
                out[i, k] = normal[i, k]
            continue
        f = face_base[mesh_of[g]] + prim_id[i]
        wb, wc = u[i], v[i]
        wa = 1.0 - wb - wc
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        nx = wa * normals[a, 0] + wb * normals[b, 0] + wc * normals[c, 0]
        ny = wa * normals[a, 1] + wb * normals[b, 1] + wc * normals[c, 1]
        nz = wa * normals[a, 2] + wb * normals[b, 2] + wc * normals[c, 2]
        r = xform_row[g]
        if r >= 0:
            # normals transform by the inverse transpose; xforms hold the inverse (3x4 rows)
            m = xforms[r]
            nx, ny, nz = (m[0] * nx + m[4] * ny + m[8] * nz,
                          m[1] * nx + m[5] * ny + m[9] * nz,
                          m[2] * nx + m[6] * ny + m[10] * nz)
        length = np.sqrt(nx * nx + ny * ny + nz * nz)
        if not length > 0:  # opposite vertex normals cancel: the face's own normal
            for k in range(3):
                out[i, k] = normal[i, k]
            continue
        out[i, 0] = nx / length
        out[i, 1] = ny / length
        out[i, 2] = nz / length


class NormalTables:
    """What :func:`shading_normals` reads of a scene: every mesh's faces and vertex normals end
    to end, and the per-object tables; made once per built scene.

    Parameters
    ----------
    meshes : list of raycore.mesh.Mesh
    kind, mesh_of, xform_row : sequence of int, length G
        Each object's kind, mesh index and instance transform row (-1 for none).
    xforms : sequence of array_like, shape (3, 4)
        Object-from-world matrices of instances.
    dtype : numpy float type
        The scene's: the normals are interpolated in it.
    """

    def __init__(self, meshes, kind, mesh_of, xform_row, xforms, dtype):
        self.kind = np.asarray(kind, np.int64)
        self.mesh_of = np.asarray(mesh_of, np.int64)
        self.xform_row = np.asarray(xform_row, np.int64)
        self.xforms = np.asarray(xforms, dtype).reshape(-1, 12)
        vertex_base = np.cumsum([0, *(len(m.vertices) for m in meshes)])[:-1]
        self.face_base = np.cumsum([0, *(len(m.faces) for m in meshes)])[:-1].astype(np.int64)
        self.faces = np.concatenate(
            [m.faces + base for m, base in zip(meshes, vertex_base, strict=True)]
            or [np.zeros((0, 3), np.int64)])
        self.normals = np.concatenate([vertex_normals(m.vertices, m.faces) for m in meshes]
                                      or [np.zeros((0, 3))]).astype(dtype)


def shading_normals(tables, geom_id, prim_id, u, v, normal):
    """Unit shading normals of closest hits.

    Parameters
    ----------
    tables : NormalTables
        The scene's.
    geom_id, prim_id : ndarray of int64, shape (N,)
    u, v : ndarray, shape (N,)
        Barycentrics of mesh hits (hit point ``(1-u-v) a + u b + v c``), as the trace gives
        them: read only at mesh hits, so no (N, 2) ``uv`` field is made for them.
    normal : ndarray, shape (N, 3)
        Geometric normals: the answer for analytic shapes and misses (NaN).

    Returns
    -------
    ndarray, shape (N, 3)
        Facing as the geometric normal does (vertex normals follow the faces' winding).
    """
    out = empty_aligned(normal.shape, normal.dtype)
    _interpolate(geom_id, prim_id, u, v, normal, tables.kind, tables.mesh_of, tables.xform_row,
                 tables.xforms, tables.face_base, tables.faces, tables.normals, out)
    return out
