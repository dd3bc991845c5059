"""Side-by-side ray casting benchmark: raycore against embreex, Open3D and trimesh.

Same meshes, same rays, one process.  For every mesh: build times and memory per triangle, then
closest-hit throughput on 1024x1024 primary camera rays (coherent) and 1M random rays from inside
the bounds (incoherent), reported in Mrays/s and as ratios to each anchor.  Machines are noisy:
the ratios are what count, so raycore and Open3D (both multi-threaded) are timed in interleaved
rounds, best of ``ROUNDS``.  Results go to benchmarks/results/bench.json and bench.md.

Run with ``make bench`` (or ``python -m benchmarks.run [--quick]``).
"""

import argparse
import json
import platform
import time
from functools import partial
from pathlib import Path

import numpy as np
import trimesh

from benchmarks.anchors import ANCHORS
from benchmarks.rays import camera_rays, random_rays
from raycore import Scene

SHARED_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"
RESULTS = Path(__file__).resolve().parent / "results"
#: trimesh's NumPy intersector is ~1e4 times slower: it runs on a subsample of this many rays
TRIMESH_SAMPLE = {"camera": 2000, "random": 300}


#: Timed calls of each multi-threaded contender (raycore, Open3D) per ray set, interleaved
ROUNDS = 5


def best_time(function, *args, repeats=3):
    """Smallest wall time of ``repeats`` calls of ``function(*args)``, and the last result."""
    best = np.inf
    result = None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function(*args)
        best = min(best, time.perf_counter() - start)
    return best, result


def interleaved_best_times(calls, rounds=ROUNDS):
    """Smallest wall time of each of ``calls`` (name -> function of no arguments) over
    ``rounds`` rounds that call each once in turn, so that the machine's drifts in load reach
    every contender alike; and each call's last result."""
    best = dict.fromkeys(calls, np.inf)
    results = {}
    for _ in range(rounds):
        for name, call in calls.items():
            seconds, results[name] = best_time(call, repeats=1)
            best[name] = min(best[name], seconds)
    return best, results


def meshes(quick):
    """(name, vertices, faces) of the shared meshes and a synthetic mesh of over 1M triangles."""
    for path in sorted(SHARED_MESHES.glob("*.obj")):
        mesh = trimesh.load(path, force="mesh", process=False)
        yield path.stem, np.asarray(mesh.vertices), np.asarray(mesh.faces)
        if quick:
            return
    sphere = trimesh.creation.icosphere(subdivisions=8)
    yield "icosphere-1.3M", np.asarray(sphere.vertices), np.asarray(sphere.faces)


