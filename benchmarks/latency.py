"""Time per call against rays per call: raycore, Open3D and embreex, from 1 ray to 1M.

Many calls are small (a robot's handful of rays per control step, a picked pixel, a
line-of-sight question), and there the fixed cost of a call is the library's speed.  This
measures it: random rays from inside nefertiti's bounds (float32, 99,938 triangles), the first n
of one set of 1M rays for each batch size n, as C-contiguous arrays in each library's native form
(``benchmarks.contenders``), made before any clock starts.  Each contender's own call is timed:

* closest hit: raycore ``intersect``, Open3D ``cast_rays``, embreex ``run(output=1)``;
* any hit: raycore ``occluded``, Open3D ``test_occlusions``, embreex ``run(query="OCCLUDED")``.

One measurement repeats a call until at least ``MIN_SECONDS`` pass, timing each call, and gives
the mean time per call and the median; each figure is the best of ``REPEATS`` measurements taken
in interleaved rounds over the contenders.  The mean is what a loop of calls costs; the median
shows the typical call when a few calls stall (on a machine shared with other work, a parallel
region can wait milliseconds for a thread the system has not scheduled).  Batches of
``FRESH_FROM`` rays or more are also timed with fresh rays at each call: the calls take the
set's consecutive slices of n rays in turn, so that no call finds the nodes its rays visit in
the caches from the call before.  Writes
benchmarks/results/latency.json, docs/latency.md and the log-log chart docs/latency.png.
Run with ``python -m benchmarks.latency [--quick]`` (part of ``make bench``).
"""

import argparse
import itertools
import json
import os
import tempfile
import time
from functools import partial
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks import contenders, meshes  # noqa: E402
from benchmarks.rays import random_rays  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MESH = "nefertiti"
BATCHES = (1, 4, 16, 64, 256, 1024, 4096, 16_384, 65_536, 262_144, 1_048_576)
QUICK_BATCHES = (1, 16, 256, 4096, 65_536)
REPEATS = 3
MIN_SECONDS = 0.2
#: Batches from this size on are timed with fresh rays too.  A loop of calls on the same rays
#: keeps the tree's nodes that they visit in the caches, and a library gains from that as far
#: as its threads take the same rays at each call: on the 2-core AVX2 EPYC, 4,096 rays took
#: Open3D 413-438 us a call repeated and 603-666 fresh, raycore 547-562 and 622-634 (medians).
FRESH_FROM = 1024
#: (query, library) -> label, in the order of the table's columns
LABELS = {
    ("closest", "raycore"): "raycore intersect",
    ("closest", "open3d"): "Open3D cast_rays",
    ("closest", "embreex"): "embreex run(output=1)",
    ("any", "raycore"): "raycore occluded",
    ("any", "open3d"): "Open3D test_occlusions",
    ("any", "embreex"): 'embreex run(query="OCCLUDED")',
}
COLORS = {"raycore": "tab:red", "open3d": "tab:blue", "embreex": "tab:green"}


def seconds_per_call(call, min_seconds):
    """(mean, median) wall time of ``call()`` over as many calls as fill ``min_seconds``, after
    a tenth of that in untimed calls (the other libraries' worker threads, still spinning from
    their last calls, settle then)."""
    warm_until = time.perf_counter() + min_seconds / 10
    while time.perf_counter() < warm_until:
        call()
    durations, total = [], 0.0
    while total < min_seconds:
        start = time.perf_counter()
        call()
        durations.append(time.perf_counter() - start)
        total += durations[-1]
    return total / len(durations), float(np.median(durations))


def calls_for(scenes, origins, directions):
    """(query, library) -> function of no arguments, on rays in each library's native form."""
    raycore, open3d, embreex = scenes
    tensor = contenders.open3d_rays(origins, directions)
    return {
        ("closest", "raycore"): partial(raycore.intersect, origins, directions),
        ("closest", "open3d"): partial(open3d.cast_rays, tensor),
        ("closest", "embreex"): partial(embreex.run, origins, directions, output=1),
        ("any", "raycore"): partial(raycore.occluded, origins, directions),
        ("any", "open3d"): partial(open3d.test_occlusions, tensor),
        ("any", "embreex"): partial(embreex.run, origins, directions, query="OCCLUDED"),
    }


