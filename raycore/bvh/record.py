"""The packed scene that every kernel reads: one record of arrays.

A built :class:`raycore.Scene` hands its kernels one :class:`SceneRecord` (a Numba structref),
not a list of loose arrays, so that a call from Python type-checks one argument for the whole
scene.  A structref's fields live behind Numba's reference-counted memory, which the traversal
(compiled without reference counts) cannot read: the entry points turn it into a
:data:`SceneArrays` named tuple once per call (:func:`arrays_of`), and kernels read
``scene.kind``, ``scene.blocks`` and so on from that.  The same record will serve the point
queries (closest point, winding number): the wide nodes and the leaf blocks are all they need.
"""

from collections import namedtuple

from numba import njit, types
from numba.experimental import structref

#: Fields in constructor order.
FIELDS = (
    # top-level BVH over bounded objects: wide rows (float32 and their int32 view), the object
    # of each leaf slot, and the objects tested before it (unbounded ones, or a lone object)
    "top_nodes", "top_refs", "top_order", "direct",
    # per object: kind, analytic parameter row, mesh, inverse-transform row (-1: none); the
    # (P, PARAM_WIDTH) parameter table (None in a scene without shapes) and the (T, 12)
    # object-from-world matrices
    "kind", "param_row", "mesh_of", "xform_row", "params", "xforms",
    # every mesh's wide rows and leaf blocks (raycore.bvh.leaves), concatenated, with each
    # mesh's first row and first block
    "mesh_nodes", "mesh_refs", "blocks", "node_base", "block_base",
)


@structref.register
class SceneRecordType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(kind)) for name, kind in fields)


class SceneRecord(structref.StructRefProxy):
    """The arrays of a built scene, as one argument for compiled code (fields:
    :data:`RECORD_FIELDS`).

    Python code also reads two attributes, set by the scene that packs the record (a field read
    from Python would compile a getter): ``tree_bytes``, the bytes of the wide rows and leaf
    blocks that traversal reads, and ``entry_points``, the compiled entries that queries called
    with records of its type (:func:`raycore.queries._compiled`).
    """


#: The record's fields: :data:`FIELDS`, then the parameter table once more, as an array in every
#: scene (empty without shapes), for :func:`tabled_arrays_of`.
RECORD_FIELDS = (*FIELDS, "table")

structref.define_proxy(SceneRecord, SceneRecordType, list(RECORD_FIELDS))


@njit(cache=True)
def new_record(*fields):
    """A :class:`SceneRecord` of ``fields`` (:data:`RECORD_FIELDS`' values, in order), made by
    compiled code.  ``SceneRecord(...)`` from Python calls a constructor that Numba compiles
    afresh in each process (it keeps it on the class, not on disk): 0.55 s of a first answer
    with every kernel cached."""
    return SceneRecord(*fields)


#: The same arrays as a named tuple, passed by value between compiled functions.
SceneArrays = namedtuple("SceneArrays", FIELDS)


@njit(cache=True, inline="always")
def _arrays(scene, table):
    """The :data:`SceneArrays` of record ``scene``, with ``table`` as the parameter table."""
    return SceneArrays(
        scene.top_nodes, scene.top_refs, scene.top_order, scene.direct,
        scene.kind, scene.param_row, scene.mesh_of, scene.xform_row, table, scene.xforms,
        scene.mesh_nodes, scene.mesh_refs, scene.blocks, scene.node_base, scene.block_base)


@njit(cache=True)
def arrays_of(scene):
    """The :data:`SceneArrays` of a :class:`SceneRecord` (inside compiled code)."""
    return _arrays(scene, scene.params)


@njit(cache=True)
def tabled_arrays_of(scene):
    """:func:`arrays_of`, with the parameter table as an array in a scene without shapes too
    (empty), so that the passes over large batches compile once for both kinds of scene.

    A scene without shapes gives :func:`arrays_of` no table, and the shapes' code compiles away
    (:func:`raycore.primitives.analytic.table_hit`): the small batches' entries, which a first
    answer compiles, take that.  The large batches' passes keep the code that every scene runs:
    compiled without the shapes, the parallel traversal ran float64 camera rays 4-5 % slower
    (one thread, stanford-bunny and nefertiti, seven alternating processes).
    """
    return _arrays(scene, scene.table)