def bench_mesh(name, vertices, faces, ray_count, camera_size):
    report = {"mesh": name, "triangles": int(len(faces)), "build_s": {}, "bytes_per_triangle": {},
              "rays": {}}
    scenes = {}
    for dtype in ("float32", "float64"):
        scene = Scene(dtype=dtype)
        scene.add_mesh(vertices, faces)
        seconds, _ = best_time(scene.build, repeats=2)
        scenes[dtype] = scene
        report["build_s"][f"raycore-{dtype}"] = seconds
        report["bytes_per_triangle"][f"raycore-{dtype}"] = scene.stats()["bytes"] / len(faces)
    report["sah_cost"] = scenes["float32"].stats()["meshes"][0]["sah_cost"]
    anchors = {}
    for anchor in ANCHORS:
        start = time.perf_counter()
        anchors[anchor.name] = anchor(vertices, faces)
        report["build_s"][anchor.name] = time.perf_counter() - start

    lo, hi = vertices[faces].reshape(-1, 3).min(0), vertices[faces].reshape(-1, 3).max(0)
    ray_sets = {
        "camera": camera_rays(lo, hi, camera_size, camera_size),
        "random": random_rays(lo, hi, ray_count, seed=1),
    }
    for kind, (origins, directions) in ray_sets.items():
        origins32 = origins.astype(np.float32)
        directions32 = directions.astype(np.float32)
        row = {"mrays_s": {}, "agreement_with_embree": {}}
        seconds, (t_ref, prim_ref) = best_time(anchors["embreex"].closest, origins32,
                                               directions32, repeats=1)
        row["mrays_s"]["embreex"] = len(origins) / seconds / 1e6
        sample = TRIMESH_SAMPLE[kind]
        seconds, _ = best_time(anchors["trimesh"].closest, origins[:sample], directions[:sample],
                               repeats=1)
        row["mrays_s"]["trimesh"] = sample / seconds / 1e6
        rays = {"float32": (origins32, directions32), "float64": (origins, directions)}
        calls = {"open3d": partial(anchors["open3d"].closest, origins32, directions32)}
        for dtype, scene in scenes.items():
            o, d = rays[dtype]
            scene.intersect(o[:1000], d[:1000])  # compile or load the kernels outside the timing
            calls[f"raycore-{dtype}"] = partial(scene.intersect, o, d)
        seconds, results = interleaved_best_times(calls)
        for name, best in seconds.items():
            row["mrays_s"][name] = len(origins) / best / 1e6
        for dtype in scenes:
            hits = results[f"raycore-{dtype}"]
            both = np.isfinite(hits.t) & np.isfinite(t_ref)
            row["agreement_with_embree"][dtype] = {
                "same_prim": float(np.mean(hits.prim_id == prim_ref)),
                "median_rel_t_error": float(np.median(
                    np.abs(hits.t[both] - t_ref[both]) / np.abs(t_ref[both]))) if both.any()
                else 0.0,
            }
        for dtype in ("float32", "float64"):
            ours = row["mrays_s"][f"raycore-{dtype}"]
            row[f"ratio_{dtype}"] = {a: ours / row["mrays_s"][a] for a in
                                     ("embreex", "open3d", "trimesh")}
        report["rays"][kind] = row
    report["build_ratio_to_embreex"] = report["build_s"]["raycore-float32"] / report["build_s"][
        "embreex"]
    return report


def markdown(reports):
    lines = [
        "| mesh | tris | rays | raycore f32 | raycore f64 | embreex | open3d | trimesh "
        "| f32/open3d | f64/open3d | f32/embreex | build f32/embreex | B/tri f32 |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in reports:
        for kind, row in r["rays"].items():
            m = row["mrays_s"]
            lines.append(
                f"| {r['mesh']} | {r['triangles']:,} | {kind} | {m['raycore-float32']:.2f} "
                f"| {m['raycore-float64']:.2f} | {m['embreex']:.2f} | {m['open3d']:.2f} "
                f"| {m['trimesh']:.4f} | {row['ratio_float32']['open3d']:.2f} "
                f"| {row['ratio_float64']['open3d']:.2f} | {row['ratio_float32']['embreex']:.2f} "
                f"| {r['build_ratio_to_embreex']:.2f} "
                f"| {r['bytes_per_triangle']['raycore-float32']:.0f} |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one mesh, fewer rays")
    args = parser.parse_args(argv)
    ray_count = 100_000 if args.quick else 1_000_000
    camera_size = 256 if args.quick else 1024
    reports = []
    for name, vertices, faces in meshes(args.quick):
        reports.append(bench_mesh(name, vertices, faces, ray_count, camera_size))
        print(markdown(reports[-1:]).splitlines()[-1] if reports else "", flush=True)
        print(markdown(reports[-1:]).splitlines()[-2], flush=True)
    table = markdown(reports)
    print(table)
    RESULTS.mkdir(exist_ok=True)
    machine = {"cpu_count": __import__("os").cpu_count(), "platform": platform.platform()}
    (RESULTS / "bench.json").write_text(json.dumps({"machine": machine, "meshes": reports},
                                                   indent=2))
    (RESULTS / "bench.md").write_text(table + "\n")


if __name__ == "__main__":
    main()
