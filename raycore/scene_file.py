"""A built :class:`~raycore.Scene` as one file: what ``build()`` made, so that loading skips it.

The file (:mod:`raycore.arrayfile`) holds the arrays the Scene and its meshes keep: each mesh's
vertices, faces, wide BVH rows and leaf blocks (with their face indices); the top-level tree;
the object tables, analytic parameters and instance transforms; and, in its JSON header, the
dtype, the build parameters and the trees' statistics.  Loading checks every index a kernel
follows (object tables, tree references, leaf ranges, face indices) and rebuilds the kernels'
record with the same code as ``build()`` (``Scene._assemble``).  Pickling a Scene goes through
the same bytes, so that a pickle holds each array once.
"""


import numpy as np
from numba import njit

from raycore import arrayfile
from raycore.bvh.build import MAX_DEPTH
from raycore.bvh.layout import BVH, NODE_WIDTH
from raycore.bvh.leaves import FACE_COLUMN, face_ints
from raycore.bvh.simd import BLOCK_PLANES, VECTOR_BYTES, block_width, lanes_for
from raycore.bvh.traverse import MESH
from raycore.bvh.validate import check_tree
from raycore.mesh import Mesh, indices_outside
from raycore.primitives import analytic

#: The BVH layout the stored trees are in; a file made for another is refused (rebuild it).
LAYOUT = {"node_width": NODE_WIDTH, "block_vector_bytes": VECTOR_BYTES,
          "block_planes": BLOCK_PLANES, "max_depth": MAX_DEPTH}
#: The kinds of analytic objects (those with a parameter row).
_ANALYTIC_KINDS = (analytic.SPHERE, analytic.PLANE, analytic.DISK, analytic.BOX,
                   analytic.TRANSFORMED_BOX, analytic.CYLINDER, analytic.CONE)
_TREE_STATS = ("depth", "node_count", "leaf_count", "sah_cost")
#: The object table's columns: the lists that Scene keeps as ``_kind``, ``_param_row``, ...
OBJECT_COLUMNS = ("kind", "param_row", "mesh_of", "xform_row", "visible")


def _tree(bvh, prefix, arrays):
    """Put ``bvh``'s arrays in ``arrays`` under ``prefix``; return its statistics."""
    arrays[f"{prefix}.nodes"] = bvh.nodes
    arrays[f"{prefix}.bounds"] = np.stack([bvh.lo, bvh.hi])
    if bvh.order is not None:
        arrays[f"{prefix}.order"] = bvh.order
    return {name: getattr(bvh, name) for name in _TREE_STATS}


def contents(scene, extra=None):
    """``(meta, arrays)`` of a built scene, for :func:`raycore.arrayfile.encode`.

    ``extra``, ``(meta, arrays)`` of the caller's own (e.g. the service's colours), is kept
    beside the scene: under ``meta["extra"]`` and arrays named ``extra.<name>``.
    """
    scene._scene()
    placed = sorted(scene._placement)
    columns = [scene._kind, scene._param_row, scene._mesh_of, scene._xform_row, scene._visible]
    arrays = {"objects": np.array(columns, np.int64).T.copy()}  # (n, 5): OBJECT_COLUMNS
    optional = {
        "params": np.array(scene._params, np.float64).reshape(-1, analytic.PARAM_WIDTH),
        "xforms": np.array(scene._xforms, np.float64).reshape(-1, 3, 4),
        "placement.objects": np.array(placed, np.int64),
        "placement.matrices": np.array([scene._placement[o][0] for o in placed],
                                       np.float64).reshape(-1, 4, 4),
        "placement.bounds": np.array([scene._placement[o][1] for o in placed],
                                     np.float64).reshape(-1, 2, 3),
        "top.slots": scene._top_slots,
        "top.direct": scene._direct,
    }
    # an empty table is left out (a small scene's load spent a microsecond on each array)
    arrays.update({name: array for name, array in optional.items() if len(array)})
    meshes = []
    for i, mesh in enumerate(scene._meshes):
        arrays[f"mesh{i}.vertices"] = mesh.vertices
        arrays[f"mesh{i}.faces"] = mesh.faces
        arrays[f"mesh{i}.blocks"] = mesh.leaf_blocks
        meshes.append(dict(_tree(mesh.bvh, f"mesh{i}", arrays),
                           build_seconds=mesh.build_seconds))
    params = scene.build_params
    meta = {"dtype": np.dtype(scene.dtype).name, "layout": LAYOUT, "meshes": meshes,
            "build": {"bins": params.bins, "max_leaf_size": params.max_leaf_size,
                      "traversal_cost": params.traversal_cost,
                      "intersection_cost": params.intersection_cost},
            "top": None if scene._top is None else _tree(scene._top, "top", arrays),
            "build_seconds": scene.build_seconds}
    if extra is not None:
        meta["extra"] = extra[0]
        arrays.update({f"extra.{name}": array for name, array in extra[1].items()})
    return meta, arrays


