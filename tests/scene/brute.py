"""Brute-force reference for Scene queries, and the comparisons the tests share.

The reference runs the per-primitive batch functions of :mod:`raycore.primitives` (one analytic
object, or one triangle, at a time over every ray) and never touches a BVH:

* analytic objects: ``analytic.intersect_<shape>`` gives the nearest root in ``[tmin, tmax]``; a
  second call from just past it gives the far root, for ``intersect_all``;
* meshes: ``triangle.intersect_triangles`` on every triangle, in the scene's precision;
* instances: the mesh's vertices are mapped to world space in float64, rounded to the scene's
  precision, and tested there (the library tests them in object space instead, so the two agree
  to a few ulps, and may disagree on hit/miss for rays within rounding distance of an edge:
  :meth:`SceneSpec.near_instance_edge` finds those rays).

Every candidate hit is kept (ray, t, geometry, primitive, uv, normal), sorted by (ray, t); the
closest hit, the any-hit and the merged list of crossings all derive from it
(:class:`Reference`), and :func:`compare_closest` / :func:`compare_all` hold the library's
answers against it.

Also here, shared by the test modules: the seeded scene of every kind of object and its rays
(:func:`random_scene`, :func:`scene_rays`, cached :func:`reference`), the shared meshes
(:func:`shared_mesh`, :func:`mesh_scene`), ray generators and the Embree and trimesh anchors.
"""

import functools
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import trimesh

from raycore import Hits, Scene
from raycore.primitives import analytic
from raycore.primitives.triangle import intersect_triangles

from .t_error import instance_tolerance

ANALYTIC = ("sphere", "plane", "disk", "box", "tbox", "cylinder", "cone")

_INTERSECT = {
    "sphere": analytic.intersect_sphere,
    "plane": analytic.intersect_plane,
    "disk": analytic.intersect_disk,
    "box": analytic.intersect_box,
    "tbox": analytic.intersect_transformed_box,
    "cylinder": analytic.intersect_cylinder,
    "cone": analytic.intersect_cone,
}


def eps(dtype):
    """Machine epsilon (2u) of a dtype-like, as a Python float."""
    return float(np.finfo(np.dtype(dtype)).eps)


@dataclass
class Obj:
    kind: str  # one of ANALYTIC, "mesh" or "instance"
    args: tuple = ()
    vertices: np.ndarray | None = None  # meshes: (V, 3) float64
    faces: np.ndarray | None = None  # meshes: (F, 3) int64
    visible: bool = True
    mesh: int = -1  # instances: geometry id of the mesh
    transform: np.ndarray | None = None  # instances: (4, 4) float64


