"""Markdown tables of ``benchmarks.run``'s results (benchmarks/results/bench.md).

Speed ratios are raycore's throughput over the other library's (> 1: raycore is faster); build
ratios are raycore's time over Open3D's (< 1: raycore is faster).
"""

import time

#: (ray set, query) of each row of the query table
ROWS = {"camera": ("camera", "closest"), "framed": ("framed", "closest"),
        "random": ("random", "closest"), "shadow": ("shadow", "any hit"),
        "count": ("random", "count"), "intersect_all": ("random", "intersect_all")}


def speed_ratio(row, ours, theirs):
    """Throughput of ``ours`` over ``theirs`` in one ray set's row (time ratio, inverted)."""
    return row["seconds"][theirs] / row["seconds"][ours]


def _hits(key, row):
    """The hit column: percentage of rays that hit, or crossings per ray for count and all."""
    if key in ("count", "intersect_all"):
        crossings = row["mean_crossings"]
        return f"{crossings['open3d']:.2f} crossings/ray"
    fractions = row["hit_fraction"]
    text = f"{100 * fractions['open3d']:.1f} %"
    if abs(fractions["raycore-float32"] - fractions["open3d"]) > 0.005:
        text += f" (raycore {100 * fractions['raycore-float32']:.1f} %)"
    return text


def _optional(row, ours, theirs):
    return f"{speed_ratio(row, ours, theirs):.2f}" if theirs in row["seconds"] else ""