def save(scene, path, extra=None):
    """Write a scene (built first if it is not) to ``path``, atomically; ``extra`` as in
    :func:`contents`."""
    arrayfile.write(path, *contents(scene, extra))


def dumps(scene):
    """The bytes of :func:`save`'s file (for pickling)."""
    return b"".join(arrayfile.encode(*contents(scene)))


def load(source, *, mmap=False):
    """A built Scene from a file :func:`save` wrote (or its bytes); see ``Scene.load``."""
    return _loaded(source, mmap)[0]


def load_with_extra(source, *, mmap=False):
    """``(scene, extra_meta, extra_arrays)`` from a file :func:`save` wrote with ``extra``
    (None and {} without)."""
    scene, meta, arrays = _loaded(source, mmap)
    extra = {name[len("extra."):]: array for name, array in arrays.items()
             if name.startswith("extra.")}
    return scene, meta.get("extra"), extra


def _loaded(source, mmap):
    """``(scene, meta, arrays)`` of a file :func:`save` wrote."""
    from raycore.scene import Scene

    meta, arrays = arrayfile.read(source, mmap=mmap)
    try:
        return _restore(Scene, meta, arrays), meta, arrays
    except (KeyError, TypeError, AttributeError) as error:
        raise ValueError(f"the scene file is corrupt (missing or malformed {error})") from error


def _taker(arrays):
    """``take(name, dtype, shape, may_be_absent=False)``: the file's array ``name``, checked
    (:func:`raycore.arrayfile.checked`); an empty one where ``may_be_absent`` and the file left
    it out (:func:`contents` leaves out empty tables)."""
    def take(name, dtype, shape, may_be_absent=False):
        if may_be_absent and shape[0] in (None, 0) and name not in arrays:
            return np.empty((0, *shape[1:]), dtype)
        return arrayfile.checked(arrays, name, dtype, shape, "the scene file")
    return take


def _objects(take, arrays):
    """The object table, (n, 5) int64: kind, parameter row, mesh, transform row, visible.

    Files of format versions 1 and 2 kept its columns as arrays of their own: these are joined.
    """
    if "objects" in arrays or "kind" not in arrays:
        return take("objects", np.int64, (None, len(OBJECT_COLUMNS)))
    kind = take("kind", np.int64, (None,))
    columns = [kind] + [take(name, np.int64, (len(kind),)) for name in OBJECT_COLUMNS[1:-1]]
    return np.stack(columns + [take("visible", bool, (len(kind),))], axis=1)  # int64


def _bvh(take, prefix, stats, order_length):
    bounds = take(f"{prefix}.bounds", np.float64, (2, 3))
    nodes = take(f"{prefix}.nodes", np.float32, (None, NODE_WIDTH))
    order = None if order_length is None else take(f"{prefix}.order", np.int64, (order_length,))
    return BVH(nodes=nodes, refs=nodes.view(np.int32), order=order, lo=bounds[0], hi=bounds[1],
               **{name: stats[name] for name in _TREE_STATS})