@dataclass
class SceneSpec:
    """A scene described once and built twice: as a ``raycore.Scene`` and as brute force."""

    objects: list = field(default_factory=list)

    def _add(self, obj):
        self.objects.append(obj)
        return len(self.objects) - 1

    def sphere(self, center, radius):
        return self._add(Obj("sphere", (center, radius)))

    def plane(self, point, normal):
        return self._add(Obj("plane", (point, normal)))

    def disk(self, center, normal, radius):
        return self._add(Obj("disk", (center, normal, radius)))

    def box(self, lo, hi):
        return self._add(Obj("box", (lo, hi)))

    def tbox(self, lo, hi, transform):
        return self._add(Obj("tbox", (lo, hi, np.asarray(transform, np.float64))))

    def cylinder(self, p0, p1, radius):
        return self._add(Obj("cylinder", (p0, p1, radius)))

    def cone(self, base_center, apex, radius):
        return self._add(Obj("cone", (base_center, apex, radius)))

    def mesh(self, vertices, faces, visible=True):
        return self._add(Obj("mesh", vertices=np.asarray(vertices, np.float64),
                             faces=np.asarray(faces, np.int64), visible=visible))

    def instance(self, mesh, transform):
        assert self.objects[mesh].kind == "mesh"
        return self._add(Obj("instance", mesh=mesh,
                             transform=np.asarray(transform, np.float64)))

    # ------------------------------------------------------------------ the library's scene

    def scene(self, dtype, **build):
        """The same objects added to a ``raycore.Scene``; geometry ids equal indices here."""
        scene = Scene(dtype=dtype, **build)
        for index, obj in enumerate(self.objects):
            if obj.kind == "mesh":
                got = scene.add_mesh(obj.vertices, obj.faces, visible=obj.visible)
            elif obj.kind == "instance":
                got = scene.add_instance(obj.mesh, obj.transform)
            elif obj.kind == "tbox":
                got = scene.add_box(*obj.args)
            else:
                got = getattr(scene, "add_" + obj.kind)(*obj.args)
            assert got == index
        return scene

    # ------------------------------------------------------------------ geometry in world space

    def mesh_of(self, index):
        obj = self.objects[index]
        return self.objects[obj.mesh] if obj.kind == "instance" else obj

    def world_vertices(self, index):
        """(V, 3) float64 world-space vertices of mesh or instance ``index``."""
        obj = self.objects[index]
        mesh = self.mesh_of(index)
        if obj.kind == "instance":
            return apply_affine(obj.transform, mesh.vertices)
        return mesh.vertices

    def triangle_objects(self):
        """Geometry ids of the visible meshes and of the instances."""
        return [i for i, o in enumerate(self.objects)
                if (o.kind == "mesh" and o.visible) or o.kind == "instance"]

    def shared_vertex_keys(self, index, dtype):
        """(F, 3) int: faces of ``index``'s mesh renumbered so that vertices with equal
        coordinates (in ``dtype``) get equal numbers, as the library compares them."""
        mesh = self.mesh_of(index)
        _, canonical = np.unique(mesh.vertices.astype(dtype), axis=0, return_inverse=True)
        return canonical.reshape(-1)[mesh.faces]

    @property
    def radius(self):
        """Radius of a ball around the origin holding every bounded object (planes excluded)."""
        extent = 0.0
        for i, obj in enumerate(self.objects):
            if obj.kind in ("mesh", "instance"):
                if obj.kind == "mesh" and not obj.visible:
                    continue
                extent = max(extent, np.abs(self.world_vertices(i)).max())
            elif obj.kind != "plane":
                lo, hi = analytic.analytic_bounds(
                    ANALYTIC.index(obj.kind), _pack(obj))
                extent = max(extent, np.abs(lo).max(), np.abs(hi).max())
        return float(extent) * np.sqrt(3)

    # ------------------------------------------------------------------ brute force

    def reference(self, origins, directions, *, dtype, triangle_test="watertight",
                  sphere_method="precise", tmin=0.0, tmax=np.inf):
        """Every hit of every ray: a :class:`Reference`."""
        dtype = np.dtype(dtype).type
        origins = np.asarray(origins, np.float64)
        directions = np.asarray(directions, np.float64)
        n = len(origins)
        tmin = np.broadcast_to(np.asarray(tmin, np.float64), (n,)).astype(dtype)
        tmax = np.broadcast_to(np.asarray(tmax, np.float64), (n,)).astype(dtype)
        parts = []

        def keep(hits, geom, prim, instance, key=None):
            hit = np.flatnonzero(hits.t < np.inf)
            parts.append(dict(
                ray=hit, t=hits.t[hit].astype(np.float64),
                geom=np.full(len(hit), geom, np.int64),
                prim=np.full(len(hit), prim, np.int64),
                uv=hits.uv[hit].astype(np.float64), normal=hits.normal[hit].astype(np.float64),
                instance=np.full(len(hit), instance), bound=np.zeros(len(hit)),
                key=np.repeat(np.asarray(key if key is not None else [-1, -1, -1])[None],
                              len(hit), axis=0)))
            return hit

        for index, obj in enumerate(self.objects):
            if obj.kind in ANALYTIC:
                extra = {"method": sphere_method} if obj.kind == "sphere" else {}
                function = _INTERSECT[obj.kind]
                first = function(origins, directions, *obj.args, tmin=tmin, tmax=tmax,
                                 normal=True, uv=True, dtype=dtype, **extra)
                hit = keep(first, index, 0, False)
                if len(hit):
                    # the far root: a convex shape is crossed at most twice
                    beyond = np.nextafter(first.t[hit], dtype(np.inf))
                    second = function(origins[hit], directions[hit], *obj.args, tmin=beyond,
                                      tmax=tmax[hit], normal=True, uv=True, dtype=dtype,
                                      **extra)
                    again = np.flatnonzero(second.t < np.inf)
                    parts.append(dict(
                        ray=hit[again], t=second.t[again].astype(np.float64),
                        geom=np.full(len(again), index, np.int64),
                        prim=np.zeros(len(again), np.int64),
                        uv=second.uv[again].astype(np.float64),
                        normal=second.normal[again].astype(np.float64),
                        instance=np.zeros(len(again), bool), bound=np.zeros(len(again)),
                        key=np.full((len(again), 3), -1)))
        # every triangle of every visible mesh and instance, in world space, in dtype
        objects = self.triangle_objects()
        if objects:
            corners = np.concatenate([
                self.world_vertices(i).astype(dtype)[self.mesh_of(i).faces] for i in objects])
            sizes = [len(self.mesh_of(i).faces) for i in objects]
            geom = np.repeat(objects, sizes)
            prim = np.concatenate([np.arange(s) for s in sizes])
            key = np.concatenate([self.shared_vertex_keys(i, dtype) for i in objects])
            instance = np.repeat([self.objects[i].kind == "instance" for i in objects], sizes)
            ray, tri, hits = triangle_pairs(origins, directions, tmin, tmax, corners,
                                            triangle_test, dtype)
            t = hits.t.astype(np.float64)
            # instance hits: how far the library's object-space t may be from this one
            bound = np.zeros(len(tri))
            inst = np.flatnonzero(instance[tri])
            if len(inst):
                local = np.concatenate([self.mesh_of(i).vertices[self.mesh_of(i).faces]
                                        for i in objects])
                transforms = np.array([self.objects[g].transform for g in geom[tri[inst]]])
                # the rays as the scene's precision holds them
                o, d = (x[ray[inst]].astype(dtype).astype(np.float64)
                        for x in (origins, directions))
                bound[inst] = instance_tolerance(triangle_test, dtype, o, d, t[inst],
                                                 local[tri[inst]], transforms)
            parts.append(dict(ray=ray, t=t, geom=geom[tri], prim=prim[tri],
                              uv=hits.uv.astype(np.float64),
                              normal=hits.normal.astype(np.float64), instance=instance[tri],
                              bound=bound, key=key[tri]))
        merged = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
        order = np.lexsort((merged["t"], merged["ray"]))
        return Reference(n=n, dtype=dtype, radius=self.radius,
                         origins=origins.astype(dtype).astype(np.float64),
                         directions=directions.astype(dtype).astype(np.float64),
                         tmin=tmin, tmax=tmax,
                         **{name: value[order] for name, value in merged.items()})

    def near_instance_edge(self, origins, directions, tmin, tmax, dtype):
        """(N,) bool: rays that pass within rounding distance of an instance triangle's edge or
        reach one at a distance within rounding of ``tmin``/``tmax``, where object-space and
        world-space tests may legitimately disagree.

        Each instance triangle is grown and shrunk (about its incentre, so every edge moves by
        ``h``) and tested in float64: a ray is near an edge when the two answers differ.
        """
        origins = np.asarray(origins, np.float64)
        directions = np.asarray(directions, np.float64)
        n = len(origins)
        near = np.zeros(n, bool)
        if n == 0:
            return near
        e = eps(dtype)
        scale = self.radius + np.linalg.norm(origins, axis=1)
        h = 256 * e * scale  # (N,) absolute distance
        tmin = np.broadcast_to(np.asarray(tmin, np.float64), (n,))
        tmax = np.broadcast_to(np.asarray(tmax, np.float64), (n,))
        slack = h / np.linalg.norm(directions, axis=1)
        instances = [i for i in self.triangle_objects() if self.objects[i].kind == "instance"]
        if not instances:
            return near
        corners = np.concatenate([self.world_vertices(i)[self.mesh_of(i).faces]
                                  for i in instances])
        a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
        la = np.linalg.norm(b - c, axis=1)
        lb = np.linalg.norm(c - a, axis=1)
        lc = np.linalg.norm(a - b, axis=1)
        perimeter = la + lb + lc
        incentre = (la[:, None] * a + lb[:, None] * b + lc[:, None] * c) / perimeter[:, None]
        inradius = np.linalg.norm(np.cross(b - a, c - a), axis=1) / perimeter
        for r in range(n):
            # every edge moved out (grown) or in (shrunk) by h[r]
            grow = (1 + h[r] / inradius)[:, None, None]
            shrink = np.maximum(1 - h[r] / inradius, 0.0)[:, None, None]
            rays = (origins[r:r + 1], directions[r:r + 1], -np.inf, np.inf)
            _, _, grown = triangle_pairs(*rays, incentre[:, None] + (corners - incentre[:, None])
                                         * grow, "watertight", np.float64, misses=True)
            _, _, shrunk = triangle_pairs(*rays, incentre[:, None] + (corners - incentre[:, None])
                                          * shrink, "watertight", np.float64, misses=True)
            t = grown.t
            maybe = np.isfinite(t) & (t >= tmin[r] - slack[r]) & (t <= tmax[r] + slack[r])
            surely = np.isfinite(shrunk.t) & (shrunk.t >= tmin[r] + slack[r]) & (
                shrunk.t <= tmax[r] - slack[r])
            near[r] = np.any(maybe != surely)
        return near


