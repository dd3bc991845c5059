"""The engines raycore is checked against, behind one small interface, for accuracy work.

Each anchor is built from (V, 3) vertices and (F, 3) faces and answers closest-hit queries on
float32 rays with ``closest(origins, directions) -> (t, prim)``: t is inf and prim -1 where a
ray misses, whatever the library returns.  That normalisation (stacking, casting, masking) makes
the answers comparable, and costs time: never time ``closest``.  Throughput is measured on each
library's own call with inputs in its native form (``benchmarks.contenders``), except in the one
column of ``benchmarks/results/bench.md`` that shows how the former method (timing
:meth:`Open3D.closest`) inflated the ratios.
"""

import numpy as np

from benchmarks.contenders import (
    embreex_arrays,
    embreex_build,
    embreex_mesh,
    open3d_build,
    open3d_mesh,
    open3d_rays,
)


class Embree:
    """Embree 4 through embreex: one ``rtcIntersect1`` per ray, serial."""

    name = "embreex"

    def __init__(self, vertices, faces):
        self.scene = embreex_build(embreex_mesh(vertices, faces))

    def closest(self, origins, directions):
        out = self.scene.run(*embreex_arrays(origins, directions), output=1)
        t = np.where(out["geomID"] >= 0, out["tfar"], np.inf)
        return t, out["primID"].astype(np.int64)


class Open3D:
    """Open3D's RaycastingScene: Embree, multi-threaded over rays."""

    name = "open3d"

    def __init__(self, vertices, faces):
        self.scene = open3d_build(open3d_mesh(vertices, faces))

    def closest(self, origins, directions):
        return open3d_closest(self.scene, origins, directions)


def open3d_closest(scene, origins, directions):
    """(t, prim) of each ray from an Open3D RaycastingScene, normalised like every anchor's.

    This is also the former benchmark's timed region for Open3D (its "wrapper"): the rays'
    conversion to a Tensor, ``cast_rays``, and the outputs' conversion and masking; about 1.5x
    the time of ``cast_rays`` alone on camera rays.
    """
    out = scene.cast_rays(open3d_rays(origins, directions))
    t = out["t_hit"].numpy()
    prim = out["primitive_ids"].numpy().astype(np.int64)
    prim[~np.isfinite(t)] = -1
    return t, prim


class Trimesh:
    """trimesh's pure-NumPy intersector (``ray_triangle``): the slowest anchor, on a subsample."""

    name = "trimesh"

    def __init__(self, vertices, faces):
        import trimesh
        from trimesh.ray.ray_triangle import RayMeshIntersector

        self._mesh = trimesh.Trimesh(vertices, faces, process=False)
        self.intersector = RayMeshIntersector(self._mesh)
        self.closest(np.zeros((1, 3)), np.array([[1.0, 0, 0]]))

    def closest(self, origins, directions):
        index_tri, index_ray, locations = self.intersector.intersects_id(
            origins, directions, multiple_hits=False, return_locations=True)
        locations = np.asarray(locations).reshape(-1, 3)  # (0,) when nothing is hit
        t = np.full(len(origins), np.inf)
        prim = np.full(len(origins), -1, np.int64)
        t[index_ray] = np.einsum("ij,ij->i", locations - origins[index_ray],
                                 directions[index_ray]) / np.einsum(
            "ij,ij->i", directions[index_ray], directions[index_ray])
        prim[index_ray] = index_tri
        return t, prim


ANCHORS = (Embree, Open3D, Trimesh)
