"""Scenes, rays and mesh files for the service tests, and the limits they run under."""

import io

import numpy as np
import trimesh

from raycore import Scene
from service.config import Settings

#: Limits small enough to reach in tests.
SETTINGS = Settings(max_rays=5000, max_body_bytes=2**20, max_triangles=20_000,
                    max_render_pixels=128 * 128, store_bytes=64 * 2**20, demo=False)

#: One object of each kind; the instance places the inline mesh (object 6) elsewhere.
TRIANGLES = {"vertices": [[-1.0, -1.0, 6.0], [1.0, -1.0, 6.0], [0.0, 1.0, 6.0]],
             "faces": [[0, 1, 2]]}
SPEC = {"dtype": "float32", "objects": [
    {"type": "sphere", "center": [0.0, 0.0, 3.0], "radius": 0.5,
     "material": {"color": [1.0, 0.0, 0.0]}},
    {"type": "plane", "point": [0.0, -2.0, 0.0], "normal": [0.0, 1.0, 0.0]},
    {"type": "disk", "center": [2.0, 0.0, 4.0], "normal": [0.0, 0.0, -1.0], "radius": 0.5},
    {"type": "box", "lo": [-2.5, -0.5, 3.5], "hi": [-1.5, 0.5, 4.5]},
    {"type": "cylinder", "p0": [0.0, 1.0, 4.0], "p1": [0.0, 2.0, 4.0], "radius": 0.4},
    {"type": "cone", "base_center": [2.0, 1.0, 4.0], "apex": [2.0, 2.0, 4.0], "radius": 0.4},
    {"type": "mesh", **TRIANGLES},
    {"type": "instance", "mesh": 6, "transform": [[1, 0, 0, 0], [0, 1, 0, 3], [0, 0, 1, 0],
                                                  [0, 0, 0, 1]]},
]}


def scene_in_process(dtype="float32"):
    """The scene of SPEC, built by calling Scene directly."""
    scene = Scene(dtype=dtype)
    scene.add_sphere([0.0, 0.0, 3.0], 0.5)
    scene.add_plane([0.0, -2.0, 0.0], [0.0, 1.0, 0.0])
    scene.add_disk([2.0, 0.0, 4.0], [0.0, 0.0, -1.0], 0.5)
    scene.add_box([-2.5, -0.5, 3.5], [-1.5, 0.5, 4.5])
    scene.add_cylinder([0.0, 1.0, 4.0], [0.0, 2.0, 4.0], 0.4)
    scene.add_cone([2.0, 1.0, 4.0], [2.0, 2.0, 4.0], 0.4)
    mesh = scene.add_mesh(TRIANGLES["vertices"], TRIANGLES["faces"])
    transform = np.eye(4)
    transform[1, 3] = 3
    scene.add_instance(mesh, transform)
    return scene


def rays(count=400, seed=0):
    """Rays from around the origin into the +z half space: hits on every object, and misses."""
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-0.2, 0.2, (count, 3))
    directions = np.column_stack([rng.uniform(-0.9, 0.9, (count, 2)), np.ones(count)])
    return origins, directions


def sphere_file(file_type, subdivisions=2):
    """Bytes of a closed unit icosphere exported by trimesh, and the mesh."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    stream = io.BytesIO()
    mesh.export(stream, file_type=file_type)
    return stream.getvalue(), mesh