def cycling(calls):
    """A function of no arguments that makes one of ``calls`` at each call, in turn."""
    turns = itertools.cycle(calls)
    return lambda: next(turns)()


def measure(batches, min_seconds):
    """``(times, fresh_times, hit_fraction)``: {batch: {(query, library): (mean, median)
    seconds per call, each the best of ``REPEATS`` measurements}} on the same rays at each call,
    the same with fresh rays at each call (batches from FRESH_FROM rays, smaller than the set),
    and the fraction of the rays that hit."""
    vertices, faces = meshes.load(MESH)
    scenes = (
        contenders.raycore_build(contenders.raycore_mesh(vertices, faces, np.float32),
                                 np.float32),
        contenders.open3d_build(contenders.open3d_mesh(vertices, faces)),
        contenders.embreex_build(contenders.embreex_mesh(vertices, faces)),
    )
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    origins, directions = contenders.embreex_arrays(*random_rays(lo, hi, max(batches), seed=2))
    hit_fraction = float(np.mean(
        scenes[1].test_occlusions(contenders.open3d_rays(origins, directions)).numpy()))
    times, fresh_times = {}, {}
    for batch in batches:
        calls = {("same", *key): call for key, call in
                 calls_for(scenes, origins[:batch], directions[:batch]).items()}
        if FRESH_FROM <= batch < len(origins):
            # inputs in native form for every slice, made before any clock starts
            slices = [calls_for(scenes, origins[start:start + batch],
                                directions[start:start + batch])
                      for start in range(0, len(origins) - batch + 1, batch)]
            calls.update({("fresh", *key): cycling([made[key] for made in slices])
                          for key in LABELS})
        for call in calls.values():
            call()  # first calls (kernel loading, thread pools) outside the timing
        best = dict.fromkeys(calls, (np.inf, np.inf))
        for _ in range(REPEATS):
            for key, call in calls.items():
                mean, median = seconds_per_call(call, min_seconds)
                best[key] = (min(best[key][0], mean), min(best[key][1], median))
        for rays, found in (("same", times), ("fresh", fresh_times)):
            row = {key[1:]: value for key, value in best.items() if key[0] == rays}
            if row:
                found[batch] = row
                print(f"{batch:>9,} {rays} rays: " + ", ".join(
                    f"{LABELS[key]} {_format(mean)} ({_format(median)})"
                    for key, (mean, median) in row.items()), flush=True)
    return times, fresh_times, hit_fraction


