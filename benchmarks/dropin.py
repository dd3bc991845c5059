"""The drop-in calls side by side: raycore's trimesh and Open3D adapters against the calls they
stand in for, as a user of each would call them.

stanford-bunny (69k triangles), 200k random rays from inside its bounds
(:func:`benchmarks.rays.random_rays`; 50k for trimesh's every-crossing query, whose Embree loop
is slow).  Each library gets its inputs in its own form before any clock starts (trimesh: float64
arrays; embreex: C-contiguous float32 arrays; Open3D: an (N, 6) float32 Tensor, which raycore's
Open3D-style calls take as they are), and each pair is timed in interleaved rounds, best of
``ROUNDS``.  Writes ``benchmarks/results/dropin.json``; the README's table "Coming from trimesh,
Open3D or embreex" quotes it.  Run with ``python -m benchmarks.dropin`` (part of ``make bench``).
"""

import json
import os
from pathlib import Path

import numpy as np

from benchmarks import contenders, meshes
from benchmarks.rays import random_rays
from benchmarks.timing import interleaved_best_times
from raycore import Scene
from raycore.integrations.trimesh import RayMeshIntersector

RESULTS = Path(__file__).resolve().parent / "results" / "dropin.json"
MESH, RAYS, EVERY_CROSSING_RAYS, ROUNDS = "stanford-bunny", 200_000, 50_000, 5


def pairs():
    """``{row: (rays, raycore's call, the other's call)}``, inputs made and every scene built
    and queried once."""
    import trimesh
    from embreex import mesh_construction, rtcore_scene
    from trimesh.ray.ray_pyembree import RayMeshIntersector as EmbreeIntersector

    vertices, faces = meshes.load(MESH)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    origins, directions = random_rays(vertices.min(0), vertices.max(0), RAYS, 1)
    few = origins[:EVERY_CROSSING_RAYS], directions[:EVERY_CROSSING_RAYS]
    ours, ours32, theirs = (RayMeshIntersector(mesh), RayMeshIntersector(mesh, dtype="float32"),
                            EmbreeIntersector(mesh))
    embree = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(embree, vertices[faces].astype(np.float32))
    o32, d32 = (np.ascontiguousarray(a, np.float32) for a in (origins, directions))
    scene = contenders.raycore_build(contenders.raycore_mesh(vertices, faces, "float32"),
                                     "float32")
    open3d = contenders.open3d_build(contenders.open3d_mesh(vertices, faces))
    tensor = contenders.open3d_rays(origins, directions)
    return {
        "trimesh intersects_first (float64)": (
            RAYS, lambda: ours.intersects_first(origins, directions),
            lambda: theirs.intersects_first(origins, directions)),
        "trimesh intersects_first (raycore float32)": (
            RAYS, lambda: ours32.intersects_first(origins, directions),
            lambda: theirs.intersects_first(origins, directions)),
        "trimesh intersects_id, multiple_hits": (
            EVERY_CROSSING_RAYS, lambda: ours.intersects_id(*few, multiple_hits=True),
            lambda: theirs.intersects_id(*few, multiple_hits=True)),
        "embreex run / Scene.intersect": (
            RAYS, lambda: scene.intersect(o32, d32).prim_id, lambda: embree.run(o32, d32)),
        "Open3D cast_rays": (RAYS, lambda: scene.cast_rays(tensor),
                             lambda: open3d.cast_rays(tensor)),
        "Open3D count_intersections": (RAYS, lambda: scene.count_intersections(tensor),
                                       lambda: open3d.count_intersections(tensor)),
        "Open3D test_occlusions": (RAYS, lambda: scene.test_occlusions(tensor),
                                   lambda: open3d.test_occlusions(tensor)),
        "Open3D list_intersections": (RAYS, lambda: scene.list_intersections(tensor),
                                      lambda: open3d.list_intersections(tensor)),
    }


def main():
    # raycore's threads first: Open3D loads an older TBB, which Numba's TBB layer refuses
    Scene("float32").intersect(contenders.PROBE_ORIGIN, contenders.PROBE_DIRECTION)
    rows = []
    for name, (count, ours, theirs) in pairs().items():
        ours(), theirs()  # warm
        best, _ = interleaved_best_times({"raycore": ours, "other": theirs}, ROUNDS)
        row = {"call": name, "rays": count, "raycore_mrays_s": count / best["raycore"] / 1e6,
               "other_mrays_s": count / best["other"] / 1e6}
        row["ratio"] = row["raycore_mrays_s"] / row["other_mrays_s"]
        rows.append(row)
        print(f"{name:44s} raycore {row['raycore_mrays_s']:6.2f} Mrays/s, other "
              f"{row['other_mrays_s']:6.2f}: {row['ratio']:.2f}", flush=True)
    RESULTS.write_text(json.dumps({"mesh": MESH, "cpus": os.cpu_count(),
                                   "load_average": os.getloadavg(), "rows": rows}, indent=1))
    print(f"written to {RESULTS}")


if __name__ == "__main__":
    main()
