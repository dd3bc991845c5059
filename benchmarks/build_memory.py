"""BVH build time and build memory: raycore against Open3D (Embree), measured honestly.

Time: in one process, after a warm-up build of a small mesh (Numba's cache loading and Embree's
first-use costs are paid there), each contender builds the mesh from its native inputs and
answers one ray, in interleaved rounds, best of ``--rounds``.  raycore: ``Scene.add_mesh`` with
arrays already in the scene's dtype, then ``intersect``.  Open3D: ``add_triangles`` with
prebuilt tensors, then ``cast_rays`` (Embree builds on commit, at the first query).

Memory: one fresh process per contender.  It loads the mesh and warms up on a small one, then
resets the kernel's peak-RSS counter (``/proc/self/clear_refs``, Linux only), builds, and reads
the peak (``VmHWM``).  The build's temporaries are the peak minus the resident memory before the
build minus the finished tree (``Scene.stats()["bytes"]``).  ``raycore-mesh`` is the mesh's own
build (``Mesh.build``) without the scene's packing of every mesh into shared arrays.

Run: ``python -m benchmarks.build_memory MESH [MESH ...] [--dtype float32] [--rounds 3]``, where
MESH is a mesh file trimesh reads or an ``.npz`` with ``vertices`` and ``faces``.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

#: Large enough (69,451 triangles) for every phase of the build to run, so that no kernel is
#: first loaded during a measured build
WARMUP_MESH = Path(__file__).resolve().parents[2] / "shared" / "meshes" / "stanford-bunny.obj"


def load(path):
    """(vertices float64 (V, 3), faces int64 (F, 3)) of a mesh file or an .npz."""
    if str(path).endswith(".npz"):
        data = np.load(path)
        return np.asarray(data["vertices"], np.float64), np.asarray(data["faces"], np.int64)
    import trimesh

    mesh = trimesh.load(path, force="mesh", process=False)
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def one_ray(vertices):
    """A ray from outside the mesh's box towards its centre, as float64 (1, 3) arrays."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = (lo + hi) / 2
    origin = centre - 2 * (hi - lo) * np.array([1.0, 0.3, 0.2])
    return origin[None], (centre - origin)[None]


def raycore_build(vertices, faces, dtype, origins, directions):
    """Scene with the mesh built and queried once; returns the scene."""
    from raycore import Scene

    scene = Scene(dtype=dtype)
    scene.add_mesh(vertices, faces)
    scene.intersect(origins, directions)
    return scene


def mesh_build(vertices, faces, dtype, origins, directions):
    """A mesh's own BVH, built as a scene builds it but without the scene's packing."""
    from raycore.bvh.build import BuildParams
    from raycore.mesh import Mesh

    mesh = Mesh(vertices, faces)
    mesh.build(np.dtype(dtype), BuildParams())
    return mesh


def open3d_inputs(vertices, faces, origins, directions):
    import open3d as o3d

    return (o3d.core.Tensor(vertices.astype(np.float32)),
            o3d.core.Tensor(faces.astype(np.uint32)),
            o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32)))


def open3d_build(vertex_tensor, face_tensor, ray_tensor):
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(vertex_tensor, face_tensor)
    scene.cast_rays(ray_tensor)
    return scene


def warm_up(dtype):
    vertices, faces = load(WARMUP_MESH)
    origins, directions = one_ray(vertices)
    raycore_build(vertices.astype(dtype), faces, dtype, origins.astype(dtype),
                  directions.astype(dtype))
    open3d_build(*open3d_inputs(vertices, faces, origins, directions))


def time_builds(path, dtype, rounds):
    """Best build-and-first-query seconds of raycore and Open3D, interleaved; raycore's stats."""
    vertices, faces = load(path)
    origins, directions = one_ray(vertices)
    warm_up(dtype)
    native = (vertices.astype(dtype), faces, dtype, origins.astype(dtype), directions.astype(dtype))
    tensors = open3d_inputs(vertices, faces, origins, directions)
    best = {"raycore": np.inf, "open3d": np.inf}
    for _ in range(rounds):
        start = time.perf_counter()
        scene = raycore_build(*native)
        best["raycore"] = min(best["raycore"], time.perf_counter() - start)
        stats = scene.stats()
        del scene
        start = time.perf_counter()
        o3d_scene = open3d_build(*tensors)
        best["open3d"] = min(best["open3d"], time.perf_counter() - start)
        del o3d_scene
    mesh = stats["meshes"][0]
    return {"triangles": len(faces), "raycore_s": best["raycore"], "open3d_s": best["open3d"],
            "ratio": best["raycore"] / best["open3d"], "sah_cost": mesh["sah_cost"],
            "tree_bytes_per_triangle": stats["bytes"] / len(faces)}


def _rss_kib(field):
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise RuntimeError(f"no {field} in /proc/self/status")


def measure_memory(path, dtype, contender):
    """Peak-RSS figures of one build in this process (call in a fresh one)."""
    vertices, faces = load(path)
    origins, directions = one_ray(vertices)
    warm_up(dtype)
    if contender in ("raycore", "raycore-mesh"):
        inputs = (vertices.astype(dtype), faces, dtype, origins.astype(dtype),
                  directions.astype(dtype))
        build = raycore_build if contender == "raycore" else mesh_build
    else:
        inputs = open3d_inputs(vertices, faces, origins, directions)
        build = open3d_build
    with open("/proc/self/clear_refs", "w") as clear:
        clear.write("5")  # resets VmHWM to the current resident size
    before = _rss_kib("VmRSS")
    scene = build(*inputs)
    peak = _rss_kib("VmHWM")
    result = {"triangles": len(faces), "contender": contender,
              "peak_over_before_MiB": (peak - before) / 1024}
    if contender != "open3d":
        tree = scene.stats()["bytes"] if contender == "raycore" else scene.nbytes
        temporaries = (peak - before) * 1024 - tree
        result.update(tree_bytes_per_triangle=tree / len(faces),
                      temporaries_bytes_per_triangle=temporaries / len(faces),
                      temporaries_over_tree=temporaries / tree)
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("meshes", nargs="+")
    parser.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--memory-only", action="store_true")
    parser.add_argument("--measure-memory", choices=["raycore", "raycore-mesh", "open3d"],
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.measure_memory:
        print(json.dumps(measure_memory(args.meshes[0], args.dtype, args.measure_memory)))
        return
    for path in args.meshes:
        row = {"mesh": path, "dtype": args.dtype}
        if not args.memory_only:
            row.update(time_builds(path, args.dtype, args.rounds))
        for contender in ("raycore", "raycore-mesh", "open3d"):
            out = subprocess.run(
                [sys.executable, "-m", "benchmarks.build_memory", path, "--dtype", args.dtype,
                 "--measure-memory", contender], capture_output=True, text=True, check=True)
            row[f"memory_{contender}"] = json.loads(out.stdout.splitlines()[-1])
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