def triangle_pairs(origins, directions, tmin, tmax, corners, test, dtype, misses=False,
                   chunk=1 << 19):
    """Test every ray against every triangle with ``intersect_triangles`` (pairwise mode: the
    same kernel as one triangle at a time over all rays, with fewer calls).

    Parameters
    ----------
    origins, directions : (N, 3); tmin, tmax : scalar or (N,)
    corners : (T, 3, 3) triangle vertices

    Returns
    -------
    ray, tri : (H,) int64
        The pairs that hit (every pair, ray-major within a triangle, when ``misses``).
    hits : Hits
        Their t, uv and normal.
    """
    n, count = len(origins), len(corners)
    tmin = np.broadcast_to(np.asarray(tmin, np.float64), (n,))
    tmax = np.broadcast_to(np.asarray(tmax, np.float64), (n,))
    per = max(1, chunk // max(n, 1))
    rays, tris, ts, uvs, normals = [], [], [], [], []
    for start in range(0, count, per):
        block = corners[start:start + per]
        m = len(block)
        ray = np.tile(np.arange(n), m)
        tri = np.repeat(np.arange(start, start + m), n)
        v = np.repeat(block, n, axis=0)
        hits = intersect_triangles(origins[ray], directions[ray], v[:, 0], v[:, 1], v[:, 2],
                                   test=test, tmin=tmin[ray], tmax=tmax[ray], uv=True,
                                   normal=True, dtype=dtype)
        keep = slice(None) if misses else np.flatnonzero(hits.t < np.inf)
        rays.append(ray[keep])
        tris.append(tri[keep])
        ts.append(hits.t[keep])
        uvs.append(hits.uv[keep])
        normals.append(hits.normal[keep])
    return (np.concatenate(rays), np.concatenate(tris),
            Hits(t=np.concatenate(ts), geom_id=None, prim_id=None, uv=np.concatenate(uvs),
                 normal=np.concatenate(normals)))


def _pack(obj):
    packers = {"sphere": analytic.pack_sphere, "plane": analytic.pack_plane,
               "disk": analytic.pack_disk, "box": analytic.pack_box,
               "tbox": analytic.pack_transformed_box, "cylinder": analytic.pack_cylinder,
               "cone": analytic.pack_cone}
    return packers[obj.kind](*obj.args)


@dataclass
class Reference:
    """Every candidate hit of a ray batch, sorted by (ray, t)."""

    n: int
    dtype: type
    radius: float  # of the scene's bounded objects
    origins: np.ndarray  # (N, 3) float64 copies of the rays as the dtype sees them
    directions: np.ndarray
    tmin: np.ndarray
    tmax: np.ndarray
    ray: np.ndarray  # (H,) the candidates
    t: np.ndarray
    geom: np.ndarray
    prim: np.ndarray
    uv: np.ndarray
    normal: np.ndarray
    instance: np.ndarray  # (H,) bool: found on an instance (world-space) triangle
    bound: np.ndarray  # (H,) on instances, |Δt| allowed to the library (t_error.py); else 0
    key: np.ndarray  # (H, 3) shared-vertex keys of mesh triangles, -1 for analytic shapes

    @property
    def offsets(self):
        return np.searchsorted(self.ray, np.arange(self.n + 1))

    @property
    def counts(self):
        """(N,) candidate hits per ray, before merging shared-edge duplicates."""
        return np.bincount(self.ray, minlength=self.n)

    def candidate_tolerance(self):
        """(H,) |Δt| allowed for each candidate: on instances, the bound derived in t_error.py
        (the library tests them in object space); elsewhere the library runs the same kernel on
        the same numbers, and a few ulps are allowed."""
        return np.where(self.instance, self.bound, 4 * eps(self.dtype) * np.abs(self.t)) + 1e-300

    def closest(self):
        """Index of each ray's first candidate (-1: miss) and its t (inf: miss)."""
        offsets = self.offsets
        hit = offsets[1:] > offsets[:-1]
        first = np.where(hit, offsets[:-1], -1)
        t = np.full(self.n, np.inf)
        t[hit] = self.t[first[hit]]
        return first, t

    def ties(self):
        """(N,) whether the closest candidate's t is within tolerance of the runner-up's (of a
        different primitive), so that which one is reported is not determined."""
        first, _ = self.closest()
        tol = self.candidate_tolerance()
        tied = np.zeros(self.n, bool)
        nxt = first + 1
        ok = (first >= 0) & (nxt < len(self.ray))
        ok[ok] = self.ray[nxt[ok]] == np.flatnonzero(ok)
        rays = np.flatnonzero(ok)
        gap = self.t[first[rays] + 1] - self.t[first[rays]]
        tied[rays] = gap <= tol[first[rays]] + tol[first[rays] + 1]
        return tied

    def merged(self):
        """Crossings after merging the hits of one mesh at one point (a shared edge or vertex).

        Two candidates merge when they lie on the same mesh object, their triangles share a
        vertex (by coordinates) and their t agree to √u relative (u the unit roundoff): a ray
        through an edge or a vertex crosses the surface once.  Returns ``(keep, counts)``: a mask
        over candidates and the (N,) number of crossings per ray.
        """
        keep = np.ones(len(self.t), bool)
        close = np.sqrt(eps(self.dtype) / 2)  # √u, u the unit roundoff
        # only rays holding two mesh hits of one object within the merge distance need a look
        pair = (self.ray[1:] == self.ray[:-1]) & (
            self.t[1:] - self.t[:-1] <= close * np.abs(self.t[1:]))
        offsets = self.offsets
        for r in np.unique(self.ray[1:][pair]):
            kept = []
            for j in range(offsets[r], offsets[r + 1]):
                duplicate = False
                if self.key[j, 0] >= 0:
                    for k in reversed(kept):
                        if self.t[j] - self.t[k] > close * abs(self.t[j]):
                            break
                        if self.geom[k] == self.geom[j] and np.intersect1d(
                                self.key[k], self.key[j]).size:
                            duplicate = True
                            break
                if duplicate:
                    keep[j] = False
                else:
                    kept.append(j)
        counts = np.bincount(self.ray[keep], minlength=self.n)
        return keep, counts


# ---------------------------------------------------------------------- comparisons


def compare_closest(hits, ref, spec=None, fields=()):
    """Assert that ``hits`` (``Scene.intersect``) agrees with the reference.

    Hit/miss must agree on every ray, and the ids must be those of the closest candidate, or of
    one tied with it, with t within that candidate's tolerance; rays that pass within rounding
    distance of an instance's edge (found by ``spec.near_instance_edge``) are excused.  Returns
    the number of rays excused.
    """
    first, t_ref = ref.closest()
    tol = ref.candidate_tolerance()
    got_hit = hits.geom_id >= 0
    ref_hit = first >= 0
    assert np.all(np.isfinite(hits.t[got_hit])), "a hit came back with a non-finite t"
    assert np.all(hits.t[~got_hit] == np.inf) and np.all(hits.prim_id[~got_hit] == -1)
    # the reported (geom, prim) must be a candidate whose t is within its tolerance of the
    # library's, and which may be the closest: within the two tolerances of the reference's
    # closest (candidates closer than that may come in either order)
    bad = got_hit != ref_hit
    both = np.flatnonzero(got_hit & ref_hit)
    offsets = ref.offsets
    ok_ids = np.zeros(len(both), bool)
    for slot in range(8):
        j = first[both] + slot
        inside = j < offsets[both + 1]
        j = np.where(inside, j, 0)
        near = inside & (ref.t[j] - ref.t[first[both]] <= tol[j] + tol[first[both]])
        same = (ref.geom[j] == hits.geom_id[both]) & (ref.prim[j] == hits.prim_id[both])
        ok_ids |= near & same & (np.abs(hits.t[both] - ref.t[j]) <= tol[j])
    bad[both] |= ~ok_ids
    excused = np.zeros(ref.n, bool)
    if bad.any() and spec is not None:
        rays = np.flatnonzero(bad)
        excused[rays] = spec.near_instance_edge(ref.origins[rays], ref.directions[rays],
                                                ref.tmin[rays], ref.tmax[rays], ref.dtype)
    wrong = np.flatnonzero(bad & ~excused)
    assert len(wrong) == 0, describe_mismatch(wrong, hits, ref)
    # surface fields where the reported primitive is the reference's best, not on excused rays
    same = both[ok_ids & ~excused[both]]
    same = same[(hits.geom_id[same] == ref.geom[first[same]])
                & (hits.prim_id[same] == ref.prim[first[same]])]
    inst = ref.instance[first[same]]
    e = eps(ref.dtype)
    if "point" in fields:
        expect = ref.origins[same] + t_ref[same, None] * ref.directions[same]
        scale = np.abs(ref.origins[same]).max(axis=1) + np.abs(expect).max(axis=1)
        err = np.abs(hits.point[same] - expect).max(axis=1)
        assert np.all(err <= np.where(inst, 32, 8) * e * scale), "hit points differ"
        assert np.all(np.isnan(hits.point[~got_hit]))
    if "uv" in fields:
        err = np.abs(hits.uv[same] - ref.uv[first[same]]).max(axis=1)
        # barycentrics of instances come from object-space edge functions: relative to the
        # triangle, the rounding of the ray is amplified by (scene size / triangle size)
        limit = np.where(inst, 4e-4 if ref.dtype == np.float32 else 1e-12, 16 * e)
        assert np.all(err <= limit), f"uv differ by up to {err.max():.3g}"
        assert np.all(np.isnan(hits.uv[~got_hit]))
    if "normal" in fields:
        err = np.abs(hits.normal[same] - ref.normal[first[same]]).max(axis=1)
        limit = np.where(inst, 4e-5 if ref.dtype == np.float32 else 1e-13, 16 * e)
        assert np.all(err <= limit), f"normals differ by up to {err.max():.3g}"
        length = np.linalg.norm(hits.normal[got_hit], axis=1)
        assert np.all(np.abs(length - 1) <= 8 * e)
        assert np.all(np.isnan(hits.normal[~got_hit]))
    return int(excused.sum())


def compare_all(all_hits, ref, spec=None):
    """Assert that ``Scene.intersect_all`` gives the reference's merged crossings.

    Per ray: the same number of crossings, the same t (sorted) within tolerance and the same
    multiset of geometry ids.  Rays near an instance edge are excused (returned as a count).
    """
    keep, counts = ref.merged()
    tol = ref.candidate_tolerance()[keep]
    got_offsets = all_hits.offsets
    assert np.array_equal(all_hits.ray_index, np.repeat(np.arange(ref.n), all_hits.counts))
    bad = all_hits.counts != counts
    ref_ray, ref_t, ref_geom = ref.ray[keep], ref.t[keep], ref.geom[keep]
    ref_offsets = np.searchsorted(ref_ray, np.arange(ref.n + 1))
    same = np.flatnonzero(~bad & (counts > 0))
    # compare sorted t lists slot by slot, for every ray at once
    for slot in range(int(counts.max(initial=0))):
        rays = same[counts[same] > slot]
        a = all_hits.t[got_offsets[rays] + slot]
        b = ref_t[ref_offsets[rays] + slot]
        bad[rays] |= np.abs(a - b) > tol[ref_offsets[rays] + slot]
    # t sorted non-decreasing per ray
    inner = all_hits.ray_index[1:] == all_hits.ray_index[:-1]
    assert np.all(all_hits.t[1:][inner] >= all_hits.t[:-1][inner]), "hits not sorted by t"
    assert np.all(np.isfinite(all_hits.t))
    # geometry multisets
    got_key = np.sort(all_hits.ray_index * (1 << 20) + all_hits.geom_id)
    ref_key = np.sort(ref_ray * (1 << 20) + ref_geom)
    if len(got_key) == len(ref_key):
        diff = got_key != ref_key
        bad[(got_key[diff] >> 20)] = True
        bad[(ref_key[diff] >> 20)] = True
    excused = np.zeros(ref.n, bool)
    if bad.any() and spec is not None:
        rays = np.flatnonzero(bad)
        excused[rays] = spec.near_instance_edge(ref.origins[rays], ref.directions[rays],
                                                ref.tmin[rays], ref.tmax[rays], ref.dtype)
    wrong = np.flatnonzero(bad & ~excused)
    if len(wrong):
        r = wrong[0]
        raise AssertionError(
            f"{len(wrong)} of {ref.n} rays differ from brute force; first: ray {r}, "
            f"o={ref.origins[r].tolist()} d={ref.directions[r].tolist()} "
            f"tmin={ref.tmin[r]} tmax={ref.tmax[r]}\n"
            f"  got t={all_hits.t[got_offsets[r]:got_offsets[r + 1]].tolist()} "
            f"geom={all_hits.geom_id[got_offsets[r]:got_offsets[r + 1]].tolist()}\n"
            f"  expected t={ref_t[ref_offsets[r]:ref_offsets[r + 1]].tolist()} "
            f"geom={ref_geom[ref_offsets[r]:ref_offsets[r + 1]].tolist()}")
    return int(excused.sum())


def describe_mismatch(wrong, hits, ref):
    r = wrong[0]
    offsets = ref.offsets
    span = slice(offsets[r], min(offsets[r + 1], offsets[r] + 4))
    return (f"{len(wrong)} of {ref.n} rays differ from brute force; first: ray {r}, "
            f"o={ref.origins[r].tolist()} d={ref.directions[r].tolist()} "
            f"tmin={ref.tmin[r]} tmax={ref.tmax[r]}: got t={hits.t[r]!r} "
            f"geom={hits.geom_id[r]} prim={hits.prim_id[r]}; expected t={ref.t[span].tolist()} "
            f"geom={ref.geom[span].tolist()} prim={ref.prim[span].tolist()}")


# ---------------------------------------------------------------------- scenes and rays

MESH_DIR = Path(__file__).resolve().parents[3] / "shared" / "meshes"
MESH_NAMES = ("stanford-bunny", "nefertiti", "fandisk", "spot", "teapot", "suzanne")
CLOSED_MESHES = ("nefertiti", "fandisk")

DTYPES = ("float32", "float64")

#: (triangle_test, sphere_method) pairs: each triangle test, and each sphere method once.
METHODS = (("watertight", "precise"), ("moller", "precise"), ("geometric", "precise"),
           ("watertight", "geometric"), ("watertight", "analytic"))


def quantize(x, step=2.0**-8):
    return np.round(np.asarray(x, np.float64) / step) * step


def random_rotation(rng):
    """A random rotation: Gram–Schmidt on the columns of a Gaussian matrix (which is QR with a
    positive diagonal in R), the first column negated when its determinant is negative.

    Written with elementwise NumPy only: ``np.linalg.qr`` and ``@`` run OpenBLAS kernels whose
    last bits differ between CPUs (AVX2, AVX-512), and so did the scenes built from them.
    """
    a = rng.normal(size=(3, 3))
    q0 = unit(a[:, 0])
    q1 = a[:, 1] - _dot(q0, a[:, 1]) * q0
    q1 = unit(q1)
    if _dot(a[:, 0], _cross(a[:, 1], a[:, 2])) < 0:
        q0 = -q0
    return np.stack([q0, q1, _cross(q0, q1)], axis=1)


def random_affine(rng, lo=0.5, hi=1.5, spread=7.0):
    """A rotation, a non-uniform scale and a translation, as a 4x4 matrix."""
    m = np.eye(4)
    m[:3, :3] = _matmul(random_rotation(rng) * rng.uniform(lo, hi, 3), random_rotation(rng))
    m[:3, 3] = rng.uniform(-spread, spread, 3)
    return m


def _dot(a, b):
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def _cross(a, b):
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _matmul(a, b):
    """``a @ b`` for 3x3 matrices, each entry summed left to right (the same bits everywhere)."""
    return (a[:, :1] * b[0] + a[:, 1:2] * b[1]) + a[:, 2:] * b[2]


def apply_affine(m, points):
    """``points @ m[:3, :3].T + m[:3, 3]``, each coordinate ``((m0 x + m1 y) + m2 z) + m3``: the
    same bits on every CPU, and within γ(4)·(|L| |p| + |t|) of the exact value."""
    return ((points[..., :1] * m[:3, 0] + points[..., 1:2] * m[:3, 1])
            + points[..., 2:] * m[:3, 2]) + m[:3, 3]


def exact_inverse(m):
    """(3, 4) float64 ``[L⁻¹ | -L⁻¹ t]`` of a 4x4 affine matrix, computed in rational arithmetic
    and rounded once."""
    (a, b, c, p), (d, e, f, q), (g, h, i, r) = [[Fraction(x) for x in row]
                                                for row in np.asarray(m)[:3].tolist()]
    adj = [[e * i - f * h, c * h - b * i, b * f - c * e], [f * g - d * i, a * i - c * g,
                                                           c * d - a * f],
           [d * h - e * g, b * g - a * h, a * e - b * d]]
    det = a * adj[0][0] + b * adj[1][0] + c * adj[2][0]
    return np.array([[float(x / det) for x in row] + [float(-(row[0] * p + row[1] * q
                                                               + row[2] * r) / det)]
                     for row in adj])


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.sqrt(_dot(v, v))[..., None]


def edge_points(vertices, faces, rng, count, m=3):
    """Points ``v + k/2^m (w - v)`` on random edges (k in 1 .. 2^m - 1) and some vertices."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    pick = edges[rng.integers(0, len(edges), count)]
    k = rng.integers(1, 2**m, count)[:, None] / 2.0**m
    v, w = vertices[pick[:, 0]], vertices[pick[:, 1]]
    on_edges = v + k * (w - v)
    corners = vertices[np.unique(faces)][rng.integers(0, len(np.unique(faces)), count // 3)]
    return np.concatenate([on_edges, corners])


@functools.cache
def random_scene(seed=0):
    """A seeded scene of 37 objects of every kind, and points worth aiming rays at.

    Returns
    -------
    spec : SceneSpec
    targets : ndarray, shape (T, 3)
        Exact (dyadic) points on edges and at vertices of the visible meshes and of the
        translated instance, at corners and edges of axis-aligned boxes, at cone apexes.
    """
    rng = np.random.default_rng(seed)
    spec = SceneSpec()
    targets = []

    def place():
        return quantize(rng.uniform(-8, 8, 3), 2.0**-4)

    spec.plane([0.0, -12.0, 0.0], [0.1, 1.0, 0.05])
    for _ in range(6):
        spec.sphere(place(), rng.uniform(0.4, 1.8))
    for _ in range(4):
        spec.disk(place(), rng.normal(size=3), rng.uniform(0.5, 1.5))
    for _ in range(4):
        lo = place()
        hi = lo + quantize(rng.uniform(0.3, 2.5, 3), 2.0**-4)
        spec.box(lo, hi)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        targets.append(corners)
        targets.append((corners[[0, 0, 0, 7, 7, 7]] + corners[[1, 2, 4, 6, 5, 3]]) / 2)
    for _ in range(3):
        spec.tbox(-rng.uniform(0.2, 1, 3), rng.uniform(0.2, 1, 3), random_affine(rng))
    for _ in range(3):
        p0 = place()
        spec.cylinder(p0, p0 + rng.normal(size=3) * 1.5, rng.uniform(0.3, 1.0))
    for _ in range(3):
        base = place()
        apex = base + quantize(rng.normal(size=3) * 1.5, 2.0**-4)
        spec.cone(base, apex, rng.uniform(0.3, 1.0))
        targets.append(apex[None])

    def visible_mesh(mesh, scale):
        vertices = quantize(mesh.vertices * scale + place())
        index = spec.mesh(vertices, mesh.faces)
        targets.append(edge_points(vertices, mesh.faces, rng, 90))
        return index

    icosphere = trimesh.creation.icosphere(subdivisions=2)
    capsule = trimesh.creation.capsule(height=1.5, radius=0.6, count=[8, 8])
    visible_mesh(icosphere, 1.6)
    box_mesh = visible_mesh(trimesh.creation.box(extents=[1.5, 1.0, 2.0]), 1.0)
    visible_mesh(capsule, 1.0)
    soup = rng.uniform(-1.5, 1.5, (40, 3, 3))
    visible_mesh(trimesh.Trimesh(soup.reshape(-1, 3), np.arange(120).reshape(40, 3),
                                 process=False), 1.0)

    # prototypes shown only through instances
    ico = spec.mesh(quantize(icosphere.vertices), icosphere.faces, visible=False)
    cap = spec.mesh(quantize(capsule.vertices), capsule.faces, visible=False)
    for _ in range(4):
        spec.instance(ico, random_affine(rng))
    spec.instance(cap, random_affine(rng, 0.8, 2.0))
    spec.instance(box_mesh, random_affine(rng))
    # an exact placement (dyadic translation): aimed rays pass exactly through its edges
    shift = np.eye(4)
    shift[:3, 3] = place()
    exact = spec.instance(ico, shift)
    targets.append(edge_points(spec.world_vertices(exact), icosphere.faces, rng, 60))
    return spec, np.concatenate(targets)


@functools.cache
def scene_rays(seed=0, count=2400):
    """Rays for :func:`random_scene`: ``(origins, directions, tmin, tmax, aimed)``.

    ``aimed`` marks the rays aimed exactly at targets (tmin 0, tmax inf).  Of the others, some
    start outside and aim into the scene, some start inside with random directions, some miss
    on purpose, and a fifth have a random tmin or a finite tmax.
    """
    spec, targets = random_scene(seed)
    rng = np.random.default_rng(seed + 1000)
    reach = 1.3 * spec.radius
    n_in = count // 2
    n_inside = count // 6
    n_out = count - n_in - n_inside
    # from a sphere around the scene towards points inside it, a third near instances
    o1 = unit(rng.normal(size=(n_in, 3))) * reach
    aim = rng.uniform(-9, 9, (n_in, 3))
    placed = np.array([o.transform[:3, 3] for o in spec.objects if o.kind == "instance"])
    near = rng.random(n_in) < 1 / 3
    aim[near] = placed[rng.integers(0, len(placed), near.sum())] + rng.normal(
        size=(near.sum(), 3))
    d1 = aim - o1
    # from inside, any direction
    o2 = rng.uniform(-9, 9, (n_inside, 3))
    d2 = rng.normal(size=(n_inside, 3))
    # from outside, any direction (many miss)
    o3 = unit(rng.normal(size=(n_out, 3))) * reach
    d3 = rng.normal(size=(n_out, 3))
    origins = np.concatenate([o1, o2, o3])
    directions = np.concatenate([d1, d2, d3])
    n = len(origins)
    tmin = np.zeros(n)
    tmax = np.full(n, np.inf)
    scale = np.linalg.norm(origins, axis=1) / np.linalg.norm(directions, axis=1)
    which = rng.random(n)
    low = which < 0.1
    tmin[low] = rng.uniform(0, 1.5, low.sum()) * scale[low]
    high = (which >= 0.1) & (which < 0.2)
    tmax[high] = rng.uniform(0.3, 2, high.sum()) * scale[high]
    # aimed rays: dyadic origins, so that target - origin is exact in float32
    ao = quantize(unit(rng.normal(size=(len(targets), 3))) * reach, 2.0**-2)
    ad = targets - ao
    assert np.all(ad.astype(np.float32) == ad), "aimed directions must be exact in float32"
    origins = np.concatenate([origins, ao])
    directions = np.concatenate([directions, ad])
    tmin = np.concatenate([tmin, np.zeros(len(ao))])
    tmax = np.concatenate([tmax, np.full(len(ao), np.inf)])
    aimed = np.concatenate([np.zeros(n, bool), np.ones(len(ao), bool)])
    # cached and shared: callers must not modify them (they are not made read-only, because
    # Numba compiles separate kernels for read-only arrays)
    return origins, directions, tmin, tmax, aimed


@functools.cache
def reference(seed, dtype, triangle_test, sphere_method):
    """Brute-force answers for :func:`scene_rays` (cached: several tests share them)."""
    spec, _ = random_scene(seed)
    origins, directions, tmin, tmax, _ = scene_rays(seed)
    return spec.reference(origins, directions, dtype=dtype, triangle_test=triangle_test,
                          sphere_method=sphere_method, tmin=tmin, tmax=tmax)


@functools.cache
def shared_mesh(name):
    """A mesh of ../shared/meshes as loaded by trimesh (no processing: the file's own faces)."""
    path = MESH_DIR / f"{name}.obj"
    if not path.exists():
        pytest.skip(f"{path} is not there (the shared/ folder beside the repository)")
    return trimesh.load(path, force="mesh", process=False)


@functools.cache
def mesh_scene(name, dtype):
    """A Scene holding one shared mesh (cached: building nefertiti's BVH takes a while)."""
    mesh = shared_mesh(name)
    scene = Scene(dtype=dtype)
    scene.add_mesh(mesh.vertices, mesh.faces)
    return scene


def camera_rays(vertices, count, rng, views=3, aim=None, telephoto=False):
    """Perspective camera rays from ``views`` viewpoints outside the bounds; unit directions.

    Each view is a pixel grid covering the middle of the bounding sphere, from 2.5 radii away
    in a random direction; or, when ``aim`` ((M, 3) points) is given, rays towards points of
    ``aim`` picked at random.  ``telephoto`` puts the eyes 20 radii away, near the coordinate
    axes (3 degrees off), so that each ray's bounding box is thin: trimesh's intersector
    tests every triangle in that box.
    """
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    side = int(np.ceil(np.sqrt(count / views)))
    origins, directions = [], []
    for view in range(views):
        if telephoto:
            axis = np.zeros(3)
            axis[view % 3] = rng.choice([-1.0, 1.0])
            eye = centre + unit(axis + rng.normal(scale=0.05, size=3)) * 20 * radius
        else:
            eye = centre + unit(rng.normal(size=3)) * 2.5 * radius
        if aim is not None:
            d = aim[rng.integers(0, len(aim), side * side)] - eye
        else:
            forward = unit(centre - eye)
            right = unit(np.cross(forward, rng.normal(size=3)))
            up = np.cross(right, forward)
            x, y = np.meshgrid(np.linspace(-0.3, 0.3, side), np.linspace(-0.3, 0.3, side))
            d = forward + x.reshape(-1, 1) * right + y.reshape(-1, 1) * up
        directions.append(unit(d))
        origins.append(np.repeat(eye[None], len(d), axis=0))
    return np.concatenate(origins), np.concatenate(directions)


def inside_rays(vertices, count, rng):
    """Rays from uniform points inside the bounds, in uniform random directions."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return rng.uniform(lo, hi, (count, 3)), unit(rng.normal(size=(count, 3)))


def embree_closest(vertices, faces, origins, directions):
    """Closest hits by Embree (embreex, float32): ``(t, prim)``, inf / -1 where missed."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(vertices[faces], np.float32))
    out = scene.run(np.ascontiguousarray(origins, np.float32),
                    np.ascontiguousarray(directions, np.float32), output=1)
    hit = out["geomID"] >= 0
    return np.where(hit, out["tfar"], np.inf), np.where(hit, out["primID"], -1).astype(np.int64)


def trimesh_closest(mesh, origins, directions):
    """Closest hits by trimesh's pure-NumPy intersector (float64): ``(t, prim)``."""
    from trimesh.ray.ray_triangle import RayMeshIntersector

    index_tri, index_ray, locations = RayMeshIntersector(mesh).intersects_id(
        origins, directions, multiple_hits=False, return_locations=True)
    t = np.full(len(origins), np.inf)
    prim = np.full(len(origins), -1, np.int64)
    d = directions[index_ray]
    t[index_ray] = np.einsum("ij,ij->i", locations - origins[index_ray], d) / np.einsum(
        "ij,ij->i", d, d)
    prim[index_ray] = index_tri
    return t, prim