def _restore(Scene, meta, arrays):
    if meta.get("layout") != LAYOUT:
        raise ValueError(f"the scene file's BVH layout {meta.get('layout')} is not this "
                         f"raycore's {LAYOUT}: build the scene again and save it")
    scene = Scene(meta["dtype"], **meta["build"])
    dtype = scene.dtype
    take = _taker(arrays)
    objects = _objects(take, arrays)
    n = len(objects)
    params = take("params", np.float64, (None, analytic.PARAM_WIDTH), True)
    xforms = take("xforms", np.float64, (None, 3, 4), True)
    placed = take("placement.objects", np.int64, (None,), True)
    matrices = take("placement.matrices", np.float64, (len(placed), 4, 4), True)
    bounds = take("placement.bounds", np.float64, (len(placed), 2, 3), True)
    top_slots = take("top.slots", np.int64, (None,), True)
    direct = take("top.direct", np.int64, (None,), True)
    sizes = {"objects": n, "meshes": len(meta["meshes"]), "params": len(params),
             "xforms": len(xforms)}
    problem = _object_problem(objects, sizes["params"], sizes["xforms"], sizes["meshes"], placed,
                              top_slots, direct)
    if problem:
        what = _OBJECT_PROBLEMS[problem].format(**sizes)
        raise ValueError(f"the scene file is corrupt ({what})")

    lanes = lanes_for(dtype)
    for i, stats in enumerate(meta["meshes"]):
        vertices = take(f"mesh{i}.vertices", np.float64, (None, 3))
        faces = take(f"mesh{i}.faces", np.int64, (None, 3))
        blocks = take(f"mesh{i}.blocks", dtype, (None, block_width(dtype)))
        problem = _mesh_problem(vertices, faces, face_ints(blocks), lanes)
        if problem:
            what = _MESH_PROBLEMS[problem].format(vertices=len(vertices), faces=len(faces))
            raise ValueError(f"the scene file is corrupt (mesh {i}: {what})")
        bvh = _bvh(take, f"mesh{i}", stats, None)
        _checked_tree(bvh.nodes, len(blocks), lanes, f"mesh {i}")
        scene._meshes.append(Mesh.restored(vertices, faces, bvh, blocks, dtype,
                                           scene.build_params, stats["build_seconds"]))

    if meta["top"] is not None:
        # the tree is over the bounded objects: those in its slots, or the lone one
        scene._top = _bvh(take, "top", meta["top"], len(top_slots) or 1)
        if len(top_slots):
            _checked_tree(scene._top.nodes, len(top_slots), 1, "the top tree")
    elif len(top_slots):
        raise ValueError("the scene file is corrupt (top-tree objects without a top tree)")

    scene._kind, scene._param_row, scene._mesh_of, scene._xform_row, visible = \
        objects.T.tolist()
    scene._visible = list(map(bool, visible))
    scene._params, scene._xforms = _rows(params), _rows(xforms)
    scene._placement = {obj: (matrices[i], (bounds[i, 0], bounds[i, 1]))
                        for i, obj in enumerate(placed.tolist())}
    scene._top_slots, scene._direct = top_slots, direct
    scene.build_seconds = meta["build_seconds"]
    scene._assemble()
    return scene


def _rows(array):
    """``list(array)``, by indexing: iterating an array ends in an IndexError, which NumPy took
    longer to make than the rest of a small scene's tables."""
    return [array[row] for row in range(len(array))]


def _checked_tree(nodes, leaf_limit, blocks, name):
    try:
        check_tree(nodes, leaf_limit, blocks, name)
    except ValueError as error:
        raise ValueError(f"the scene file is corrupt ({error})") from error


_OBJECT_PROBLEMS = {
    1: "unknown object kinds",
    2: "mesh references outside [0, {meshes})",
    3: "parameter rows outside [0, {params})",
    4: "transform rows outside [-1, {xforms})",
    5: "object tables disagree with kinds",
    6: "placed objects outside [0, {objects})",
    7: "the top tree's objects outside [0, {objects})",
    8: "directly tested objects outside [0, {objects})",
    9: "visibility flags other than 0 and 1",
}


