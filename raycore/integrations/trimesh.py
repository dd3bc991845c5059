"""A drop-in for trimesh's ray intersectors: ``mesh.ray = RayMeshIntersector(mesh)``.

Every trimesh feature built on ``mesh.ray`` (``mesh.contains``, ``proximity.signed_distance``,
``proximity.longest_ray``, ray voxelization, ...) then runs on raycore.  The interface is that
of ``trimesh.ray.ray_pyembree.RayMeshIntersector``, method for method, with its return types,
shapes, dtypes and ordering.  Where trimesh's intersectors are known to be wrong, this one is
not:

- **Duplicate hits in multiple-hit mode** (trimesh #2504, #1097).  trimesh finds every hit with
  Embree by restarting each ray a fixed offset past its last hit; when the offset is swallowed
  by float32 rounding the ray re-hits the same face until ``max_hits``, and the crossing is
  reported up to ``max_hits`` times.  raycore lists every crossing in one traversal
  (:meth:`raycore.Scene.intersect_all`): each is reported once, and a crossing through a shared
  edge or vertex once, not once per face (trimesh's NumPy intersector reports it per face,
  trimesh #2317).
- **Misses on shared edges and vertices** (trimesh #1766, #1496).  Those reports, made with
  pyembree's Embree 2, show rays through an edge or vertex shared by several faces missing all
  of them (embreex's Embree 4 did not miss any of the edge- and vertex-aimed rays of this
  module's tests).  raycore's default triangle test (Woop, Benthin and Wald 2013) with
  conservative box tests never lets such a ray through, in either precision.
- **Precision at large coordinates** (trimesh #48, #1919).  Embree runs in float32 on
  coordinates scaled to a box of 100; hit points far from the origin lose digits.  This
  intersector runs in float64 by default (``dtype="float32"`` trades that for speed), and with
  ``scale_to_box`` moves the mesh's lower corner to the origin before the kernels see it, so
  that a mesh placed far from the origin keeps all of the precision of its own size.
- **Self-hits from surface origins** (trimesh #331, #48).  A ray that starts on the surface (a
  sampled point with its normal, a previous hit) re-hits that surface about half the time with
  Embree, and always with trimesh's NumPy intersector, which accepts hits 1e-6 behind the
  origin.  Here a hit closer to the origin than the rounding of the origin's coordinates (a few
  units in the last place of the larger of the origin's and the mesh's coordinates) cannot be
  told from the surface the ray starts on, and is not reported; nor is any hit behind the
  origin.  Rays leaving the surface at a grazing angle may still see it: move such origins off
  the surface with :func:`raycore.offset_ray_origin`.
- **Unstable contains** (trimesh #181, #242, #1097).  trimesh's ``contains_points`` casts two
  rays per point and re-casts disagreements along a random direction, so repeated calls can
  answer differently, and duplicate hits flip the parity.  Here it is
  :meth:`raycore.Scene.contains`: a majority of three fixed rays, each counting crossings once,
  the same answer on every call.

Differences a caller may notice: triangle indices are int64 everywhere (trimesh's Embree
intersector returns int32 from ``intersects_first``); a ray with a zero direction hits nothing,
as in trimesh, but NaN or infinite coordinates raise ``ValueError``.
"""

import numpy as np
import trimesh
from numba import njit
from trimesh import caching

from raycore.primitives.triangle import triangle_test_code
from raycore.rays import as_float_array, flag, integer
from raycore.scene import Scene

#: A hit within this many units in the last place of the origin's (or the mesh's) coordinates is
#: taken for the surface the ray starts on (see the module's notes on self-hits).
SELF_HIT_ULPS = 64

#: Size of the box trimesh's Embree intersector scales meshes to (``100 / mesh.scale``).
_BOX_SIZE = 100.0


