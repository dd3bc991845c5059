"""Scene: a registry of geometry, its two-level BVH, and the ray queries.

Every ``add_*`` returns a geometry id (the index of the object it creates).  Meshes get their own
BVH once, shared by all their instances; the top-level BVH is rebuilt over objects when the scene
changes.  Analytic shapes stay analytic: a sphere is one object, not a tessellation.
"""

import itertools
import os
import threading
import time

import numpy as np

from raycore import queries, scene_file
from raycore._memory import empty_on_line
from raycore.bvh.build import BuildParams
from raycore.bvh.layout import NODE_WIDTH, build_bvh
from raycore.bvh.leaves import empty_blocks
from raycore.bvh.record import new_record
from raycore.bvh.traverse import MESH
from raycore.hits import AllHits, Hits, SurfaceHits, check_fields
from raycore.integrations import open3d as _open3d
from raycore.mesh import Mesh, affine_inverse, affine_product, validate_transform
from raycore.primitives import analytic, box, cone, cylinder, disk, plane, sphere
from raycore.primitives.triangle import WATERTIGHT, triangle_test_code
from raycore.rays import as_float_array, flag, integer, ray_arrays, refuse, resolve_dtype
from raycore.shading import NormalTables, shading_normals

#: Directions for ``contains``: a majority vote over three rays makes the parity test robust to a
#: ray that grazes a mesh (touches it without crossing).  Irrational-looking components keep them
#: off axis-aligned and symmetric features.
_CONTAINS_DIRECTIONS = np.array([
    [0.5773502691896258, 0.5773502691896258, 0.5773502691896257],
    [-0.3163755790315131, 0.8433432417069424, 0.4344235271543209],
    [0.7247963917217364, -0.2510937052283718, -0.6416733155716311],
])


