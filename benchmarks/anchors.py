"""The engines raycore is measured against, behind one small interface.

Each anchor is built from (V, 3) vertices and (F, 3) faces and answers closest-hit queries on
float32 rays; building and querying are timed separately by the caller.
"""

import numpy as np


class Embree:
    """Embree 4 through embreex: one ``rtcIntersect1`` per ray, serial."""

    name = "embreex"

    def __init__(self, vertices, faces):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, np.ascontiguousarray(vertices[faces], np.float32))
        # Embree commits the scene on the first query: include it in the build
        self.closest(np.zeros((1, 3), np.float32), np.array([[1.0, 0, 0]], np.float32))

    def closest(self, origins, directions):
        out = self._scene.run(origins, directions, output=1)
        t = np.where(out["geomID"] >= 0, out["tfar"], np.inf)
        return t, out["primID"].astype(np.int64)


class Open3D:
    """Open3D's RaycastingScene: Embree, multi-threaded over rays."""

    name = "open3d"

    def __init__(self, vertices, faces):
        import open3d as o3d

        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(o3d.core.Tensor(np.asarray(vertices, np.float32)),
                                  o3d.core.Tensor(np.asarray(faces, np.uint32)))
        self.closest(np.zeros((1, 3), np.float32), np.array([[1.0, 0, 0]], np.float32))

    def closest(self, origins, directions):
        rays = self._o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
        out = self._scene.cast_rays(rays)
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
        self._intersector = RayMeshIntersector(self._mesh)
        self.closest(np.zeros((1, 3)), np.array([[1.0, 0, 0]]))

    def closest(self, origins, directions):
        index_tri, index_ray, locations = self._intersector.intersects_id(
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
