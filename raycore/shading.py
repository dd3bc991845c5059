"""Shading normals: mesh vertex normals interpolated with the hits' barycentrics.

A mesh's vertex normals are the area-weighted mean of the geometric normals of the faces around
each vertex (the sum of their unnormalised cross products), so that they point the way the
faces' own normals do.  Analytic shapes are smooth already: their shading normal is their
geometric normal.
"""

import numpy as np
from numba import njit, prange

from raycore._fp import like
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


@njit(inline="always")
def interpolated_normal(tables, g, prim, u, v, nx, ny, nz):
    """Unit shading normal of a hit on object ``g`` (not a miss), of the precision of its unit
    geometric normal ``(nx, ny, nz)``: that normal itself unless ``g`` is a mesh.

    ``tables`` is :attr:`NormalTables.arrays`; ``prim``, ``u``, ``v`` the hit's primitive id
    and barycentrics.  For the passes over closest hits (:func:`shading_normals`, the render's).
    """
    kind, mesh_of, xform_row, xforms, face_base, faces, normals = tables
    if kind[g] != MESH:
        return nx, ny, nz
    f = face_base[mesh_of[g]] + prim
    wa = 1.0 - u - v
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    sx = wa * normals[a, 0] + u * normals[b, 0] + v * normals[c, 0]
    sy = wa * normals[a, 1] + u * normals[b, 1] + v * normals[c, 1]
    sz = wa * normals[a, 2] + u * normals[b, 2] + v * normals[c, 2]
    r = xform_row[g]
    if r >= 0:
        # normals transform by the inverse transpose; xforms hold the inverse (3x4 rows)
        m = xforms[r]
        sx, sy, sz = (m[0] * sx + m[4] * sy + m[8] * sz,
                      m[1] * sx + m[5] * sy + m[9] * sz,
                      m[2] * sx + m[6] * sy + m[10] * sz)
    length = np.sqrt(sx * sx + sy * sy + sz * sz)
    if not length > 0:  # opposite vertex normals cancel: the face's own normal
        return nx, ny, nz
    return like(nx, sx / length), like(nx, sy / length), like(nx, sz / length)


@njit(cache=True, parallel=True, _nrt=False)
def _interpolate(tables, geom_id, prim_id, u, v, normal, out):
    for i in prange(len(geom_id)):
        g = geom_id[i]
        if g < 0:
            for k in range(3):
                out[i, k] = normal[i, k]
            continue
        out[i, 0], out[i, 1], out[i, 2] = interpolated_normal(
            tables, g, prim_id[i], u[i], v[i], normal[i, 0], normal[i, 1], normal[i, 2])


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
        #: The tables as one argument of compiled code (:func:`interpolated_normal`).
        self.arrays = (self.kind, self.mesh_of, self.xform_row, self.xforms, self.face_base,
                       self.faces, self.normals)


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
    _interpolate(tables.arrays, geom_id, prim_id, u, v, normal, out)
    return out
