"""Side-by-side ray casting benchmark: raycore against Open3D and embreex, timed honestly.

Every contender's timed region holds its own call and nothing else: its inputs are made
beforehand in its native form (``benchmarks.contenders``) and its outputs are taken as it returns
them.  Contenders are timed in interleaved rounds (A, B, C, A, B, C, ...), best of ``--rounds``.

For every mesh (``benchmarks.meshes``: each shared mesh, and nefertiti subdivided to 1.6M and
6.4M triangles; 1024x1024 camera rays and 500k random rays, 512x512 and 250k on the subdivided
meshes, where one call still takes 50 ms or more):

* build: raycore (add_mesh, build, one ray), Open3D (add_triangles, one ray: Embree builds
  then) and embreex (scene, one ray), after warm-up builds in the same process; the first build
  of the process (Numba's cache loading) is reported apart.  Peak memory of each build is
  measured in a fresh process (``benchmarks.build_memory``), on meshes of 1M triangles or more.
* queries, each ray set with the fraction of its rays that hit:
  - closest hit on three ray sets: ``camera`` (the whole mesh in view, so many rays miss),
    ``framed`` (the same eye, its view narrowed until >= 90 % of the rays hit), ``random``
    (from uniform points inside the bounds, uniform directions); raycore float32 and float64
    against Open3D's float32 ``cast_rays`` and serial embreex (``run(output=1)``);
  - any hit: ``shadow`` rays from the framed camera's hits to random points on a spherical
    area light placed where about half of them are blocked (``benchmarks.rays``), raycore
    ``occluded`` against Open3D's ``test_occlusions`` (origins offset off the surface once, the
    same rays for both, tmin = 0, tmax = 1 at the light);
  - ``count`` and ``intersect_all`` on the random rays against Open3D's ``count_intersections``
    and ``list_intersections``;
  - the gain from one thread to two: raycore float32 with ``numba.set_num_threads(1)`` and Open3D
    with ``nthreads=1``, in the same rounds as their default two-thread calls;
  - the former method's ratio, once, on the camera and random rays: Open3D timed through the
    former benchmark's wrapper (``benchmarks.anchors.open3d_closest``).
* per core: the closest-hit sets again in a subprocess with ``NUMBA_NUM_THREADS=1``, against
  serial embreex and single-thread Open3D.
* with AVX2 only: on a machine whose kernels are compiled for x86-64-v4 (AVX-512), the
  closest-hit and shadow sets again in a subprocess whose kernels are compiled for x86-64-v3
  (``raycore._target``), against Open3D there, both on every core: how the two compare on a CPU
  without AVX-512.  Open3D 0.20's Embree has no AVX-512 kernels (no ``embree::avx512`` code in
  its library, and ``perf`` samples its traversal's hot loop on 256-bit registers on a Zen 5), so
  on such a machine only raycore's kernels differ.

Results go to benchmarks/results/bench.json and bench.md (``benchmarks.report``).  Run with
``make bench`` or ``python -m benchmarks.run [--quick] [--no-large] [--meshes NAME ...]``; the
full run takes about 15 minutes on 2 cores.
"""

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import numba
import numpy as np

from benchmarks import contenders, meshes, report
from benchmarks.anchors import open3d_closest
from benchmarks.rays import (
    camera_rays,
    framed_camera_rays,
    half_shadow_light,
    light_points,
    random_rays,
    shadow_rays,
)

# best_time is imported from here by benchmarks.speed_accuracy
from benchmarks.timing import best_time, interleaved_best_times  # noqa: F401
from raycore._target import LEVELS, compiled_features, level_settings

