"""The built-in demo scene (id ``demo``): a procedural torus mesh, an instance of it, and one of
each analytic shape on a floor, generated here so that it needs nothing outside the project."""

import logging

import numpy as np

from raycore.camera import perspective_rays
from raycore.render import render
from service.builder import build_scene
from service.schemas import SceneSpec

logger = logging.getLogger("raycore.service")

#: A camera that frames the demo, for the README and the OpenAPI examples.
DEMO_CAMERA = {"type": "perspective", "position": [7.0, 5.0, -9.0], "look_at": [0.0, 1.0, 0.0],
               "up": [0.0, 1.0, 0.0], "fov": 45.0, "width": 640, "height": 480}


def torus(major=1.0, minor=0.35, rings=48, sides=24):
    """A closed torus around the y axis.

    Returns
    -------
    vertices : ndarray of float64, shape (rings * sides, 3)
    faces : ndarray of int64, shape (2 * rings * sides, 3)
        Counter-clockwise seen from outside.
    """
    u = np.linspace(0, 2 * np.pi, rings, endpoint=False)[:, None]
    v = np.linspace(0, 2 * np.pi, sides, endpoint=False)[None, :]
    radius = major + minor * np.cos(v)
    vertices = np.stack(np.broadcast_arrays(radius * np.cos(u), minor * np.sin(v),
                                            radius * np.sin(u)), axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings), np.arange(sides), indexing="ij")
    a, b = i * sides + j, (i + 1) % rings * sides + j
    c, d = (i + 1) % rings * sides + (j + 1) % sides, i * sides + (j + 1) % sides
    faces = np.concatenate([np.stack([a, d, c], -1), np.stack([a, c, b], -1)]).reshape(-1, 3)
    return vertices, faces


def demo_spec():
    """The demo scene's spec (float32)."""
    vertices, faces = torus()
    lean = np.radians(60)
    placed = [[1.0, 0.0, 0.0, -2.5], [0.0, np.cos(lean), -np.sin(lean), 1.4],
              [0.0, np.sin(lean), np.cos(lean), 2.0], [0.0, 0.0, 0.0, 1.0]]
    return SceneSpec.model_validate({"dtype": "float32", "objects": [
        {"type": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
         "material": {"color": [0.75, 0.75, 0.7]}},
        {"type": "mesh", "vertices": (vertices + [0.0, 0.35, 0.0]).tolist(),
         "faces": faces.tolist(), "material": {"color": [0.9, 0.6, 0.2]}},
        {"type": "instance", "mesh": 1, "transform": placed,
         "material": {"color": [0.2, 0.6, 0.9]}},
        {"type": "sphere", "center": [0, 1.2, 0], "radius": 0.8,
         "material": {"color": [0.9, 0.25, 0.2]}},
        {"type": "box", "lo": [1.8, 0, -0.6], "hi": [3.0, 1.2, 0.6],
         "material": {"color": [0.3, 0.8, 0.35]}},
        {"type": "cylinder", "p0": [-1.5, 0, -2.2], "p1": [-1.5, 1.6, -2.2], "radius": 0.45,
         "material": {"color": [0.6, 0.4, 0.85]}},
        {"type": "cone", "base_center": [1.2, 0, -2.4], "apex": [1.2, 1.8, -2.4], "radius": 0.6,
         "material": {"color": [0.95, 0.85, 0.3]}},
        {"type": "disk", "center": [0, 0.01, 2.6], "normal": [0, 1, 0], "radius": 0.9,
         "material": {"color": [0.2, 0.2, 0.25]}},
    ]})


def load_demo(state):
    """Build the demo scene into ``state.store`` (pinned, alias ``demo``), load the kernels that
    requests use by answering a few queries, then mark ``state`` ready.

    Runs at startup as compute work (:meth:`service.runtime.Runtime.compute`): a failure is
    logged and leaves /readyz at 503.
    """
    try:
        entry, held = build_scene(demo_spec(), state.store.get, state.settings.max_triangles,
                                  state.settings.max_planes)
        state.store.put("scene", entry.info.id, entry, held, pinned=True)
        state.store.alias("scene", "demo", entry.info.id)
        origins, directions = perspective_rays(DEMO_CAMERA["position"], DEMO_CAMERA["look_at"],
                                               DEMO_CAMERA["up"], DEMO_CAMERA["fov"], 8, 8)
        render(entry.scene, origins, directions, 8, 8, "lambert", colors=entry.colors)
        entry.scene.intersect_all(origins, directions)
        state.ready.set()
    except Exception:  # the thread's outermost boundary: nothing above it would report it
        logger.exception("the demo scene could not be built; /readyz stays 503")
