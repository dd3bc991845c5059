"""Triangle meshes: validation, per-mesh BVH, and loading files through trimesh."""

import math
import time
from dataclasses import replace

import numpy as np
from numba import njit, prange

from raycore.bvh.layout import build_bvh_from_records
from raycore.bvh.leaves import pack_leaves
from raycore.bvh.records import (
    PARALLEL_FROM,
    PRIM_INDEX,
    PRIM_WIDTH,
    check_primitive_count,
    round_down32,
    round_up32,
)
from raycore.bvh.simd import lanes_for
from raycore.rays import as_float_array

#: Faces per parallel work item of the passes over faces below.
FACE_CHUNK = 65536


@njit(cache=True)
def indices_outside(indices, count):
    """Whether any of ``indices`` ((K,) int64, C-ordered) lies outside [0, count).

    One comparison for both ends, of the largest index taken as unsigned (a negative one is
    then past any count), in a loop without an early exit that LLVM vectorises: iterating the
    array took twice as long (1.04 against 0.52 ms for 2.4M indices).
    """
    unsigned = indices.view(np.uint64)
    top = np.uint64(0)
    for i in range(len(unsigned)):
        top = max(top, unsigned[i])
    return len(unsigned) > 0 and top >= np.uint64(count)


@njit(cache=True)
def _bound_faces(vertices, faces, start, end, part):
    """Bounds of the vertices that faces ``start:end`` reference into ``part`` (6,) float64:
    lo, then hi."""
    part[0:3] = np.inf
    part[3:6] = -np.inf
    for f in range(start, end):
        for k in range(3):
            for a in range(3):
                x = vertices[faces[f, k], a]
                part[a] = min(part[a], x)
                part[3 + a] = max(part[3 + a], x)


@njit(cache=True, parallel=True)
def _bound_chunks(vertices, faces, parts):
    n = faces.shape[0]
    for c in prange(len(parts)):
        _bound_faces(vertices, faces, c * FACE_CHUNK, min(n, (c + 1) * FACE_CHUNK), parts[c])