def query_table(document):
    lines = [
        "| mesh | triangles | ray set | query | rays | hits | raycore f32 Mrays/s "
        "| Open3D Mrays/s | **f32 / Open3D** | **f64 / Open3D** | f32 / embreex "
        "| former f32 / Open3D (wrapper timed) |",
        "|---|---:|---|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for mesh in document["meshes"]:
        for key, row in mesh["queries"].items():
            lines.append(
                f"| {mesh['mesh']} | {mesh['triangles']:,} | {' | '.join(ROWS[key])} "
                f"| {row['rays']:,} | {_hits(key, row)} "
                f"| {row['mrays_s']['raycore-float32']:.2f} | {row['mrays_s']['open3d']:.2f} "
                f"| **{speed_ratio(row, 'raycore-float32', 'open3d'):.2f}** "
                f"| **{speed_ratio(row, 'raycore-float64', 'open3d'):.2f}** "
                f"| {_optional(row, 'raycore-float32', 'embreex')} "
                f"| {_optional(row, 'raycore-float32', 'open3d-former-wrapper')} |")
    return lines


def thread_table(document):
    one_thread = {mesh["mesh"]: mesh["queries"] for mesh in document["one_thread"]["meshes"]}
    lines = [
        "| mesh | ray set | raycore / embreex, one thread (subprocess) "
        "| raycore / Open3D, one thread each (subprocess) | raycore / embreex, one thread "
        "(in process) | raycore gain 1 -> 2 threads | Open3D gain 1 -> 2 threads |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for mesh in document["meshes"]:
        for key in ("camera", "framed", "random"):
            row, single = mesh["queries"][key], one_thread[mesh["mesh"]][key]
            lines.append(
                f"| {mesh['mesh']} | {key} "
                f"| {speed_ratio(single, 'raycore-float32', 'embreex'):.2f} "
                f"| {speed_ratio(single, 'raycore-float32', 'open3d-1-thread'):.2f} "
                f"| {speed_ratio(row, 'raycore-float32-1-thread', 'embreex'):.2f} "
                f"| {speed_ratio(row, 'raycore-float32', 'raycore-float32-1-thread'):.2f} "
                f"| {speed_ratio(row, 'open3d', 'open3d-1-thread'):.2f} |")
    return lines


def avx2_table(document):
    """raycore's AVX2 kernels against Open3D, beside its AVX-512 kernels' ratios."""
    avx2 = {mesh["mesh"]: mesh["queries"] for mesh in document["avx2"]["meshes"]}
    lines = [
        "| mesh | ray set | query | hits | **f32 / Open3D, AVX2 kernels** "
        "| f32 / Open3D, AVX-512 kernels (above) |",
        "|---|---|---|---|---:|---:|",
    ]
    for mesh in document["meshes"]:
        for key, row in avx2[mesh["mesh"]].items():
            lines.append(
                f"| {mesh['mesh']} | {' | '.join(ROWS[key])} | {_hits(key, row)} "
                f"| **{speed_ratio(row, 'raycore-float32', 'open3d'):.2f}** "
                f"| {speed_ratio(mesh['queries'][key], 'raycore-float32', 'open3d'):.2f} |")
    return lines


def _avx2_section(document):
    """The AVX2 run's section, where there was one (the main run's kernels used AVX-512)."""
    if not document.get("avx2"):
        return []
    return [
        "## With AVX2 only (kernels compiled for x86-64-v3)",
        "",
        "raycore's kernels use AVX-512 on this machine (x86-64-v4). These rows are the "
        "closest-hit and shadow sets again in a subprocess whose kernels are compiled for "
        f"{document['avx2']['cpu_name']} (AVX2 and FMA: `NUMBA_CPU_NAME` and "
        "`NUMBA_CPU_FEATURES`, as raycore itself chooses on a CPU without AVX-512), against "
        "Open3D in the same rounds, both on "
        f"{document['avx2']['numba_threads']} threads. Open3D's Embree has no AVX-512 kernels "
        "(Open3D 0.20: no `embree::avx512` code in its library, and `perf` samples its "
        "traversal's hot loop on 256-bit registers), so this is how the two compare on a CPU "
        "with AVX2 only, on this machine's cores.",
        "",
        *avx2_table(document),
        "",
    ]


def _load_warning(document):
    """A paragraph when other work kept every core busy during the run."""
    load = document["load_average"]
    if min(load["start"], load["end"]) < document["machine"]["cpu_count"]:
        return []
    return ["", "**The load average exceeded the number of cores during this run**: a second "
            "thread often found no free core, so the two-thread figures, their ratios to serial "
            "embreex and the gains from a second thread are disturbed more than the rest."]


def _per_triangle(count, triangles):
    return f"{count / triangles:.0f}"


def build_table(document):
    lines = [
        "| mesh | triangles | raycore f32 s | raycore f64 s | Open3D s | embreex s "
        "| **raycore f32 / Open3D time** | tree B/tri f32 (f64) | raycore peak B/tri "
        "| raycore temporaries B/tri | **temporaries / tree** | Open3D peak B/tri "
        "| embreex peak B/tri |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for mesh in document["meshes"]:
        seconds, n = mesh["build_seconds"], mesh["triangles"]
        memory = ["", "", "", "", ""]  # not measured on small meshes
        if "build_memory" in mesh:
            ours = mesh["build_memory"]["raycore"]
            memory = [_per_triangle(ours["peak_extra_bytes"], n),
                      _per_triangle(ours["temporaries_bytes"], n),
                      f"**{ours['temporaries_bytes'] / ours['tree_bytes']:.1f}**",
                      *(_per_triangle(mesh["build_memory"][name]["peak_extra_bytes"], n)
                        for name in ("open3d", "embreex"))]
        lines.append(
            f"| {mesh['mesh']} | {n:,} | {seconds['raycore-float32']:.3f} "
            f"| {seconds['raycore-float64']:.3f} | {seconds['open3d']:.3f} "
            f"| {seconds['embreex']:.3f} "
            f"| **{seconds['raycore-float32'] / seconds['open3d']:.2f}** "
            f"| {_per_triangle(mesh['tree_bytes']['float32'], n)} "
            f"({_per_triangle(mesh['tree_bytes']['float64'], n)}) | " + " | ".join(memory) + " |")
    return lines


def markdown(document):
    """The whole of bench.md."""
    m = document["machine"]
    first = document["first_build_seconds"]
    return "\n".join([
        "# raycore against Open3D and embreex",
        "",
        f"Measured {time.strftime('%Y-%m-%d')} on {m['cpu']} ({m['cpu_count']} cores, "
        f"{', '.join(m['simd'])}); Numba {m['numba']}, threading layer "
        f"{m['threading_layer']}, {m['numba_threads']} threads; Open3D {m['open3d']}, embreex "
        f"{m['embreex']}; load average {document['load_average']['start']:.1f} at the start, "
        f"{document['load_average']['end']:.1f} at the end (other work shares the machine). "
        f"The run took {document['duration_seconds'] / 60:.1f} min "
        "(`python -m benchmarks.run`, see its docstring for the method).",
        "",
        "Each library's own call is timed, with its inputs already in its native form (Open3D: "
        "an (N, 6) float32 Tensor; embreex: C-contiguous float32 arrays; raycore: arrays in the "
        "scene's dtype) and its outputs as it returns them; interleaved rounds, best of "
        f"{document['rounds']}. Speed ratios: raycore's throughput over the other's (> 1: "
        "raycore is faster). raycore float64 is compared with Open3D's float32. embreex is "
        "serial (one ray per call into Embree); Open3D and raycore use both cores.",
        *_load_warning(document),
        "",
        "Meshes: the shared meshes, and nefertiti subdivided twice (1.6M triangles) and three "
        "times (6.4M) with trimesh's `subdivide` (`benchmarks/meshes.py`). Ray sets: `camera` "
        "sees the whole mesh (many rays miss); `framed` has the same eye and a view narrowed "
        "until at least 90 % of a probe's rays hit; `random` starts inside the bounds in "
        "uniform directions; `shadow` goes from the framed camera's hits (origins offset off "
        "the surface, tmin = 0) to random points on a spherical area light placed where about "
        "half of them are blocked; "
        "`count` and `intersect_all` use the random rays. 1024x1024 camera rays and 500k "
        "random rays on the shared meshes, 512x512 and 250k on the subdivided ones.",
        "",
        "## Queries",
        "",
        "The last column shows the former benchmark's method once: Open3D timed through a "
        "wrapper that stacked and cast the rays into a Tensor and converted and masked its "
        "outputs (`benchmarks.anchors.open3d_closest`). The ratios published before this "
        "benchmark were measured that way; the bold columns are the honest ones.",
        "",
        *query_table(document),
        "",
        "## Per core, and the gain from a second thread (closest hit, float32)",
        "",
        "One thread: a subprocess with `NUMBA_NUM_THREADS=1` (Numba ran "
        f"{document['one_thread']['numba_threads']} thread there) against serial embreex and "
        "Open3D with `nthreads=1`; and, in the main process, raycore under "
        "`numba.set_num_threads(1)` in the same rounds as serial embreex. Gain: the two-thread "
        "call's speed over the one-thread call's, in the same interleaved rounds.",
        "",
        *thread_table(document),
        "",
        *_avx2_section(document),
        "## Build",
        "",
        "Time: add the mesh, build, trace one ray (Embree builds on the first query), after "
        "warm-up builds in the same process; raycore's first build of the process took "
        f"{first['float32']:.1f} s in float32 and {first['float64']:.1f} s in float64 (Numba "
        "loads its cache then; the warm-up queries are not included). Memory: each build in a "
        "fresh process after a small warm-up build, peak resident memory during the build minus "
        "the resident memory before it; raycore's temporaries are that minus the finished tree "
        "(`Scene.stats()['bytes']`), the scene's own copy of the input included. Measured on "
        "the meshes of 1M triangles or more: below, allocator pools and granularity are as "
        "large as the build (Embree reuses the warm-up build's blocks).",
        "",
        *build_table(document),
        "",
    ])


def mesh_summary(mesh):
    """One line of progress for a finished mesh."""
    parts = [f"{key} {speed_ratio(row, 'raycore-float32', 'open3d'):.2f}"
             for key, row in mesh["queries"].items()]
    seconds = mesh["build_seconds"]
    return (f"{mesh['mesh']} ({mesh['triangles']:,} triangles): f32 / Open3D "
            f"{', '.join(parts)}; build time {seconds['raycore-float32'] / seconds['open3d']:.2f}x"
            " Open3D's")