class RayMeshIntersector:
    """Ray queries on a trimesh mesh, answered by raycore.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The mesh to cast rays at; the intersector follows its changes (trimesh's cache keys).
    scale_to_box : bool
        Move the mesh's lower corner to the origin and scale it to a box of about 100, as
        trimesh's Embree intersector does, before building raycore's scene.  Results are given
        in the mesh's own frame either way.
    **options
        ``dtype`` ("float64", the default, or "float32"), ``triangle_test`` ("watertight", the
        default, "moller" or "geometric"), and :class:`raycore.Scene`'s build parameters
        (``bins``, ``max_leaf_size``, ``traversal_cost``, ``intersection_cost``).

    Examples
    --------
    >>> import trimesh
    >>> mesh = trimesh.creation.box()
    >>> mesh.ray = RayMeshIntersector(mesh)
    >>> mesh.ray.intersects_first([[0, 0, 5]], [[0, 0, -1]]).tolist()
    [6]
    """

    def __init__(self, mesh, scale_to_box=True, **options):
        if not isinstance(mesh, trimesh.Trimesh):
            raise ValueError(f"mesh must be a trimesh.Trimesh, got {type(mesh).__name__}")
        self.mesh = mesh
        self._scale_to_box = flag(scale_to_box, "scale_to_box")
        self._triangle_test = options.pop("triangle_test", "watertight")
        triangle_test_code(self._triangle_test)  # refuse a bad name now, not at the first query
        self._scene_options = {"dtype": "float64", **options}
        try:
            Scene(**self._scene_options)
        except TypeError as error:
            raise ValueError(f"options: {error}") from None
        self._cache = caching.Cache(id_function=self.mesh.__hash__)

    # ------------------------------------------------------------------ the scene

    @caching.cache_decorator
    def _frame(self):
        """(origin (3,), scale): world point p is ``(p - origin) * scale`` in the scene."""
        if not self._scale_to_box or len(self.mesh.vertices) == 0:
            return np.zeros(3), 1.0
        scale = _BOX_SIZE / self.mesh.scale if self.mesh.scale > 0 else 1.0
        return np.asarray(self.mesh.vertices, np.float64).min(axis=0), float(scale)

    @caching.cache_decorator
    def _scene(self):
        """The raycore Scene of the mesh in the scene's frame, rebuilt when the mesh changes."""
        origin, scale = self._frame
        scene = Scene(**self._scene_options)
        vertices = (np.asarray(self.mesh.vertices, np.float64) - origin) * scale
        scene.add_mesh(vertices, np.asarray(self.mesh.faces, np.int64))
        return scene.build()

    @caching.cache_decorator
    def _reach(self):
        """(scene, world): the largest coordinate magnitude of the mesh in either frame."""
        if len(self.mesh.vertices) == 0:
            return 0.0, 0.0
        origin, scale = self._frame
        world = float(np.abs(self.mesh.bounds).max())
        return float(np.abs(self.mesh.bounds - origin).max()) * scale, world

    def _rays(self, ray_origins, ray_directions):
        """The rays in the scene's frame, with unit directions and self-hit bounds.

        Returns
        -------
        origins, directions : ndarray of float64, shape (N, 3)
            World origins and unit directions (zero where the direction was zero).
        usable : ndarray of int64, shape (U,)
            Rays with a non-zero direction; the others hit nothing, as in trimesh.
        local, local_directions : ndarray of float64, shape (U, 3)
            The usable rays in the scene's frame (which moves and scales, so that a unit
            direction stays one).
        tmin : ndarray of float64, shape (U,)
            Hits nearer than this (in the scene's frame) are the origin's own surface.
        """
        origins = as_float_array(ray_origins, "ray_origins", np.float64, (None, 3))
        directions = as_float_array(ray_directions, "ray_directions", np.float64, (None, 3))
        if origins.shape != directions.shape:
            raise ValueError(f"ray_origins and ray_directions must have the same shape, got "
                             f"{origins.shape} and {directions.shape}")
        origin, scale = self._frame
        scene_reach, world_reach = self._reach
        # the origin's own rounding, in the scene's precision and in the caller's float64
        scene_ulp = SELF_HIT_ULPS * float(np.finfo(self._scene.dtype).eps)
        world_ulp = SELF_HIT_ULPS * float(np.finfo(np.float64).eps) * scale
        units, local = np.empty_like(directions), np.empty_like(origins)
        tmin, moving = np.empty(len(origins)), np.empty(len(origins), bool)
        _in_scene_frame(origins, directions, origin, scale, scene_reach, world_reach,
                        scene_ulp, world_ulp, units, local, tmin, moving)
        usable = np.flatnonzero(moving)
        if len(usable) == len(origins):
            return origins, units, usable, local, units, tmin
        return origins, units, usable, local[usable], units[usable], tmin[usable]

    # ------------------------------------------------------------------ trimesh's interface

    def intersects_id(self, ray_origins, ray_directions, multiple_hits=True, max_hits=100,
                      return_locations=False):
        """Faces hit by each ray: the first, or every one along it.

        Parameters
        ----------
        ray_origins, ray_directions : array_like, shape (n, 3)
            Directions need not be unit length.
        multiple_hits : bool
            Every crossing along each ray (each once), or only the first.
        max_hits : int
            At most this many crossings per ray, the nearest.
        return_locations : bool
            Also return where each hit lies.

        Returns
        -------
        index_tri : ndarray of int64, shape (m,)
            Face of each hit.
        index_ray : ndarray of int64, shape (m,)
            Ray of each hit.  Hits come as trimesh's Embree intersector gives them: every ray's
            first hit (by ray), then every ray's second hit, and so on.
        locations : ndarray of float64, shape (m, 3)
            Hit points, only with ``return_locations``.
        """
        integer(max_hits, "max_hits", 0, np.inf)
        multiple_hits = flag(multiple_hits, "multiple_hits")
        return_locations = flag(return_locations, "return_locations")
        origins, directions, usable, local, local_directions, tmin = self._rays(ray_origins,
                                                                                 ray_directions)
        scene = self._scene
        if multiple_hits:
            hits = scene.intersect_all(local, local_directions, tmin,
                                       triangle_test=self._triangle_test)
            rank = np.arange(len(hits)) - hits.offsets[hits.ray_index]
            # trimesh's order: by depth along the ray, then by ray
            order = np.lexsort((hits.ray_index, rank))
            order = order[rank[order] < max_hits]
            rays, tri, t = hits.ray_index[order], hits.prim_id[order], hits.t[order]
        else:
            hits = scene.intersect(local, local_directions, tmin,
                                   triangle_test=self._triangle_test)
            rays = np.flatnonzero(hits.hit)
            tri, t = hits.prim_id[rays], hits.t[rays]
        index_ray = usable[rays].astype(np.int64)
        index_tri = tri.astype(np.int64)
        if not return_locations:
            return index_tri, index_ray
        distance = t.astype(np.float64) / self._frame[1]
        locations = origins[index_ray] + directions[index_ray] * distance[:, None]
        return index_tri, index_ray, locations

    def intersects_location(self, ray_origins, ray_directions, multiple_hits=True):
        """Where rays hit the mesh.

        Parameters
        ----------
        ray_origins, ray_directions : array_like, shape (n, 3)
        multiple_hits : bool
            Every crossing along each ray (each once), or only the first.

        Returns
        -------
        locations : ndarray of float64, shape (m, 3)
        index_ray : ndarray of int64, shape (m,)
        index_tri : ndarray of int64, shape (m,)
        """
        index_tri, index_ray, locations = self.intersects_id(
            ray_origins, ray_directions, multiple_hits=multiple_hits, return_locations=True)
        return locations, index_ray, index_tri

    def intersects_first(self, ray_origins, ray_directions):
        """(n,) int64: the first face each ray hits, -1 where it hits none."""
        origins, _, usable, local, local_directions, tmin = self._rays(ray_origins,
                                                                        ray_directions)
        first = np.full(len(origins), -1, np.int64)
        first[usable] = self._scene.intersect(local, local_directions, tmin,
                                              triangle_test=self._triangle_test).prim_id
        return first

    def intersects_any(self, ray_origins, ray_directions):
        """(n,) bool: whether each ray hits the mesh (stops at the first hit)."""
        origins, _, usable, local, local_directions, tmin = self._rays(ray_origins,
                                                                        ray_directions)
        hit = np.zeros(len(origins), bool)
        hit[usable] = self._scene.occluded(local, local_directions, tmin,
                                           triangle_test=self._triangle_test)
        return hit

    def contains_points(self, points):
        """(n,) bool: whether each point lies inside the (closed) mesh.

        A majority of three fixed rays, each counting crossings once
        (:meth:`raycore.Scene.contains`): the same answer on every call.  Points on the surface
        may go either way.
        """
        points = as_float_array(points, "points", np.float64, (None, 3))
        origin, scale = self._frame
        return self._scene.contains((points - origin) * scale)

    # ------------------------------------------------------------------ copies, as trimesh's

    def __getstate__(self):
        state = self.__dict__.copy()
        state.pop("_cache", None)  # the scene is rebuilt from the mesh, as trimesh's is
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._cache = caching.Cache(id_function=self.mesh.__hash__)

    def __copy__(self, *args):
        # trimesh's intersectors share the mesh in copies and deep copies alike
        return RayMeshIntersector(self.mesh, scale_to_box=self._scale_to_box,
                                  triangle_test=self._triangle_test, **self._scene_options)

    def __deepcopy__(self, *args):
        return self.__copy__()