RESULTS = Path(__file__).resolve().parent / "results"
#: The checkout, where the benchmark's subprocesses (``python -m benchmarks...``) run, so that
#: they find the benchmarks whatever the caller's working directory (``raycore bench``).
CHECKOUT = Path(__file__).resolve().parents[1]
DTYPES = (np.float32, np.float64)
#: Meshes of at least this many triangles are "large": fewer rays and build rounds, so that a
#: full run fits in about 15 minutes on 2 cores (a large mesh's call still takes >= 50 ms)
LARGE = 1_000_000
#: Rays per set: (camera width = height, random rays)
RAY_COUNTS = {"small": (1024, 500_000), "large": (512, 250_000), "quick": (256, 65_536)}
#: Interleaved build rounds
BUILD_ROUNDS = {"small": 3, "large": 2, "quick": 3}
CLOSEST_SETS = ("camera", "framed", "random")
#: The sets on which the former method's ratio is shown
FORMER_SETS = ("camera", "random")
#: Build memory is measured from this many triangles.  Below, allocator pools and granularity
#: are as large as the build: Embree reuses the blocks of the warm-up build, and Open3D's build
#: of 100k triangles then seems to take 1 byte per triangle.
MEMORY_MIN_TRIANGLES = 1_000_000
#: Shadow rays on which each candidate light is tried (``benchmarks.rays.half_shadow_light``)
SHADOW_SAMPLE = 4096
#: The benchmark's runs: the main one, and those of its subprocesses (:func:`variant_run`): one
#: thread, and kernels compiled for x86-64-v3 (AVX2).
FULL, ONE_THREAD, AVX2 = "full", "one-thread", "avx2"


def with_threads(count, function):
    """``function`` run with Numba's thread count set to ``count`` (restored afterwards)."""
    def call():
        before = numba.get_num_threads()
        numba.set_num_threads(count)
        try:
            return function()
        finally:
            numba.set_num_threads(before)
    return call


def first_builds():
    """Seconds of the process's first raycore build of a small mesh in each dtype (Numba loads
    its cache, or compiles), then warm-up builds and queries of every contender."""
    vertices, faces = meshes.warm_up_mesh()
    first = {}
    for dtype in DTYPES:
        start = time.perf_counter()
        contenders.raycore_build(contenders.raycore_mesh(vertices, faces, dtype), dtype)
        first[np.dtype(dtype).name] = time.perf_counter() - start
    origins, directions = random_rays(vertices.min(axis=0), vertices.max(axis=0), 1000)
    for dtype in DTYPES:
        scene = contenders.raycore_build(contenders.raycore_mesh(vertices, faces, dtype), dtype)
        o, d = origins.astype(dtype), directions.astype(dtype)
        for query in (scene.intersect, scene.occluded, scene.count, scene.intersect_all):
            query(o, d)
    contenders.open3d_build(contenders.open3d_mesh(vertices, faces))
    contenders.embreex_build(contenders.embreex_mesh(vertices, faces))
    return first


def build_all(vertices, faces, rounds):
    """Timed builds of every contender; (seconds, the scenes built last).

    raycore float32, Open3D and embreex are timed in interleaved rounds; raycore float64, which
    only serves the float64 queries, is timed once after them.
    """
    builds = {
        "raycore-float32": partial(contenders.raycore_build,
                                   contenders.raycore_mesh(vertices, faces, np.float32),
                                   np.float32),
        "open3d": partial(contenders.open3d_build, contenders.open3d_mesh(vertices, faces)),
        "embreex": partial(contenders.embreex_build, contenders.embreex_mesh(vertices, faces)),
    }
    seconds, scenes = interleaved_best_times(builds, rounds)
    mesh = contenders.raycore_mesh(vertices, faces, np.float64)
    seconds["raycore-float64"], scenes["raycore-float64"] = best_time(
        contenders.raycore_build, mesh, np.float64, repeats=1)
    return seconds, scenes


def build_memory(mesh_name):
    """Peak memory of each contender's build of ``mesh_name``, each in a fresh process."""
    out = {}
    for contender in ("raycore", "open3d", "embreex"):
        answer = subprocess.run(
            [sys.executable, "-m", "benchmarks.build_memory", mesh_name, contender],
            capture_output=True, text=True, check=True, cwd=CHECKOUT)
        out[contender] = json.loads(answer.stdout.splitlines()[-1])
    return out