def _format(seconds):
    """A time per call with a unit that keeps 2-4 significant digits."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.1f} µs"
    if seconds < 1:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def _time_label(seconds, _position=None):
    """A tick label: 1 µs, 10 µs, ..., 1 ms, ..., 1 s."""
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("ns", 1e-9)):
        if seconds >= scale * 0.999:
            return f"{seconds / scale:g} {unit}"
    return f"{seconds:g} s"


def _count_label(count, _position=None):
    """A tick label: 1, 16, 256, 4k, 64k, 1M."""
    for suffix, scale in (("M", 2**20), ("k", 2**10)):
        if count >= scale:
            return f"{count / scale:g}{suffix}"
    return f"{count:g}"


def chart(times, path, title):
    """Log-log chart of time per call against rays per call, closest and any hit side by side:
    the mean per call in solid lines, the median call in dotted lines."""
    batches = sorted(times)
    figure, axes = plt.subplots(1, 2, figsize=(11, 5), sharey=True)
    for ax, query, name in zip(axes, ("closest", "any"), ("closest hit", "any hit"),
                               strict=True):
        for library, color in COLORS.items():
            means, medians = zip(*(times[b][(query, library)] for b in batches), strict=True)
            ax.loglog(batches, means, "o-", color=color, label=LABELS[(query, library)],
                      markersize=4)
            ax.loglog(batches, medians, ":", color=color, linewidth=1)
        ax.set_title(name)
        ax.set_xlabel("rays per call")
        ax.set_xticks(batches[::2] if len(batches) > 6 else batches)
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(_count_label))
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.yaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(_time_label))
        ax.grid(True, which="major", alpha=0.4)
        ax.grid(True, which="minor", alpha=0.1)
        ax.plot([], [], ":", color="gray", label="dotted: median call")
        ax.legend(loc="upper left", fontsize=9)
    axes[0].set_ylabel("time per call (mean of a loop of calls)")
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def markdown(times, fresh_times, hit_fraction, duration, load_average):
    """docs/latency.md: the table of the chart, its rows again with fresh rays at each call,
    and raycore's time over Open3D's."""
    lines = [
        "# Time per call against rays per call",
        "",
        "![time per call](latency.png)",
        "",
        f"Random rays from inside {MESH}'s bounds ({hit_fraction:.0%} of them hit something), "
        "float32, as C-contiguous arrays in each library's native form, each library's own "
        f"call timed; best of {REPEATS} measurements of at least {MIN_SECONDS} s of calls each, "
        "in interleaved rounds. Each cell: mean time per call over a loop of calls (median "
        "call in brackets). embreex is serial; raycore and Open3D use both cores. Ratio: "
        "raycore's time over Open3D's (< 1: raycore is faster), of the means (of the medians). "
        f"Measured {time.strftime('%Y-%m-%d')} in {duration:.0f} s "
        f"(`python -m benchmarks.latency`) on a 2-core machine shared with other work (load "
        f"average {load_average[0]:.1f} at the start, {load_average[1]:.1f} at the end): the "
        "figures are indicative.",
        "",
        "Every call of the loop casts the same rays (the set's first n):",
        "",
        *_table(times),
    ]
    if fresh_times:
        lines += ["", "Fresh rays at each call: the loop's calls take the set's consecutive "
                  "slices of n rays in turn, so that the caches do not hold the nodes that a "
                  "call's rays visit from the call before (what a stream of different rays "
                  "meets):", "", *_table(fresh_times)]
    return "\n".join(lines) + "\n"


def _table(times):
    """The markdown table's lines of ``times`` ({batch: {(query, library): (mean, median)}})."""
    keys = list(LABELS)

    def ratio(row, query, which):
        return row[(query, "raycore")][which] / row[(query, "open3d")][which]

    lines = ["| rays per call | " + " | ".join(LABELS[k] for k in keys)
             + " | intersect / cast_rays | occluded / test_occlusions |",
             "|---:|" + "---:|" * (len(keys) + 2)]
    for batch in sorted(times):
        row = times[batch]
        cells = [f"{_format(row[k][0])} ({_format(row[k][1])})" for k in keys]
        cells += [f"{ratio(row, query, 0):.2f} ({ratio(row, query, 1):.2f})"
                  for query in ("closest", "any")]
        lines.append(f"| {batch:,} | " + " | ".join(cells) + " |")
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="five batch sizes, short measurements: a smoke run, written to a "
                             "temporary folder unless --out is given")
    parser.add_argument("--out", type=Path, help="folder for latency.png, .md and .json "
                        "(default: docs/ and benchmarks/results/)")
    args = parser.parse_args(argv)
    if args.quick and args.out is None:
        args.out = Path(tempfile.mkdtemp(prefix="raycore-latency-"))
    docs = args.out or ROOT / "docs"
    results = args.out or ROOT / "benchmarks" / "results"
    docs.mkdir(parents=True, exist_ok=True)
    start, load_at_start = time.perf_counter(), os.getloadavg()[0]
    batches, min_seconds = (QUICK_BATCHES, 0.02) if args.quick else (BATCHES, MIN_SECONDS)
    times, fresh_times, hit_fraction = measure(batches, min_seconds)
    duration = time.perf_counter() - start
    chart(times, docs / "latency.png",
          f"Time per call, random rays inside {MESH} (float32, 2 cores)")
    load_average = (load_at_start, os.getloadavg()[0])
    (docs / "latency.md").write_text(markdown(times, fresh_times, hit_fraction, duration,
                                              load_average))

    def per_call(found):
        return {str(batch): {f"{q}/{lib}": {"mean": mean, "median": median}
                             for (q, lib), (mean, median) in row.items()}
                for batch, row in found.items()}

    record = {"mesh": MESH, "hit_fraction": hit_fraction, "duration_seconds": duration,
              "load_average": load_average, "seconds_per_call": per_call(times),
              "fresh_rays_seconds_per_call": per_call(fresh_times)}
    (results / "latency.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"{docs / 'latency.png'} and latency.md written in {duration:.0f} s")


if __name__ == "__main__":
    main()
