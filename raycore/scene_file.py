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

from raycore import arrayfile
from raycore.bvh.build import MAX_DEPTH
from raycore.bvh.layout import BVH, NODE_WIDTH
from raycore.bvh.leaves import FACE_COLUMN, face_ints
from raycore.bvh.simd import BLOCK_PLANES, VECTOR_BYTES, block_width, lanes_for
from raycore.bvh.traverse import MESH
from raycore.bvh.validate import check_tree
from raycore.mesh import Mesh
from raycore.primitives import analytic

#: The BVH layout the stored trees are in; a file made for another is refused (rebuild it).
LAYOUT = {"node_width": NODE_WIDTH, "block_vector_bytes": VECTOR_BYTES,
          "block_planes": BLOCK_PLANES, "max_depth": MAX_DEPTH}
_ANALYTIC_KINDS = (analytic.SPHERE, analytic.PLANE, analytic.DISK, analytic.BOX,
                   analytic.TRANSFORMED_BOX, analytic.CYLINDER, analytic.CONE)
_TREE_STATS = ("depth", "node_count", "leaf_count", "sah_cost")


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
    arrays = {
        "kind": np.array(scene._kind, np.int64),
        "param_row": np.array(scene._param_row, np.int64),
        "mesh_of": np.array(scene._mesh_of, np.int64),
        "xform_row": np.array(scene._xform_row, np.int64),
        "visible": np.array(scene._visible, bool),
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
    return load_with_extra(source, mmap=mmap)[0]


def load_with_extra(source, *, mmap=False):
    """``(scene, extra_meta, extra_arrays)`` from a file :func:`save` wrote with ``extra``
    (None and {} without)."""
    from raycore.scene import Scene

    meta, arrays = arrayfile.read(source, mmap=mmap)
    try:
        scene = _restore(Scene, meta, arrays)
    except (KeyError, TypeError, AttributeError) as error:
        raise ValueError(f"the scene file is corrupt (missing or malformed {error})") from error
    extra = {name[len("extra."):]: array for name, array in arrays.items()
             if name.startswith("extra.")}
    return scene, meta.get("extra"), extra


def _taker(arrays):
    """``take(name, dtype, shape)``: the file's array ``name``, checked
    (:func:`raycore.arrayfile.checked`)."""
    return lambda name, dtype, shape: arrayfile.checked(arrays, name, dtype, shape,
                                                        "the scene file")


def _within(values, low, high, what):
    if len(values) and (values.min() < low or values.max() >= high):
        raise ValueError(f"the scene file is corrupt ({what} outside [{low}, {high}))")


def _bvh(take, prefix, stats, order_length):
    bounds = take(f"{prefix}.bounds", np.float64, (2, 3))
    nodes = take(f"{prefix}.nodes", np.float32, (None, NODE_WIDTH))
    order = None if order_length is None else take(f"{prefix}.order", np.int64, (order_length,))
    return BVH(nodes=nodes, refs=nodes.view(np.int32), order=order, lo=bounds[0].copy(),
               hi=bounds[1].copy(), **{name: stats[name] for name in _TREE_STATS})


def _restore(Scene, meta, arrays):
    if meta.get("layout") != LAYOUT:
        raise ValueError(f"the scene file's BVH layout {meta.get('layout')} is not this "
                         f"raycore's {LAYOUT}: build the scene again and save it")
    scene = Scene(meta["dtype"], **meta["build"])
    dtype = scene.dtype
    take = _taker(arrays)
    kind = take("kind", np.int64, (None,))
    n = len(kind)
    param_row = take("param_row", np.int64, (n,))
    mesh_of = take("mesh_of", np.int64, (n,))
    xform_row = take("xform_row", np.int64, (n,))
    visible = take("visible", bool, (n,))
    params = take("params", np.float64, (None, analytic.PARAM_WIDTH))
    xforms = take("xforms", np.float64, (None, 3, 4))
    is_mesh = kind == MESH
    if not np.all(is_mesh | np.isin(kind, _ANALYTIC_KINDS)):
        raise ValueError("the scene file is corrupt (unknown object kinds)")
    _within(mesh_of[is_mesh], 0, len(meta["meshes"]), "mesh references")
    _within(param_row[~is_mesh], 0, len(params), "parameter rows")
    _within(xform_row[is_mesh], -1, len(xforms), "transform rows")
    if np.any(param_row[is_mesh] != -1) or np.any(mesh_of[~is_mesh] != -1) or np.any(
            xform_row[~is_mesh] != -1):
        raise ValueError("the scene file is corrupt (object tables disagree with kinds)")

    for i, stats in enumerate(meta["meshes"]):
        # Mesh checks the faces against the vertices (a rebuild reads vertices by them)
        try:
            mesh = Mesh(take(f"mesh{i}.vertices", np.float64, (None, 3)),
                        take(f"mesh{i}.faces", np.int64, (None, 3)))
        except ValueError as error:
            raise ValueError(f"the scene file is corrupt (mesh {i}: {error})") from error
        blocks = take(f"mesh{i}.blocks", dtype, (None, block_width(dtype)))
        lanes = lanes_for(dtype)
        faces = face_ints(blocks)[:, FACE_COLUMN:FACE_COLUMN + lanes]
        _within(faces, -1, len(mesh.faces), f"mesh {i}'s face indices")
        bvh = _bvh(take, f"mesh{i}", stats, None)
        _checked_tree(bvh.nodes, len(blocks), lanes, f"mesh {i}")
        mesh.restore(bvh, blocks, dtype, scene.build_params, stats["build_seconds"])
        scene._meshes.append(mesh)

    placed = take("placement.objects", np.int64, (None,))
    matrices = take("placement.matrices", np.float64, (len(placed), 4, 4))
    bounds = take("placement.bounds", np.float64, (len(placed), 2, 3))
    _within(placed, 0, n, "placed objects")
    top_slots = take("top.slots", np.int64, (None,))
    direct = take("top.direct", np.int64, (None,))
    _within(top_slots, 0, n, "the top tree's objects")
    _within(direct, 0, n, "directly tested objects")
    if meta["top"] is not None:
        # the tree is over the bounded objects: those in its slots, or the lone one
        scene._top = _bvh(take, "top", meta["top"], len(top_slots) or 1)
        if len(top_slots):
            _checked_tree(scene._top.nodes, len(top_slots), 1, "the top tree")
    elif len(top_slots):
        raise ValueError("the scene file is corrupt (top-tree objects without a top tree)")

    scene._kind, scene._param_row = kind.tolist(), param_row.tolist()
    scene._mesh_of, scene._xform_row = mesh_of.tolist(), xform_row.tolist()
    scene._visible = visible.tolist()
    scene._params, scene._xforms = list(params), list(xforms)
    scene._placement = {int(obj): (matrix, (box[0], box[1]))
                        for obj, matrix, box in zip(placed, matrices, bounds, strict=True)}
    scene._top_slots, scene._direct = top_slots, direct
    scene.build_seconds = meta["build_seconds"]
    scene._assemble()
    return scene


def _checked_tree(nodes, leaf_limit, blocks, name):
    try:
        check_tree(nodes, leaf_limit, blocks, name)
    except ValueError as error:
        raise ValueError(f"the scene file is corrupt ({error})") from error