def ray_sets(vertices, faces, open3d_scene, sizes):
    """The ray sets of a mesh, float32 (N, 3) C-contiguous arrays, and each one's description.

    Open3D's answers pick the framed camera's view and give the shadow rays' hit points: any
    library would do, and Open3D's are not the ones under test.
    """
    camera_size, random_count = sizes
    corners = vertices[faces].reshape(-1, 3)
    lo, hi = corners.min(axis=0), corners.max(axis=0)

    def open3d_hit(origins, directions):
        out = open3d_scene.cast_rays(contenders.open3d_rays(origins, directions))
        return np.isfinite(out["t_hit"].numpy())

    framed_origins, framed_directions, fov = framed_camera_rays(lo, hi, camera_size, camera_size,
                                                               open3d_hit)
    sets = {
        "camera": camera_rays(lo, hi, camera_size, camera_size),
        "framed": (framed_origins, framed_directions),
        "random": random_rays(lo, hi, random_count, seed=1),
    }
    sets = {name: contenders.embreex_arrays(*rays) for name, rays in sets.items()}
    out = open3d_scene.cast_rays(contenders.open3d_rays(*sets["framed"]))
    t = out["t_hit"].numpy()
    hit = np.isfinite(t)
    hits = (sets["framed"][0][hit], sets["framed"][1][hit], t[hit],
            out["primitive_normals"].numpy()[hit])
    sample = tuple(a[::max(1, len(a) // SHADOW_SAMPLE)] for a in hits)

    def blocked_fraction(centre):
        lights = light_points(centre, lo, hi, len(sample[0]))
        rays = contenders.open3d_rays(*shadow_rays(*sample, lights))
        return float(np.mean(open3d_scene.test_occlusions(rays, 0.0, 1.0).numpy()))

    light = half_shadow_light(lo, hi, blocked_fraction)
    sets["shadow"] = shadow_rays(*hits, light_points(light, lo, hi, len(hits[0])))
    notes = {"camera": f"{camera_size}x{camera_size}, field of view 40 degrees",
             "framed": f"{camera_size}x{camera_size}, field of view {fov:.1f} degrees",
             "random": f"{random_count} rays from inside the bounds",
             "shadow": "from the framed camera's hits to a spherical light centred at "
                       f"{np.round(light, 3).tolist()}"}
    return sets, notes


def hit_fraction(name, result):
    """Fraction of rays that hit, from a contender's answer as it returned it."""
    if name.startswith("raycore"):
        return float(np.mean(result.hit if hasattr(result, "hit") else result))
    if name.startswith("embreex"):
        return float(np.mean(result["geomID"] >= 0))
    if isinstance(result, dict):  # Open3D cast_rays
        return float(np.mean(np.isfinite(result["t_hit"].numpy())))
    return float(np.mean(result.numpy()))  # Open3D test_occlusions


def time_set(calls, rounds, rays):
    """Best seconds and Mrays/s of each call, and the answers of the last round."""
    seconds, results = interleaved_best_times(calls, rounds)
    return {"rays": rays, "seconds": seconds,
            "mrays_s": {name: rays / s / 1e6 for name, s in seconds.items()}}, results


def closest_calls(rays, scenes, tensor, former, variant=FULL):
    """Timed calls of a closest-hit set: name -> function of no arguments.

    ``rays`` are float32 (origins, directions), ``tensor`` the same rays for Open3D."""
    (o32, d32), (o64, d64) = rays, (rays[0].astype(np.float64), rays[1].astype(np.float64))
    if variant == ONE_THREAD:  # the subprocess with NUMBA_NUM_THREADS=1
        return {"raycore-float32": partial(scenes["raycore-float32"].intersect, o32, d32),
                "embreex": partial(scenes["embreex"].run, o32, d32, output=1),
                "open3d-1-thread": partial(scenes["open3d"].cast_rays, tensor, nthreads=1)}
    if variant == AVX2:
        return {"raycore-float32": partial(scenes["raycore-float32"].intersect, o32, d32),
                "open3d": partial(scenes["open3d"].cast_rays, tensor)}
    calls = {
        "raycore-float32": partial(scenes["raycore-float32"].intersect, o32, d32),
        "raycore-float64": partial(scenes["raycore-float64"].intersect, o64, d64),
        "open3d": partial(scenes["open3d"].cast_rays, tensor),
        "raycore-float32-1-thread": with_threads(
            1, partial(scenes["raycore-float32"].intersect, o32, d32)),
        "open3d-1-thread": partial(scenes["open3d"].cast_rays, tensor, nthreads=1),
        "embreex": partial(scenes["embreex"].run, o32, d32, output=1),
    }
    if former:
        calls["open3d-former-wrapper"] = partial(open3d_closest, scenes["open3d"], o32, d32)
    return calls


def bench_queries(sets, scenes, rounds, variant=FULL):
    """Timings of the queries of ``variant`` (every query in the main run) on the ray sets of
    one mesh."""
    rows = {}
    for name in CLOSEST_SETS:
        tensor = contenders.open3d_rays(*sets[name])
        calls = closest_calls(sets[name], scenes, tensor, name in FORMER_SETS, variant)
        row, results = time_set(calls, rounds, len(sets[name][0]))
        row["hit_fraction"] = {n: hit_fraction(n, r) for n, r in results.items()
                               if n != "open3d-former-wrapper"}
        rows[name] = row
    if variant == ONE_THREAD:
        return rows

    o32, d32 = sets["shadow"]
    tensor = contenders.open3d_rays(o32, d32)
    calls = {
        "raycore-float32": partial(scenes["raycore-float32"].occluded, o32, d32, 0.0, 1.0),
        "open3d": partial(scenes["open3d"].test_occlusions, tensor, 0.0, 1.0),
    }
    if variant == FULL:
        calls["raycore-float64"] = partial(scenes["raycore-float64"].occluded,
                                           o32.astype(np.float64), d32.astype(np.float64), 0.0,
                                           1.0)
    row, results = time_set(calls, rounds, len(o32))
    row["hit_fraction"] = {n: hit_fraction(n, r) for n, r in results.items()}
    rows["shadow"] = row
    if variant == AVX2:
        return rows

    o32, d32 = sets["random"]
    o64, d64 = o32.astype(np.float64), d32.astype(np.float64)
    tensor = contenders.open3d_rays(o32, d32)
    for query, open3d_query in (("count", "count_intersections"),
                                ("intersect_all", "list_intersections")):
        calls = {
            "raycore-float32": partial(getattr(scenes["raycore-float32"], query), o32, d32),
            "raycore-float64": partial(getattr(scenes["raycore-float64"], query), o64, d64),
            "open3d": partial(getattr(scenes["open3d"], open3d_query), tensor),
        }
        row, results = time_set(calls, rounds, len(o32))
        if query == "count":
            ours, theirs = results["raycore-float32"], results["open3d"].numpy()
        else:
            ours = results["raycore-float32"].counts
            theirs = np.diff(results["open3d"]["ray_splits"].numpy())
        row["mean_crossings"] = {"raycore-float32": float(np.mean(ours)),
                                 "open3d": float(np.mean(theirs))}
        row["same_count_fraction"] = float(np.mean(ours == theirs))
        rows[query] = row
    return rows


def bench_mesh(name, quick, rounds, variant=FULL):
    """The measurements of ``variant`` (see the module doc) on one mesh."""
    vertices, faces = meshes.load(name)
    size = "quick" if quick else "large" if len(faces) >= LARGE else "small"
    load_average = os.getloadavg()[0]
    if variant != FULL:
        scenes = {
            "raycore-float32": contenders.raycore_build(
                contenders.raycore_mesh(vertices, faces, np.float32), np.float32),
            "open3d": contenders.open3d_build(contenders.open3d_mesh(vertices, faces))}
        if variant == ONE_THREAD:  # the AVX2 run does not time embreex
            scenes["embreex"] = contenders.embreex_build(contenders.embreex_mesh(vertices, faces))
    else:
        build_seconds, scenes = build_all(vertices, faces, BUILD_ROUNDS[size])
    sets, notes = ray_sets(vertices, faces, scenes["open3d"], RAY_COUNTS[size])
    rows = bench_queries(sets, scenes, rounds, variant)
    for ray_set, row in rows.items():
        row["ray_set"] = notes["random" if ray_set in ("count", "intersect_all") else ray_set]
    result = {"mesh": name, "triangles": int(len(faces)), "queries": rows,
              "load_average_at_start": load_average}
    if variant == FULL:
        result["build_seconds"] = build_seconds
        result["tree_bytes"] = {dtype: scenes[f"raycore-{dtype}"].stats()["bytes"]
                                for dtype in ("float32", "float64")}
        if quick or len(faces) >= MEMORY_MIN_TRIANGLES:  # a smoke run tries every step
            result["build_memory"] = build_memory(name)
    return result


def variant_run(variant, names, quick, rounds):
    """The measurements of ``variant`` (ONE_THREAD or AVX2), run in a subprocess: with
    ``NUMBA_NUM_THREADS=1``, or with kernels compiled for x86-64-v3."""
    settings = ({"NUMBA_NUM_THREADS": "1"} if variant == ONE_THREAD
                else level_settings(LEVELS[-1]))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"{variant}.json"
        command = [sys.executable, "-m", "benchmarks.run", "--variant-output", variant,
                   str(path), "--rounds", str(rounds), "--meshes", *names] + ["--quick"] * quick
        subprocess.run(command, check=True, cwd=CHECKOUT, env={**os.environ, **settings})
        return json.loads(path.read_text())


def compiled_for_avx512():
    """Whether this process's kernels use AVX-512 (x86-64-v4, as raycore chooses on a machine
    that runs it), so that an AVX2 run measures something else."""
    return "avx512vl" in compiled_features()


def machine():
    """What the figures were measured on."""
    import embreex
    import open3d

    with open("/proc/cpuinfo") as cpuinfo:
        fields = dict(line.split(":", 1) for line in cpuinfo if ":" in line)
    fields = {key.strip(): value.strip() for key, value in fields.items()}
    flags = fields.get("flags", "").split()
    return {"cpu": fields.get("model name", "unknown"), "cpu_count": os.cpu_count(),
            "simd": [f for f in ("avx2", "avx512f", "fma") if f in flags],
            "numba": numba.__version__, "numba_threads": numba.config.NUMBA_NUM_THREADS,
            "threading_layer": numba.threading_layer(), "open3d": open3d.__version__,
            "embreex": getattr(embreex, "__version__", "unknown")}


def parser():
    """The benchmark's command line options (``raycore bench`` offers the same ones)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help=f"one small mesh ({meshes.QUICK_MESH}), few rays: a smoke run")
    parser.add_argument("--no-large", action="store_true",
                        help="skip the subdivided meshes of 1.6M and 6.4M triangles")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds per ray set")
    parser.add_argument("--meshes", nargs="+", metavar="NAME",
                        help="measure only these meshes (names from benchmarks.meshes)")
    parser.add_argument("--out", type=Path, help="folder for bench.json and bench.md (default: "
                        "benchmarks/results/; with --quick, a temporary folder)")
    # a subprocess's run (variant_run): which, and where its results go
    parser.add_argument("--variant-output", nargs=2, metavar=("VARIANT", "PATH"),
                        help=argparse.SUPPRESS)
    return parser


def _no_progress(description, total=None):
    return contextlib.nullcontext(lambda amount=1: None)


def main(argv=None, progress=_no_progress):
    """Run the benchmark.

    Parameters
    ----------
    argv : list of str, optional
        Options (see :func:`parser`); the command line's by default.
    progress : callable, optional
        ``progress(description, total)``, a context manager that yields ``advance(amount)``
        (``raycore bench`` passes its progress bar's stages).
    """
    args = parser().parse_args(argv)
    start, load_at_start = time.perf_counter(), os.getloadavg()[0]
    names = args.meshes or meshes.benchmark_meshes(args.quick, large=not args.no_large)

    if args.variant_output:
        variant, path = args.variant_output
        first_builds()
        results = [bench_mesh(name, args.quick, args.rounds, variant) for name in names]
        Path(path).write_text(json.dumps(
            {"numba_threads": numba.get_num_threads(),
             "cpu_name": os.environ.get("NUMBA_CPU_NAME"), "meshes": results}))
        return

    with progress("first builds"):
        first = first_builds()
    results = []
    with progress("meshes", total=len(names)) as advance:
        for name in names:
            results.append(bench_mesh(name, args.quick, args.rounds))
            print(report.mesh_summary(results[-1]), flush=True)
            advance()
    with progress("one thread, in a subprocess"):
        one_thread = variant_run(ONE_THREAD, names, args.quick, args.rounds)
    avx2 = None
    if compiled_for_avx512():
        with progress("AVX2 kernels, in a subprocess"):
            avx2 = variant_run(AVX2, names, args.quick, args.rounds)
    document = {"machine": machine(), "first_build_seconds": first, "rounds": args.rounds,
                "meshes": results, "one_thread": one_thread, "avx2": avx2,
                "duration_seconds": time.perf_counter() - start,
                "load_average": {"start": load_at_start, "end": os.getloadavg()[0]}}
    out = args.out or (Path(tempfile.mkdtemp(prefix="raycore-bench-")) if args.quick
                       else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(document, indent=1) + "\n")
    (out / "bench.md").write_text(report.markdown(document))
    print(f"{out / 'bench.md'} written in {document['duration_seconds']:.0f} s")


if __name__ == "__main__":
    main()
