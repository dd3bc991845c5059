"""Each library's inputs in its native form, and its build, for timing its own calls only.

A user of Open3D keeps rays in an (N, 6) float32 ``o3d.core.Tensor``; a user of embreex keeps
C-contiguous float32 arrays; a user of raycore keeps arrays in the scene's dtype.  The functions
here make those inputs before any clock starts.  The timed regions then hold one library call,
and its outputs are taken as the library returns them:

* raycore: ``scene.intersect(o, d)``, ``occluded``, ``count``, ``intersect_all``;
* Open3D: ``scene.cast_rays(rays)``, ``test_occlusions``, ``count_intersections``,
  ``list_intersections``;
* embreex: ``scene.run(o, d, output=1)`` and ``scene.run(o, d, dists=1.0, query="OCCLUDED")``.

A build is what a user waits for before the first answer: the mesh added, the tree built and one
ray traced (Embree builds its tree on the first query after a change).
"""

import numpy as np

from raycore import Scene

#: The first query of a build: one ray, in each library's form.
PROBE_ORIGIN, PROBE_DIRECTION = np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]])


def raycore_mesh(vertices, faces, dtype):
    """Vertices in the scene's dtype and int64 faces, both C-contiguous."""
    return np.ascontiguousarray(vertices, dtype), np.ascontiguousarray(faces, np.int64)


def raycore_build(mesh, dtype):
    """A raycore Scene of ``mesh`` (from :func:`raycore_mesh`), built and queried once."""
    scene = Scene(dtype=dtype)
    scene.add_mesh(*mesh)
    scene.build()
    scene.intersect(PROBE_ORIGIN.astype(dtype), PROBE_DIRECTION.astype(dtype))
    return scene


def open3d_mesh(vertices, faces):
    """(vertex positions, triangle indices) as Open3D wants them: float32 and uint32 Tensors."""
    import open3d as o3d

    return (o3d.core.Tensor(np.ascontiguousarray(vertices, np.float32)),
            o3d.core.Tensor(np.ascontiguousarray(faces, np.uint32)))


def open3d_rays(origins, directions):
    """Rays as Open3D wants them: one (N, 6) float32 Tensor of origin and direction rows."""
    import open3d as o3d

    return o3d.core.Tensor(np.ascontiguousarray(np.hstack([origins, directions]), np.float32))


def open3d_build(mesh):
    """An Open3D RaycastingScene of ``mesh`` (from :func:`open3d_mesh`), queried once."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(*mesh)
    scene.cast_rays(open3d_rays(PROBE_ORIGIN, PROBE_DIRECTION))
    return scene


def embreex_arrays(*arrays):
    """C-contiguous float32 copies (or the arrays themselves when they already are)."""
    return tuple(np.ascontiguousarray(a, np.float32) for a in arrays)


def embreex_mesh(vertices, faces):
    """(vertices, indices) as embreex's indexed TriangleMesh reads them: float32 and int32."""
    return np.ascontiguousarray(vertices, np.float32), np.ascontiguousarray(faces, np.int32)


def embreex_build(mesh):
    """An embreex EmbreeScene of ``mesh`` (from :func:`embreex_mesh`), queried once (which
    commits it: Embree builds then)."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, *mesh)
    scene.run(*embreex_arrays(PROBE_ORIGIN, PROBE_DIRECTION), output=1)
    return scene