class Scene:
    """A set of analytic shapes and triangle meshes, queried with batches of rays.

    Parameters
    ----------
    dtype : {"float32", "float64"}
        Precision of the stored geometry and of every kernel.
    bins, max_leaf_size, traversal_cost, intersection_cost
        SAH build parameters of the meshes' trees (see :class:`raycore.bvh.build.BuildParams`).
        A mesh's leaf triangles are tested a block at a time (eight float32 or four float64:
        :mod:`raycore.bvh.leaves`), and the SAH prices a leaf by the blocks it fills (as
        Embree's builder does): leaves of up to 8 at a cost of 1.0 a block of four made trees
        of 57-60 B per triangle (73 B when pricing each triangle at 0.4) that traced random rays
        4-8 % faster (stanford-bunny, one thread).  The
        top-level tree over objects, each tested on its own, keeps the default costs, with
        ``bins``.

    Examples
    --------
    >>> scene = Scene(dtype="float64")
    >>> sphere = scene.add_sphere([0, 0, 5], 1.0)
    >>> hits = scene.intersect([[0, 0, 0]], [[0, 0, 1]], fields=("normal",))
    >>> float(hits.t[0]), int(hits.geom_id[0]), hits.normal[0].tolist()
    (4.0, 0, [0.0, 0.0, -1.0])
    """

    def __init__(self, dtype="float32", *, bins=16, max_leaf_size=8, traversal_cost=1.0,
                 intersection_cost=1.0):
        self.dtype = resolve_dtype(dtype)
        self._kernel_dtype = np.dtype(self.dtype)
        self.build_params = BuildParams(bins, max_leaf_size, traversal_cost, intersection_cost)
        self._meshes = []  # Mesh, each with its BVH built lazily
        self._kind = []  # per object
        self._param_row = []
        self._mesh_of = []
        self._xform_row = []
        self._visible = []
        self._params = []  # (20,) float64 rows of analytic shapes
        self._xforms = []  # (3, 4) float64 object-from-world matrices of instances
        self._placement = {}  # instance object -> (4x4 world-from-object matrix, world bounds)
        self._record = None  # the built scene's SceneRecord (raycore.bvh.record)
        self._build_lock = threading.Lock()
        self._top = None  # BVH over the bounded objects, once built
        self._top_slots = None  # (S,) int64: the object in each of the top tree's leaf slots
        self._direct = None  # (D,) int64: objects tested before the tree (unbounded, or lone)
        self.build_seconds = 0.0
        self._normal_tables = None  # (record, raycore.shading.NormalTables) once smooth-shaded

    # ------------------------------------------------------------------ geometry

    def _fits(self, values, names):
        """Return ``values``, or raise ``ValueError`` naming ``names`` when they overflow the
        scene's precision (a float32 scene cannot hold 1e39, nor a radius whose square is)."""
        with np.errstate(over="ignore"):
            stored = np.asarray(values).astype(self.dtype)
        if not np.all(np.isfinite(stored)):
            raise ValueError(f"{names} overflow {np.dtype(self.dtype).name}: "
                             "use a float64 scene or smaller values")
        return values

    def _add_object(self, kind, *, params=None, mesh=-1, xform=None, visible=True):
        self._kind.append(kind)
        self._param_row.append(len(self._params) if params is not None else -1)
        if params is not None:
            self._params.append(params)
        self._mesh_of.append(mesh)
        self._xform_row.append(len(self._xforms) if xform is not None else -1)
        if xform is not None:
            self._xforms.append(xform)
        self._visible.append(visible)
        self._record = None
        return len(self._kind) - 1

    def add_mesh(self, vertices, faces, *, visible=True):
        """Add a triangle mesh; return its geometry id.

        Parameters
        ----------
        vertices : array_like, shape (V, 3)
        faces : array_like of int, shape (F, 3)
            Vertex indices, each in [0, V).
        visible : bool
            False makes the mesh a prototype that only appears through :meth:`add_instance`.
        """
        visible = flag(visible, "visible")
        mesh = Mesh(vertices, faces)
        self._fits(mesh.vertices, "vertices")
        self._meshes.append(mesh)
        return self._add_object(MESH, mesh=len(self._meshes) - 1, visible=visible)

    def add_instance(self, geom_id, transform):
        """Place another copy of mesh ``geom_id`` under a 4x4 affine ``transform``; return its id.

        The copy shares the mesh's vertices and BVH: memory does not grow with the mesh's size.
        ``geom_id`` may itself be an instance: the copy is then placed at ``transform`` applied
        after that instance's own transform.
        """
        if not (isinstance(geom_id, (int, np.integer)) and not isinstance(geom_id, bool)
                and 0 <= geom_id < len(self._kind) and self._kind[geom_id] == MESH):
            raise ValueError(f"geom_id must be the id of a mesh in this scene, got {geom_id!r}")
        matrix = validate_transform(transform)
        if geom_id in self._placement:
            matrix = affine_product(matrix, self._placement[geom_id][0])
        mesh_index = self._mesh_of[geom_id]
        # rounded once from the exact inverse: the same bits on every CPU, unlike np.linalg.inv
        inverse = self._fits(affine_inverse(matrix), "transform (its inverse)")
        obj = self._add_object(MESH, mesh=mesh_index, xform=inverse)
        self._placement[obj] = (matrix, self._meshes[mesh_index].transformed_bounds(matrix))
        return obj

    def _add_shape(self, kind, params, names):
        return self._add_object(kind, params=self._fits(params, names))

    def add_sphere(self, center, radius):
        """Add a sphere; return its geometry id."""
        return self._add_shape(analytic.SPHERE, sphere.pack(center, radius), "center, radius")

    def add_plane(self, point, normal):
        """Add an infinite plane through ``point`` with ``normal``; return its geometry id."""
        return self._add_shape(analytic.PLANE, plane.pack(point, normal), "point, normal")

    def add_disk(self, center, normal, radius):
        """Add a disk; return its geometry id."""
        return self._add_shape(analytic.DISK, disk.pack(center, normal, radius),
                               "center, normal, radius")

    def add_box(self, lo, hi, transform=None):
        """Add an axis-aligned box [lo, hi], optionally under a 4x4 affine ``transform``."""
        if transform is None:
            return self._add_shape(analytic.BOX, box.pack(lo, hi), "lo, hi")
        return self._add_shape(analytic.TRANSFORMED_BOX, box.pack_transformed(lo, hi, transform),
                               "lo, hi, transform")

    def add_cylinder(self, p0, p1, radius):
        """Add a cylinder from ``p0`` to ``p1``, capped at both ends; return its geometry id."""
        return self._add_shape(analytic.CYLINDER, cylinder.pack(p0, p1, radius), "p0, p1, radius")

    def add_cone(self, base_center, apex, radius):
        """Add a cone with its base (capped) at ``base_center``; return its geometry id."""
        return self._add_shape(analytic.CONE, cone.pack(base_center, apex, radius),
                               "base_center, apex, radius")

    def __len__(self):
        return len(self._kind)

    @property
    def triangle_count(self):
        """Triangles stored (instances share their mesh's)."""
        return sum(len(mesh.faces) for mesh in self._meshes)

    # ------------------------------------------------------------------ build

    def _object_bounds(self, obj):
        kind = self._kind[obj]
        if kind == MESH:
            if obj in self._placement:
                return self._placement[obj][1]
            return self._meshes[self._mesh_of[obj]].bounds
        # bound the shape as stored, in the scene's precision
        params = self._params[self._param_row[obj]].astype(self.dtype).astype(np.float64)
        return analytic.analytic_bounds(kind, params)

    def build(self):
        """Build (or rebuild) the BVHs; queries call this when the scene changed."""
        start = time.perf_counter()
        for mesh in self._meshes:
            mesh.build(self.dtype, self.build_params)
        visible = np.flatnonzero(self._visible)
        bounds = [self._object_bounds(obj) for obj in visible]
        lo = np.array([b[0] for b in bounds]).reshape(-1, 3)
        hi = np.array([b[1] for b in bounds]).reshape(-1, 3)
        finite = np.all(np.isfinite(lo) & np.isfinite(hi), axis=1)
        bounded = visible[finite]
        self._top = None  # the tree over bounded objects also gives the scene's bounds
        if len(bounded):
            # instance boxes are computed from rounded transforms: pad them by a few ulps
            span = np.maximum(np.abs(lo[finite]), np.abs(hi[finite])).max(axis=1, keepdims=True)
            pad = 64 * np.finfo(self.dtype).eps * span
            self._top = build_bvh(lo[finite] - pad, hi[finite] + pad,
                                  BuildParams(bins=self.build_params.bins))
        if len(bounded) > 1:
            self._top_slots, self._direct = bounded[self._top.order], visible[~finite]
        else:
            # A lone object is tested directly, like the planes: its own BVH or shape test culls
            # as well as a top-level box would, and a ray is spared a level of traversal.
            self._top_slots = np.zeros(0, np.int64)
            self._direct = np.concatenate([visible[~finite], bounded])
        self._assemble()
        self.build_seconds = time.perf_counter() - start
        return self

    def _assemble(self):
        """Pack the built trees and the object tables into the record the kernels read (after
        :meth:`build`, or after :func:`raycore.scene_file.load` restored what it built)."""
        dtype = self.dtype
        empty_nodes = np.zeros((0, NODE_WIDTH), np.float32)
        top_nodes = self._top.nodes if len(self._top_slots) else empty_nodes
        blocks = [m.leaf_blocks for m in self._meshes]
        mesh_nodes = _joined([m.bvh.nodes for m in self._meshes]) if blocks else empty_nodes
        all_blocks = _joined(blocks) if blocks else empty_blocks(0, dtype)
        table = np.array(self._params, dtype=dtype).reshape(-1, analytic.PARAM_WIDTH)
        record = new_record(
            top_nodes, top_nodes.view(np.int32), self._top_slots, self._direct,
            np.array(self._kind, np.int64), np.array(self._param_row, np.int64),
            np.array(self._mesh_of, np.int64), np.array(self._xform_row, np.int64),
            # None without shapes: their code then compiles away (analytic.table_hit)
            table if len(table) else None,
            np.array(self._xforms, dtype=dtype).reshape(-1, 12),
            mesh_nodes, mesh_nodes.view(np.int32),
            all_blocks,
            _starts([len(m.bvh.nodes) for m in self._meshes]), _starts([len(b) for b in blocks]),
            table,
        )
        record.tree_bytes = top_nodes.nbytes + mesh_nodes.nbytes + all_blocks.nbytes
        record.entry_points = queries.entry_points_for(record)
        self._record = record

    def _scene(self):
        """The built scene's record, built first if the scene changed (once, under a lock, when
        several threads query a scene that is not built yet)."""
        record = self._record
        if record is None:
            with self._build_lock:
                if self._record is None:
                    self.build()
                record = self._record
        return record

    @property
    def bounds(self):
        """(lo, hi): (3,) float64 bounds of the bounded objects (inf where empty)."""
        self._scene()
        if self._top is None:
            return np.full(3, np.inf), np.full(3, -np.inf)
        return self._top.lo.copy(), self._top.hi.copy()

    def stats(self):
        """Tree quality and memory: a dict with the top-level BVH's and each mesh's figures.

        Each BVH reports ``sah_cost``, ``depth``, ``nodes``, ``leaves`` and ``bytes``; meshes also
        report ``triangles`` and ``build_seconds``.
        """
        self._scene()

        def describe(bvh):
            if bvh is None:
                return None
            return {"sah_cost": bvh.sah_cost, "depth": bvh.depth, "nodes": bvh.node_count,
                    "leaves": bvh.leaf_count, "bytes": bvh.nbytes}

        meshes = [dict(describe(m.bvh), triangles=len(m.faces), build_seconds=m.build_seconds,
                       bytes=m.nbytes) for m in self._meshes]
        return {"top": describe(self._top), "meshes": meshes, "objects": len(self._kind),
                "bytes": sum(m["bytes"] for m in meshes)
                + (self._top.nbytes if self._top is not None else 0)}

    # ------------------------------------------------------------------ queries

    def intersect(self, origins, directions, tmin=0.0, tmax=np.inf, *,
                  triangle_test="watertight", sphere_method="precise", fields=()):
        """Closest hit of each ray.

        Parameters
        ----------
        origins, directions : array_like, shape (N, 3)
            Directions need not be unit length; t is in units of their length.
        tmin, tmax : float or array_like of shape (N,)
        triangle_test : {"watertight", "moller", "geometric"}
        sphere_method : {"precise", "geometric", "analytic"}
        fields : iterable of {"uv", "normal", "point", "shading_normal"}
            Surface data to compute besides t and the ids (see :class:`raycore.hits.Hits`).

        Returns
        -------
        Hits
        """
        return self._hits(origins, directions, tmin, tmax, triangle_test, sphere_method,
                          check_fields(fields))

    def _hits(self, origins, directions, tmin, tmax, triangle_test, sphere_method, fields,
              miss=np.nan):
        """:meth:`intersect` of checked ``fields``, with ``miss`` in the surface fields' rows of
        misses (:func:`raycore.queries.surface_fields`): the Open3D adapter's zeros."""
        rays, t, obj, prim, surface = self._closest_hits(
            origins, directions, tmin, tmax, triangle_test, sphere_method, bool(fields))
        if not fields:
            return Hits(t, obj, prim)
        u, v, slot = surface
        smooth = "shading_normal" in fields  # interpolated with u, v; normal where not a mesh
        uv, normal, point = queries.surface_fields(
            self._record, rays[0], rays[1], t, obj, slot, u, v, "uv" in fields,
            smooth or "normal" in fields, "point" in fields, miss)
        surface = {"uv": uv, "normal": normal, "point": point}
        if smooth:
            surface["shading_normal"] = self._shading_normals(obj, prim, u, v, normal)
        return Hits(t=t, geom_id=obj, prim_id=prim,
                    **{name: surface[name] for name in fields})

    def _closest_hits(self, origins, directions, tmin, tmax, triangle_test, sphere_method,
                      barycentrics, out=None):
        """``(rays, t, obj, prim, (u, v, slot))``: the rays as the kernels take them and
        :func:`raycore.queries.closest_hits` of them (the last item empty unless
        ``barycentrics``), into ``out`` as there; a ValueError naming what is wrong with a ray
        it refused."""
        test = triangle_test_code(triangle_test)
        method = analytic.sphere_method_code(sphere_method)
        rays = ray_arrays(origins, directions, tmin, tmax, self._kernel_dtype)
        first_bad, t, obj, prim, surface = queries.closest_hits(
            self._scene(), rays, test, method, barycentrics=barycentrics, out=out)
        if first_bad < len(rays[0]):  # the compiled pass refused a ray: say what is wrong
            refuse(origins, directions, tmin, tmax, self.dtype)
        return rays, t, obj, prim, surface

    def _shading_normals(self, geom_id, prim_id, u, v, normal):
        """:func:`raycore.shading.shading_normals` of hits."""
        return shading_normals(self._vertex_normal_tables(), geom_id, prim_id, u, v, normal)

    def _vertex_normal_tables(self):
        """The built scene's :class:`raycore.shading.NormalTables`, made once per build."""
        record = self._record
        if self._normal_tables is None or self._normal_tables[0] is not record:
            self._normal_tables = (record, NormalTables(
                self._meshes, self._kind, self._mesh_of, self._xform_row, self._xforms,
                self.dtype))
        return self._normal_tables[1]

    def _surface_hits(self, origins, directions, triangle_test, smooth, out=None):
        """Closest hits, and what a compiled pass over them computes their normals from
        (:func:`raycore.queries.hit_surface`, :func:`raycore.shading.interpolated_normal`):
        the render's, which would otherwise write them out and read them back.  ``out``: the
        arrays ``(t, geom_id, prim_id, u, v, slot)`` to write them to, as
        :func:`raycore.queries.closest_hits` takes them.

        Returns
        -------
        SurfaceHits
            ``tables`` empty unless ``smooth``.
        """
        rays, t, obj, prim, (u, v, slot) = self._closest_hits(
            origins, directions, 0.0, np.inf, triangle_test, "precise", True, out)
        tables = self._vertex_normal_tables() if smooth else NormalTables(
            [], [], [], [], [], self.dtype)
        return SurfaceHits(self._record, tables.arrays, rays[0], rays[1], t, obj, prim, u, v,
                           slot)

    def occluded(self, origins, directions, tmin=0.0, tmax=np.inf, *,
                 triangle_test="watertight", sphere_method="precise"):
        """(N,) bool: whether anything lies on each ray within [tmin, tmax] (stops at the first)."""
        test = triangle_test_code(triangle_test)
        method = analytic.sphere_method_code(sphere_method)
        rays = ray_arrays(origins, directions, tmin, tmax, self._kernel_dtype)
        first_bad, hit = queries.any_hits(self._scene(), rays, test, method)
        if first_bad < len(rays[0]):  # the compiled pass refused a ray: say what is wrong
            refuse(origins, directions, tmin, tmax, self.dtype)
        return hit

    def intersect_all(self, origins, directions, tmin=0.0, tmax=np.inf, *,
                      triangle_test="watertight", sphere_method="precise", max_hits=None):
        """Every surface crossing along each ray, sorted by (ray, t).

        A ray through an edge or vertex shared by several triangles of one mesh crosses the
        surface once and is reported once.

        Parameters
        ----------
        max_hits : int, optional
            Crossings the answer may list at most: more raise :class:`raycore.TooManyHits`
            (a ``ValueError``) once they are counted, before memory is taken for them.

        Returns
        -------
        AllHits
        """
        if max_hits is not None:
            integer(max_hits, "max_hits", 0, np.inf)
        test = triangle_test_code(triangle_test)
        method = analytic.sphere_method_code(sphere_method)
        rays = ray_arrays(origins, directions, tmin, tmax, self._kernel_dtype)
        first_bad, counts, t, obj, prim = queries.all_hits(self._scene(), rays, test, method,
                                                           max_hits)
        if first_bad < len(rays[0]):  # the compiled pass refused a ray: say what is wrong
            refuse(origins, directions, tmin, tmax, self.dtype)
        ray_index = np.arange(len(counts), dtype=np.int64).repeat(counts)
        return AllHits(ray_index=ray_index, t=t, geom_id=obj, prim_id=prim, counts=counts)

    def count(self, origins, directions, tmin=0.0, tmax=np.inf, *,
              triangle_test="watertight", sphere_method="precise"):
        """(N,) int64: number of surface crossings along each ray, counted as
        :meth:`intersect_all` lists them, without listing them."""
        test = triangle_test_code(triangle_test)
        method = analytic.sphere_method_code(sphere_method)
        rays = ray_arrays(origins, directions, tmin, tmax, self._kernel_dtype)
        first_bad, counts, _ = queries.crossing_counts(self._scene(), rays, test, method)
        if first_bad < len(rays[0]):  # the compiled pass refused a ray: say what is wrong
            refuse(origins, directions, tmin, tmax, self.dtype)
        return counts

    def contains(self, points):
        """(M,) bool: whether each point lies inside a closed object of the scene.

        Counts crossings of each closed object along three rays from the point; a point is inside
        an object when the count is odd, and the three rays vote.  Meant for closed (watertight)
        meshes and the closed analytic shapes; planes and disks enclose nothing and are ignored.
        """
        points = as_float_array(points, "points", self.dtype, (None, 3))
        scene = self._scene()
        votes = np.zeros(len(points), np.int64)
        directions = np.empty_like(points)
        for direction in _CONTAINS_DIRECTIONS:
            directions[:] = direction
            rays = ray_arrays(points, directions, 0.0, np.inf, self._kernel_dtype)
            _, odd = queries.odd_crossings(scene, rays, WATERTIGHT, sphere.PRECISE)
            votes += odd
        return votes >= 2

    # ------------------------------------------------------------------ files and pickling

    def save(self, path):
        """Write the built scene (built first if it changed) to one file at ``path``.

        The file holds the geometry, the trees and every table queries read, so that
        :meth:`load` skips the build; it is written to a temporary file, flushed and renamed,
        so that ``path`` never holds half a scene.  The format (:mod:`raycore.scene_file`) is
        a JSON header and aligned raw arrays with checksums; nothing in it is pickled.
        """
        scene_file.save(self, path)

    @classmethod
    def load(cls, path, *, mmap=False):
        """Read a scene that :meth:`save` wrote, ready for queries (no build).

        Parameters
        ----------
        path : str or path-like
        mmap : bool
            Map the file instead of reading it: its pages are read as queries touch them and
            shared between processes that map the same file.

        Raises
        ------
        ValueError
            When the file is not a raycore scene file, is truncated or corrupt (a checksum, or
            a reference a query would follow, is wrong), or has a newer format version.
        """
        return scene_file.load(path, mmap=mmap)

    def __reduce__(self):
        # one copy of every array, in the file format: a pickle is about the file's size
        return scene_file.load, (scene_file.dumps(self),)

    # ------------------------------------------------------------------ interop

    # Open3D's RaycastingScene calls, as thin adapters (raycore.integrations.open3d)
    cast_rays, count_intersections = _open3d.cast_rays, _open3d.count_intersections
    list_intersections, test_occlusions = _open3d.list_intersections, _open3d.test_occlusions
    create_rays_pinhole = staticmethod(_open3d.create_rays_pinhole)

    @classmethod
    def from_trimesh(cls, mesh_or_scene, dtype="float32", **build):
        """Build a Scene from a ``trimesh.Trimesh`` or a ``trimesh.Scene``.

        A trimesh Scene's geometries become meshes and its graph's placements become instances,
        so a geometry used many times is stored once.
        """
        import trimesh

        scene = cls(dtype=dtype, **build)
        if isinstance(mesh_or_scene, trimesh.Trimesh):
            scene.add_mesh(mesh_or_scene.vertices, mesh_or_scene.faces)
            return scene
        if not isinstance(mesh_or_scene, trimesh.Scene):
            raise ValueError("mesh_or_scene must be a trimesh.Trimesh or trimesh.Scene, "
                             f"got {type(mesh_or_scene).__name__}")
        prototypes = {}
        for node in mesh_or_scene.graph.nodes_geometry:
            transform, name = mesh_or_scene.graph[node]
            geometry = mesh_or_scene.geometry[name]
            if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
                continue
            if name not in prototypes:
                prototypes[name] = scene.add_mesh(geometry.vertices, geometry.faces,
                                                  visible=False)
            scene.add_instance(prototypes[name], transform)
        return scene

    @classmethod
    def from_file(cls, path, dtype="float32", **build):
        """Load a mesh file (OBJ, PLY, STL, OFF, GLB, ... through trimesh) into a Scene.

        Raises
        ------
        ValueError
            Naming ``path`` and the file, when it is not a path or trimesh cannot read it.
        """
        from raycore.mesh import load_trimesh

        if not isinstance(path, (str, os.PathLike)):
            # trimesh would take it as a file type it does not know
            raise ValueError(f"path must be a file path (str or os.PathLike), got "
                             f"{type(path).__name__}")
        try:
            loaded = load_trimesh(path)
        except ValueError as error:
            raise ValueError(f"path {os.fspath(path)!r}: {error}") from error
        return cls.from_trimesh(loaded, dtype=dtype, **build)


