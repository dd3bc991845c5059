"""The benchmark meshes: every shared mesh, and large meshes made by subdividing one of them.

The large meshes are nefertiti (99,938 triangles, closed) subdivided by trimesh's ``subdivide``
(each triangle into four, midpoints on the edges, so the surface stays closed and the shape
stays the same): twice gives 1,599,008 triangles, three times 6,396,032.  They are made once and
cached as .npy files under ``$RAYCORE_BENCH_CACHE`` (default ``~/.cache/raycore-bench``),
outside the repository.
"""

import os
from pathlib import Path

import numpy as np
import trimesh

SHARED_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"
#: Large meshes: name -> (shared mesh, times subdivided)
SUBDIVIDED = {"nefertiti-1.6M": ("nefertiti", 2), "nefertiti-6.4M": ("nefertiti", 3)}
#: The mesh of ``--quick`` runs
QUICK_MESH = "spot"


def cache_dir():
    """Where the subdivided meshes are kept between runs."""
    default = Path.home() / ".cache" / "raycore-bench"
    return Path(os.environ.get("RAYCORE_BENCH_CACHE", default))


def shared_mesh_names():
    """Names of the shared meshes (their file stems), sorted."""
    return sorted(path.stem for path in SHARED_MESHES.glob("*.obj"))


def load(name):
    """(vertices, faces) of a shared or subdivided mesh: (V, 3) float64 and (F, 3) int64."""
    if name in SUBDIVIDED:
        return _subdivided(name)
    mesh = trimesh.load(SHARED_MESHES / f"{name}.obj", force="mesh", process=False)
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def _subdivided(name):
    base, times = SUBDIVIDED[name]
    paths = [cache_dir() / f"{name}-{part}.npy" for part in ("vertices", "faces")]
    if not all(path.exists() for path in paths):
        vertices, faces = load(base)
        for _ in range(times):
            vertices, faces = trimesh.remesh.subdivide(vertices, faces)
        paths[0].parent.mkdir(parents=True, exist_ok=True)
        for path, array, dtype in zip(paths, (vertices, faces), (np.float64, np.int64),
                                     strict=True):
            np.save(path, np.ascontiguousarray(array, dtype))
    return tuple(np.load(path) for path in paths)


def benchmark_meshes(quick=False, large=True):
    """Names of the meshes a run measures: one small mesh when ``quick``; otherwise every
    shared mesh, then the subdivided ones when ``large``."""
    if quick:
        return [QUICK_MESH]
    return shared_mesh_names() + (list(SUBDIVIDED) if large else [])


def warm_up_mesh():
    """(vertices, faces) of a small closed mesh (1,280 triangles) for warm-up builds."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    return np.asarray(sphere.vertices, np.float64), np.asarray(sphere.faces, np.int64)