@njit(cache=True, error_model="numpy")
def _in_scene_frame(origins, directions, origin, scale, scene_reach, world_reach, scene_ulp,
                    world_ulp, units, local, tmin, moving):
    """:meth:`RayMeshIntersector._rays` in one compiled pass: as NumPy expressions, its dozen
    passes over the rays took longer than tracing them (30 against 23 ms, 200k random rays in
    stanford-bunny).

    Fills ``units`` (unit directions, or the direction itself where its length rounds to 0),
    ``local`` (origins in the scene's frame), ``tmin`` (SELF_HIT_ULPS ulps of the larger of the
    origin's and the mesh's coordinates, in either frame, as ``scene_ulp`` and ``world_ulp``
    give them) and ``moving`` (whether the direction's length is above 0), all (N, ...).  The
    rays are finite (``as_float_array`` refuses others).
    """
    for i in range(len(origins)):
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        moving[i] = length > 0
        divisor = length if length > 0 else 1.0
        units[i, 0], units[i, 1], units[i, 2] = dx / divisor, dy / divisor, dz / divisor
        in_scene, in_world = scene_reach, world_reach
        for a in range(3):
            local[i, a] = (origins[i, a] - origin[a]) * scale
            in_scene = max(in_scene, abs(local[i, a]))
            in_world = max(in_world, abs(origins[i, a]))
        tmin[i] = scene_ulp * in_scene + world_ulp * in_world