def referenced_bounds(vertices, faces):
    """(lo, hi): (3,) float64 bounds of the vertices that ``faces`` (F, 3) reference in
    ``vertices`` (V, 3), without gathering the (F, 3, 3) corners: a chunk of FACE_CHUNK faces a
    core, and a lone chunk on the calling thread (a parallel region of one item would only wake
    the sleeping threads)."""
    parts = np.empty((max(-(-len(faces) // FACE_CHUNK), 1), 6))
    if len(parts) == 1:
        _bound_faces(vertices, faces, 0, len(faces), parts[0])
    else:
        _bound_chunks(vertices, faces, parts)
    return parts[:, :3].min(axis=0), parts[:, 3:].max(axis=0)


@njit(cache=True, inline="always")
def _triangle_record(vertices, faces, prims, index, f):
    """Write the record of face ``f`` into ``prims`` (and its int32 view ``index``)."""
    for a in range(3):
        x0 = vertices[faces[f, 0], a]
        x1 = vertices[faces[f, 1], a]
        x2 = vertices[faces[f, 2], a]
        prims[f, a] = round_down32(min(x0, x1, x2))
        prims[f, 3 + a] = round_up32(max(x0, x1, x2))
    index[f, PRIM_INDEX] = f
    index[f, PRIM_INDEX + 1] = 0


@njit(cache=True, parallel=True)
def _triangle_records(vertices, faces, on_all_cores):
    prims = np.empty((faces.shape[0], PRIM_WIDTH), np.float32)
    index = prims.view(np.int32)
    if on_all_cores:
        for f in prange(faces.shape[0]):
            _triangle_record(vertices, faces, prims, index, f)
    else:  # see raycore.bvh.records._records
        for f in range(faces.shape[0]):
            _triangle_record(vertices, faces, prims, index, f)
    return prims


def triangle_records(vertices, faces):
    """BVH primitive records of triangles: their boxes rounded outwards to float32 and their
    indices, (F, PRIM_WIDTH) float32 (see :mod:`raycore.bvh.build`), straight from ``vertices``
    (V, 3) in the scene's dtype and ``faces`` (F, 3); on all cores from PARALLEL_FROM faces."""
    return _triangle_records(vertices, faces, len(faces) >= PARALLEL_FROM)


class Mesh:
    """Vertices and faces of a triangle mesh, and its BVH once built.

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
    faces : array_like of int, shape (F, 3)

    Raises
    ------
    ValueError
        Naming ``vertices`` or ``faces``: wrong shape, non-finite coordinates, no faces, indices
        that are not integers or lie outside [0, V).
    """

    def __init__(self, vertices, faces):
        vertices = as_float_array(vertices, "vertices", np.float64, (None, 3))
        try:
            faces = np.asarray(faces)
        except (TypeError, ValueError) as error:  # ragged rows
            raise ValueError(f"faces must be an (F, 3) array of vertex indices: {error}") \
                from error
        if faces.dtype.kind not in "iu":
            if faces.dtype.kind != "f" or not np.all(np.isfinite(faces)) or np.any(
                    faces != np.round(faces)):
                raise ValueError(f"faces must hold integer vertex indices, got dtype {faces.dtype}")
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(f"faces must have shape (F, 3), got {faces.shape}")
        if len(faces) == 0:
            raise ValueError("faces must hold at least one triangle")
        indices = np.ascontiguousarray(faces, dtype=np.int64)
        if indices_outside(indices.reshape(-1), len(vertices)):
            raise ValueError(
                f"faces must index vertices in [0, {len(vertices)}), "
                f"got indices in [{faces.min()}, {faces.max()}]")
        self._set(vertices, indices)

    def _set(self, vertices, faces):
        """Hold valid ``vertices`` (V, 3) float64 and ``faces`` (F, 3) int64, both C-ordered,
        with no BVH yet."""
        self.vertices, self.faces = vertices, faces
        self._bounds = None
        self.bvh = None  # its leaves reference leaf_blocks once built
        self.leaf_blocks = None
        self.build_seconds = 0.0
        self._built_for = None

    @property
    def bounds(self):
        """(lo, hi): (3,) float64 bounds of the referenced vertices."""
        if self._bounds is None:
            self._bounds = referenced_bounds(self.vertices, self.faces)
        lo, hi = self._bounds
        return lo.copy(), hi.copy()

    def transformed_bounds(self, matrix):
        """World bounds of the mesh under a 4x4 affine ``matrix`` (its box's 8 corners)."""
        lo, hi = self.bounds
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        world = transform_points(matrix, corners)
        return world.min(axis=0), world.max(axis=0)

    def build(self, dtype, params):
        """Build the BVH for triangles stored in ``dtype`` (once per dtype and parameters)."""
        if self._built_for == (dtype, params):
            return
        start = time.perf_counter()
        check_primitive_count(len(self.faces))
        # bound the triangles as the kernels will see them, after rounding to dtype; rounding
        # is monotonic, so the rounded bounds are the bounds of the rounded vertices
        vertices = self.vertices.astype(dtype, copy=False)
        lo, hi = (bound.astype(dtype).astype(np.float64) for bound in self.bounds)
        # let a rebuild's old tree go before the new one takes memory
        self.bvh = self.leaf_blocks = self._built_for = None
        # the SAH prices a leaf by the blocks its triangles fill
        bvh = build_bvh_from_records(triangle_records(vertices, self.faces), lo, hi,
                                     replace(params, block_size=lanes_for(dtype)))
        self.leaf_blocks = pack_leaves(bvh.nodes, bvh.refs, bvh.order, vertices, self.faces,
                                       dtype)
        # the blocks' face indices replace the leaf order, and the leaves now point at blocks
        self.bvh = replace(bvh, order=None)
        self.build_seconds = time.perf_counter() - start
        self._built_for = (dtype, params)

    @classmethod
    def restored(cls, vertices, faces, bvh, leaf_blocks, dtype, params, build_seconds):
        """A mesh with the BVH that :meth:`build` made for it earlier, as
        :mod:`raycore.scene_file` stored them, in place of building one.

        The caller has checked the arrays (``raycore.scene_file._mesh_problem``, with
        :func:`indices_outside` as here): ``vertices`` (V, 3) float64, finite; ``faces`` (F, 3)
        int64 in [0, V), F > 0; both C-ordered.  The checks of ``__init__``, which take any
        array_like, are not repeated.
        """
        mesh = cls.__new__(cls)
        mesh._set(vertices, faces)
        mesh.bvh, mesh.leaf_blocks = bvh, leaf_blocks
        mesh.build_seconds = build_seconds
        mesh._built_for = (dtype, params)
        return mesh

    @property
    def nbytes(self):
        """Bytes held for ray queries: the BVH and the leaf blocks (with their face indices)."""
        return self.bvh.nbytes + self.leaf_blocks.nbytes


def validate_transform(transform):
    """Return a 4x4 float64 affine matrix, or raise ``ValueError`` naming ``transform``.

    Accepts (4, 4) with last row (0, 0, 0, 1) or (3, 4); the linear part must be invertible, with
    a condition number (:func:`condition_number`) of at most 1e12.
    """
    matrix = as_float_array(transform, "transform", np.float64)
    if matrix.shape == (3, 4):
        matrix = np.vstack([matrix, [0.0, 0.0, 0.0, 1.0]])
    if matrix.shape != (4, 4):
        raise ValueError(f"transform must have shape (4, 4) or (3, 4), got {matrix.shape}")
    if not np.array_equal(matrix[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError("transform must be affine: its last row must be (0, 0, 0, 1)")
    if condition_number(matrix[:3, :3]) > 1e12:
        raise ValueError("transform must be invertible (its linear part is singular)")
    return matrix


# Affine matrices are inverted and composed here in exact integer arithmetic (a float64 is an
# integer over a power of two) and rounded once, so that every machine stores the same bits.
# NumPy's inv and matmul run OpenBLAS kernels chosen for the CPU: for one transform, the kernels
# of an AVX2-only EPYC and of an AVX-512 Zen 4 gave inverses up to 6 ulps apart, which moved the
# float64 t of a ray grazing an instance's triangle (at 1.3 degrees) by 42 ulps.


def _integers(matrix):
    """``(ints, denominator)``: the entries of a float64 matrix as nested lists of integers over
    one power of two, ``matrix == ints / denominator`` exactly."""
    ratios = [[x.as_integer_ratio() for x in row]
              for row in np.asarray(matrix, np.float64).tolist()]
    denominator = max(d for row in ratios for _, d in row)
    return [[n * (denominator // d) for n, d in row] for row in ratios], denominator


def _rounded(numerator, denominator):
    """The float64 nearest to ``numerator / denominator`` (integers): CPython rounds an integer
    true division correctly."""
    try:
        return numerator / denominator
    except OverflowError as error:
        raise ValueError("transform overflows float64 once inverted or composed") from error


def _adjugate(rows):
    """Adjugate (nested lists) and determinant of a 3x3 integer matrix given as three rows."""
    (a, b, c), (d, e, f), (g, h, i) = rows
    adjugate = [[e * i - f * h, c * h - b * i, b * f - c * e],
                [f * g - d * i, a * i - c * g, c * d - a * f],
                [d * h - e * g, b * g - a * h, a * e - b * d]]
    return adjugate, a * adjugate[0][0] + b * adjugate[1][0] + c * adjugate[2][0]


def affine_inverse(matrix):
    """The inverse of an affine map, each entry the exact value rounded once to float64.

    Parameters
    ----------
    matrix : array_like, shape (4, 4) or (3, 4)
        Float64 ``[L | t]`` (rows below the third are ignored): ``x -> L x + t``.

    Returns
    -------
    ndarray, shape (3, 4)
        ``[L⁻¹ | -L⁻¹ t]``, the same bits on every machine.

    Raises
    ------
    ValueError
        Naming ``transform`` when ``L`` is singular or its inverse overflows float64.
    """
    ints, denominator = _integers(np.asarray(matrix)[:3])
    adjugate, det = _adjugate([row[:3] for row in ints])
    if det == 0:
        raise ValueError("transform must be invertible (its linear part is singular)")
    # L = ints / D, so L⁻¹ = adj(ints) D / det(ints) and -L⁻¹ t = -adj(ints) t_ints / det(ints)
    shift = [row[3] for row in ints]
    return np.array([[_rounded(a * denominator, det) for a in row]
                     + [_rounded(-(row[0] * shift[0] + row[1] * shift[1] + row[2] * shift[2]),
                                 det)]
                     for row in adjugate])


def affine_product(first, second):
    """``first @ second`` of two 4x4 affine matrices, each entry rounded once from the exact
    product (4x4 float64, last row (0, 0, 0, 1))."""
    a, da = _integers(first)
    b, db = _integers(second)
    columns = list(zip(*b, strict=True))
    return np.array([[_rounded(sum(x * y for x, y in zip(row, column, strict=True)), da * db)
                      for column in columns] for row in a])


def condition_number(linear):
    """``‖L‖∞ ‖L⁻¹‖∞`` of a 3x3 float64 matrix, correctly rounded (inf when singular).

    Within a factor 3 of the 2-norm condition number either way, equal to it for a scaling, and
    the same on every machine (``np.linalg.cond`` runs LAPACK's SVD, whose last bits depend on
    the CPU: a transform near a limit could pass on one machine and fail on another).
    """
    ints, _ = _integers(linear)
    adjugate, det = _adjugate(ints)
    if det == 0:
        return math.inf
    # L = ints / D and L⁻¹ = adj(ints) D / det(ints): the scale cancels
    norm = max(sum(abs(x) for x in row) for row in ints)
    inverse_norm = max(sum(abs(x) for x in row) for row in adjugate)
    try:
        return norm * inverse_norm / abs(det)
    except OverflowError:
        return math.inf


def transform_points(matrix, points):
    """``points @ L.T + t`` for a (3, 4) or (4, 4) affine ``[L | t]`` and (N, 3) points, each
    coordinate summed left to right (``((L0 x + L1 y) + L2 z) + t``): the same bits on every
    machine, within γ(4)·(|L| |p| + |t|) of the exact value."""
    matrix = np.asarray(matrix, np.float64)
    points = np.asarray(points, np.float64)
    return ((points[:, :1] * matrix[:3, 0] + points[:, 1:2] * matrix[:3, 1])
            + points[:, 2:] * matrix[:3, 2]) + matrix[:3, 3]


def load_trimesh(path_or_file, file_type=None):
    """Load a mesh file with trimesh; return a ``trimesh.Trimesh`` or ``trimesh.Scene``.

    Only the geometry is read: rays need no materials, and a material's texture is an image
    that a small file can declare huge (a 100 kB glTF with a 12000x12000 PNG took 400 MB).

    Raises
    ------
    ValueError
        When trimesh cannot read the file or it holds no triangles.
    """
    import trimesh

    try:
        loaded = trimesh.load(path_or_file, file_type=file_type, process=False,
                              skip_materials=True)
    except Exception as error:  # trimesh raises many exception types for unreadable input
        raise ValueError(f"could not read the mesh file: {error}") from error
    if isinstance(loaded, trimesh.Scene):
        if not any(isinstance(g, trimesh.Trimesh) and len(g.faces) for g in
                   loaded.geometry.values()):
            raise ValueError("the mesh file holds no triangles")
    elif not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValueError("the mesh file holds no triangles")
    return loaded