@njit(cache=True)
def _object_problem(objects, param_rows, xform_rows, mesh_count, placed, top_slots, direct):
    """0, or the key in _OBJECT_PROBLEMS of the first problem found with the object tables, in
    one pass over them (NumPy took a dozen calls, 0.1 ms of a small scene's load).

    Parameters
    ----------
    objects : ndarray of int64, shape (n, 5)
        Per object, the :data:`OBJECT_COLUMNS` as :class:`raycore.Scene` keeps them: a mesh has
        a mesh, maybe a transform row (-1: none) and no parameter row (-1); an analytic shape a
        parameter row only; visible is 0 or 1.
    param_rows, xform_rows, mesh_count : int
        Rows of the parameter and transform tables, and meshes.
    placed, top_slots, direct : ndarray of int64
        Object indices: of the instances placed, in the top tree's slots, tested directly.
    """
    n = len(objects)
    for i in range(n):
        row = objects[i]
        kind, param_row, mesh_of, xform_row, visible = row[0], row[1], row[2], row[3], row[4]
        if visible != 0 and visible != 1:
            return 9
        if kind == MESH:
            if mesh_of < 0 or mesh_of >= mesh_count:
                return 2
            if xform_row < -1 or xform_row >= xform_rows:
                return 4
            if param_row != -1:
                return 5
            continue
        known = False
        for analytic_kind in _ANALYTIC_KINDS:
            known |= kind == analytic_kind
        if not known:
            return 1
        if param_row < 0 or param_row >= param_rows:
            return 3
        if mesh_of != -1 or xform_row != -1:
            return 5
    if indices_outside(placed, n):
        return 6
    if indices_outside(top_slots, n):
        return 7
    if indices_outside(direct, n):
        return 8
    return 0


_MESH_PROBLEMS = {
    1: "no triangles",
    2: "vertices that are not finite",
    3: "face indices outside [0, {vertices})",
    4: "leaf blocks' face indices outside [-1, {faces})",
}


@njit(cache=True)
def _mesh_problem(vertices, faces, block_ints, lanes):
    """0, or the key in _MESH_PROBLEMS of the first problem found with a stored mesh, in one
    pass over each array: what :class:`raycore.mesh.Mesh` requires of its arrays (a rebuild
    reads vertices by the faces), and leaf blocks whose face indices (-1 in padding lanes)
    lie within the faces (queries read faces by them).

    Parameters
    ----------
    vertices : ndarray of float64, shape (V, 3)
    faces : ndarray of int64, shape (F, 3)
    block_ints : ndarray of int32, shape (B, BLOCK_PLANES * VECTOR_BYTES / 4)
        The leaf blocks viewed as int32 (:func:`raycore.bvh.leaves.face_ints`): the face index
        of lane ``lane`` of block ``b`` is at ``[b, FACE_COLUMN + lane]``.  The whole view, not
        the face columns' slice: a slice of one block's row is C-contiguous and of several is
        not, which Numba types apart, and a file's one-block mesh compiled this function again
        at run time (the container test caught it).
    lanes : int
        Triangles per block.
    """
    # loops over indices, without an early exit, that LLVM vectorises: iterating the arrays
    # took twice as long (1.04 against 0.52 ms for 2.4M coordinates)
    if len(faces) == 0:
        return 1
    coordinates = vertices.reshape(-1)
    finite = True
    for i in range(len(coordinates)):
        finite &= np.isfinite(coordinates[i])
    if not finite:
        return 2
    if indices_outside(faces.reshape(-1), len(vertices)):
        return 3
    top = np.uint64(0)
    for row in range(block_ints.shape[0]):
        for lane in range(FACE_COLUMN, FACE_COLUMN + lanes):
            top = max(top, np.uint64(np.int64(block_ints[row, lane]) + 1))
    if top > np.uint64(len(faces)):
        return 4
    return 0