def check_scene(scene):
    """``scene`` if it answers as a :class:`Scene` does (a Scene, or a proxy of one, such as the
    benchmarks' timing wrappers), else ``ValueError`` naming it: functions that take a scene
    raised AttributeError on the first attribute they read."""
    if all(hasattr(scene, name) for name in ("dtype", "intersect", "occluded")):
        return scene
    raise ValueError(f"scene must be a raycore.Scene, got {type(scene).__name__}")


def _joined(parts):
    """The arrays ``parts`` (one or more, of one dtype and row shape) end to end, starting on a
    cache line; a lone one as it is (a copy of a large mesh's tree took as much memory again as
    the tree, and 0.38 s at 6.4M triangles)."""
    if len(parts) == 1:
        return parts[0]
    rows = sum(len(part) for part in parts)
    row = parts[0].shape[1:]
    joined = empty_on_line(rows * int(np.prod(row)), parts[0].dtype).reshape(rows, *row)
    return np.concatenate(parts, out=joined)


def _starts(sizes):
    """(len(sizes),) int64: where each of consecutive runs of ``sizes`` starts (summed in
    Python: np.cumsum of a short list took 6 us, a third of packing a one-mesh record)."""
    return np.array([0, *itertools.accumulate(sizes)][:-1], np.int64)

