"""Speed against accuracy, on one page: ``make chart``.

Writes, under ``docs/``:

* ``speed-vs-accuracy.png`` and ``.md``: every method and precision (triangle: watertight,
  moller, geometric; sphere: precise, geometric, analytic; float32 and float64) and the anchors
  (embreex, Open3D, trimesh), with throughput on a log x-axis and, one panel each, the leak rate
  on closed meshes, the hit/miss disagreement with the exact reference and the median relative
  t error.  The error figures come from the failure-case catalogue of ``tests/stability``
  (``tests/stability/catalogue.py``), whose tables follow the summary in the Markdown file.
* ``model-what-you-need.png`` and ``.md``: a sphere as an analytic primitive against
  tessellated spheres of growing resolution (throughput, memory, error of t against the exact
  sphere), and N instances of one mesh against the same geometry flattened into one mesh
  (memory, build time, throughput).

Throughput: closest hits of 512 x 512 camera rays (``benchmarks.rays.camera_rays``), the best of
three interleaved rounds (every contender once per round, each warmed up on its rays first):
on nefertiti (../shared/meshes, 100k triangles) for the triangle tests and the anchors (trimesh
on a fixed subset, every 1031st ray, in every round), on one analytic sphere for the sphere
methods; the share of rays that hit is reported with them.  Each anchor's own call is timed,
on inputs already in its native form, as ``benchmarks.run`` times them (Open3D's
``cast_rays`` on an (N, 6) float32 Tensor, embreex's ``run`` on contiguous float32 arrays,
trimesh's ``intersects_id``).
Seeds are fixed; timings vary from run to run and machine to machine.
"""

import argparse
import os
import platform
import time
from functools import partial
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import trimesh  # noqa: E402

from benchmarks.anchors import ANCHORS  # noqa: E402
from benchmarks.contenders import embreex_arrays, open3d_rays  # noqa: E402
from benchmarks.rays import camera_rays  # noqa: E402
from benchmarks.run import best_time  # noqa: E402
from benchmarks.timing import interleaved_best_times  # noqa: E402
from raycore import Scene  # noqa: E402
from raycore.primitives.analytic import PARAM_WIDTH  # noqa: E402
from tests.primitives import reference  # noqa: E402
from tests.stability import catalogue  # noqa: E402
from tests.stability.catalogue import (  # noqa: E402
    CASES,
    DTYPES,
    METHODS,
    QUADRIC,
    SPAWN_PLACES,
    SPAWN_STRATEGIES,
    measure,
    measure_anchor,
    nefertiti_case,
    self_intersection,
    shared_mesh,
)

DOCS = Path(__file__).resolve().parents[1] / "docs"
CAMERA = 512
#: trimesh's throughput: every TRIMESH_STRIDE-th camera ray (255 of 262,144; a stride prime to
#: the image's width spreads them over the whole image, whose first rows all miss, so that they
#: hit as often as the full set; trimesh takes ~6 ms a ray that hits nefertiti, and is called
#: four times)
TRIMESH_STRIDE = 1031
#: trimesh on the catalogue's mesh cases: at most this many rays per case (it is ~1e4 times
#: slower), and fewer on nefertiti
TRIMESH_CASE_RAYS = {"edges-nefertiti": 300}
TRIMESH_CASE_DEFAULT = 1500
#: nefertiti's edges subsampled for the leak figures (of 150k; 3 origins, 3 points per edge)
NEFERTITI_EDGES = 40_000

COLORS = {
    "triangle watertight": "tab:blue", "triangle moller": "tab:orange",
    "triangle geometric": "tab:green", "sphere precise": "tab:red",
    "sphere geometric": "tab:purple", "sphere analytic": "tab:brown",
    "embreex": "black", "open3d": "tab:gray", "trimesh": "tab:olive",
}
MARKERS = {"float32": "o", "float64": "s"}
FLOOR = {"leak": 1e-6, "disagreement": 1e-6, "t_error": 1e-18}


def _log(message):
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


# ----------------------------------------------------------------------------- throughput


def _mrays(seconds, count):
    return count / seconds / 1e6


def throughput():
    """Mrays/s of every method, precision and anchor on camera rays (see the module doc), and
    the share of those rays that hit: ``(speed, hit fractions)``, the latter keyed "mesh",
    "trimesh subset" and "sphere"."""
    vertices, faces = shared_mesh("nefertiti")
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    origins, directions = camera_rays(lo, hi, CAMERA, CAMERA)
    # every contender's input is built before the clock; each timed call holds only its own
    # call, and all are timed in the same interleaved rounds
    calls, counts = {}, {}
    for dtype in DTYPES:
        scene = Scene(dtype=dtype)
        scene.add_mesh(vertices, faces)
        scene.build()
        o, d = origins.astype(dtype), directions.astype(dtype)
        for method in METHODS[:3]:
            scene.intersect(o[:1000], d[:1000], **method.options)  # compile outside the timing
            calls[(method.label, dtype)] = partial(scene.intersect, o, d, **method.options)
            counts[(method.label, dtype)] = len(o)
    # each anchor's own call, on inputs already in its native form (benchmarks.contenders);
    # the anchors' ``closest`` normalises the outputs too, and is never timed
    o32, d32 = embreex_arrays(origins, directions)
    rays = open3d_rays(o32, d32)
    # trimesh (~1e4 times slower) on a fixed subset, the same in every round
    o_sub, d_sub = (np.ascontiguousarray(a[::TRIMESH_STRIDE]) for a in (origins, directions))
    for anchor_class in ANCHORS:
        anchor = anchor_class(vertices, faces)
        if anchor.name == "trimesh":
            key, count = (anchor.name, "float64"), len(o_sub)
            calls[key] = partial(anchor.intersector.intersects_id, o_sub, d_sub,
                                 multiple_hits=False, return_locations=True)
        else:
            key, count = (anchor.name, "float32"), len(o32)
            if anchor.name == "open3d":
                calls[key] = partial(anchor.scene.cast_rays, rays)
            else:
                calls[key] = partial(anchor.scene.run, o32, d32, output=1)
        calls[key]()  # warm up on the very rays it is timed on (first-call costs)
        counts[key] = count
    seconds, results = interleaved_best_times(calls, rounds=3)
    speed = {key: _mrays(seconds[key], counts[key]) for key in calls}
    hits = results[(METHODS[0].label, "float64")].hit
    hit_fraction = {"mesh": float(hits.mean()),
                    "trimesh subset": float(hits[::TRIMESH_STRIDE].mean())}
    del calls, results
    # the sphere methods: one analytic sphere framed like the mesh
    center, radius = np.array([0.5, -0.25, 1.0]), 1.0
    origins, directions = camera_rays(center - radius, center + radius, CAMERA, CAMERA)
    calls = {}
    for dtype in DTYPES:
        scene = Scene(dtype=dtype)
        scene.add_sphere(center, radius)
        o, d = origins.astype(dtype), directions.astype(dtype)
        for method in METHODS[3:]:
            scene.intersect(o[:1000], d[:1000], **method.options)
            calls[(method.label, dtype)] = partial(scene.intersect, o, d, **method.options)
    seconds, results = interleaved_best_times(calls, rounds=3)
    speed.update({key: _mrays(seconds[key], len(origins)) for key in calls})
    hit_fraction["sphere"] = float(results[(METHODS[3].label, "float64")].hit.mean())
    return speed, hit_fraction


# ----------------------------------------------------------------------------- accuracy


def accuracy():
    """Outcomes of every method (and anchor) on every case of its family.

    Returns
    -------
    results : dict
        ``(label, dtype) -> {case name: Outcome}``.
    cases : list of Case
        The catalogue's cases plus nefertiti's edges (when the shared meshes are there).
    """
    cases = list(CASES)
    nefertiti = nefertiti_case(count=NEFERTITI_EDGES)
    if nefertiti is not None:
        cases.insert(4, nefertiti)
    results = {}
    for case in cases:
        for dtype in DTYPES:
            for method in case.methods():
                results.setdefault((method.label, dtype), {})[case.name] = measure(
                    case, method, dtype)
        if case.family == "triangle":
            for anchor_class in ANCHORS:
                limit = None
                dtype = "float32"
                if anchor_class.name == "trimesh":
                    limit = TRIMESH_CASE_RAYS.get(case.name, TRIMESH_CASE_DEFAULT)
                    dtype = "float64"
                results.setdefault((anchor_class.name, dtype), {})[case.name] = (
                    measure_anchor(case, anchor_class, limit=limit))
        _log(f"accuracy: {case.name}")
    return results, cases


def summarize(outcomes, cases):
    """The three figures of one method: mean leak rate over the leak cases, mean hit/miss
    disagreement over every case, median relative t error over all common hits; and the number
    of claimed rays it got wrong."""
    panel = {case.name: case.panel for case in cases}
    leaks = [o.leak_rate for name, o in outcomes.items() if panel[name] == "leak"]
    errors = np.concatenate([o.errors for o in outcomes.values()])
    return {
        "leak": float(np.mean(leaks)) if leaks else float("nan"),
        "disagreement": float(np.mean([o.disagreement for o in outcomes.values()])),
        "t_error": float(np.median(errors)) if len(errors) else float("nan"),
        "claimed_wrong": sum(o.claimed_wrong for o in outcomes.values()),
        "claimed": sum(o.claimed for o in outcomes.values()),
    }


# ----------------------------------------------------------------------------- chart 1

PANELS = (
    ("leak", "leak rate on closed meshes\n(rays through shared edges and vertices, from inside)"),
    ("disagreement", "hit/miss disagreement with the exact reference\n(mean over the "
                     "catalogue's cases)"),
    ("t_error", "median relative t error\n(common hits, all cases)"),
)


def _labels(ax, points):
    """Annotate (x, y, text, color) points, stacking the labels of points that nearly
    coincide (log scales) so that they do not overprint."""
    placed = []
    for x, y, text, color in sorted(points, key=lambda p: (p[1], p[0])):
        lift = 0
        for px, py, plift in placed:
            if abs(np.log10(x / px)) < 0.35 and abs(np.log10(y / py)) < 0.25:
                lift = max(lift, plift + 1)
        placed.append((x, y, lift))
        ax.annotate(text, (x, y), xytext=(6, -3 + 8 * lift), textcoords="offset points",
                    fontsize=7, color=color)


def chart_speed_accuracy(rows, path):
    families = (("triangle", "Triangles (throughput: nefertiti, 100k triangles)"),
                ("sphere", "Spheres (throughput: one analytic sphere)"))
    fig, axes = plt.subplots(2, 3, figsize=(17, 10), constrained_layout=True)
    for line, (family, family_title) in zip(axes, families, strict=True):
        members = [r for r in rows if r["family"] == family
                   or (family == "triangle" and r["family"] == "anchor")]
        for ax, (key, title) in zip(line, PANELS, strict=True):
            floor = FLOOR[key]
            points = []
            for row in members:
                value = row[key]
                if not np.isfinite(value) or not np.isfinite(row["mrays"]):
                    continue
                anchor = row["family"] == "anchor"
                y = max(value, floor)
                ax.scatter(row["mrays"], y, s=140 if anchor else 55,
                           marker="*" if anchor else MARKERS[row["dtype"]],
                           color=COLORS[row["label"]], zorder=3)
                short = row["label"].split()[-1] + ("" if anchor else f" {row['dtype'][-2:]}")
                points.append((row["mrays"], y, short, COLORS[row["label"]]))
            _labels(ax, points)
            ax.set_xscale("log")
            ax.set_yscale("log")
            _, high = ax.get_ylim()
            ax.set_ylim(floor / 3, 2.0 if key != "t_error" else max(high * 3, floor * 100))
            ticks = [t for t in ax.get_yticks() if floor < t < ax.get_ylim()[1]]
            ax.set_yticks([floor] + ticks)
            ax.set_yticklabels(["0"] + [f"{t:.0e}" for t in ticks])
            ax.axhline(floor * 1.8, color="0.8", lw=0.8, zorder=1)
            low, high = ax.get_xlim()
            ax.set_xlim(low / 1.5, high * 2)
            ax.set_xlabel("throughput, Mrays/s (log)", fontsize=8)
            if family == "sphere" and key == "leak":
                title = "leak rate\n(rays from inside a sphere 1e4 away, some near its surface)"
            ax.set_title(f"{family_title}\n{title}", fontsize=9)
            ax.grid(True, which="major", alpha=0.3)
    handles = [plt.Line2D([], [], ls="", marker="o", color=c, label=label)
               for label, c in COLORS.items()]
    handles += [plt.Line2D([], [], ls="", marker=m, color="0.4", label=dtype)
                for dtype, m in MARKERS.items()]
    handles.append(plt.Line2D([], [], ls="", marker="*", color="0.4", markersize=11,
                              label="anchor (float32; trimesh float64)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=6, fontsize=8)
    fig.suptitle("raycore: speed against accuracy, every method and precision (points on the "
                 "bottom line of a panel are exactly 0)", fontsize=12)
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)


def _pct(x):
    if not np.isfinite(x):
        return "–"
    return "0" if x == 0 else f"{100 * x:.3g} %"


def _sci(x):
    if not np.isfinite(x):
        return "–"
    return "0" if x == 0 else f"{x:.1e}"


def table_speed_accuracy(rows, results, cases, spawn, seconds, hit_fraction):
    lines = [
        "# Speed against accuracy",
        "",
        "Generated by `make chart` (`benchmarks/speed_accuracy.py`); do not edit.  "
        f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, {platform.python_version()}; "
        f"the run took {seconds:.0f} s.",
        "",
        "![speed against accuracy](speed-vs-accuracy.png)",
        "",
        "## Summary",
        "",
        "Throughput: 512 x 512 camera rays (nefertiti, 100k triangles, for the triangle tests "
        f"and the anchors, {_pct(hit_fraction['mesh'])} of them hit; trimesh on a fixed subset "
        f"of every {TRIMESH_STRIDE}st of them ({len(range(0, CAMERA**2, TRIMESH_STRIDE)):,} "
        "rays) "
        "in every round, "
        f"{_pct(hit_fraction['trimesh subset'])} of which hit; one analytic sphere for the "
        f"sphere methods, {_pct(hit_fraction['sphere'])} of the rays hit), the best of 3 "
        "interleaved rounds, each contender warmed up on its rays first.  Leak rate: mean over "
        "the leak cases (rays from inside closed surfaces through shared edges and vertices); "
        "disagreement: mean over all the family's cases of the share of rays whose hit/miss "
        "differs from the exact reference; t error: median over all common hits.  "
        "Claimed: rays on which the method claims to agree with the exact reference (see "
        "`tests/stability/catalogue.py`), and how many of them it got wrong.",
        "",
        "| method | precision | Mrays/s | leak rate | disagreement | median rel. t error "
        "| claimed rays wrong |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        claimed = (f"{row['claimed_wrong']} of {row['claimed']}" if row["claims"] else "–")
        lines.append(f"| {row['label']} | {row['dtype']} | {row['mrays']:.3g} "
                     f"| {_pct(row['leak'])} | {_pct(row['disagreement'])} "
                     f"| {_sci(row['t_error'])} | {claimed} |")
    lines += ["", "## The catalogue, case by case", "",
              "Hit/miss disagreement with the exact reference (leaks: the exact answer hits, "
              "the method misses); in brackets, claimed rays gotten wrong where the method "
              "makes a claim.  The same numbers are printed by `pytest tests/stability -s`.",
              ""]
    for family, title in (("triangle", "Triangles"), ("sphere", "Spheres"),
                          ("quadric", "Cylinders and cones (one method each)")):
        labels = [key for key in results
                  if any(c.family == family and c.name in results[key] for c in cases)]
        lines += [f"### {title}", "",
                  "| case | " + " | ".join(f"{label} {dtype}" for label, dtype in labels) + " |",
                  "|---|" + "---:|" * len(labels)]
        for case in cases:
            if case.family != family:
                continue
            cells = []
            for key in labels:
                outcome = results[key].get(case.name)
                if outcome is None:
                    cells.append("–")
                    continue
                cell = _pct(outcome.disagreement)
                claims = key[0] in ("triangle watertight", "sphere precise", QUADRIC.label)
                if claims:
                    cell += f" ({outcome.claimed_wrong} of {outcome.claimed})"
                cells.append(cell)
            lines.append(f"| {case.name}: {case.title} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["### Secondary rays", "",
              "Rays spawned on a closed convex surface (a sphere: analytic for the sphere "
              "methods, 1280 triangles for the triangle tests; `box-surface`: origins exactly on "
              "a tessellated box's faces), half leaving it and half entering it: the share that "
              "re-hits the surface it leaves (or, entering, escapes).", "",
              "| method | precision | place | " + " | ".join(SPAWN_STRATEGIES) + " |",
              "|---|---|---|" + "---:|" * len(SPAWN_STRATEGIES)]
    for (label, dtype, place), rates in spawn.items():
        lines.append(f"| {label} | {dtype} | {place} | "
                     + " | ".join(_pct(rates[s]) for s in SPAWN_STRATEGIES) + " |")
    return "\n".join(lines) + "\n"


def secondary_rays():
    spawn = {}
    for method in METHODS:
        for dtype in DTYPES:
            for place in SPAWN_PLACES:
                if place == "box-surface" and method.family != "triangle":
                    continue
                spawn[(method.label, dtype, place)] = {
                    s: self_intersection(method, dtype, place, s) for s in SPAWN_STRATEGIES}
    return spawn


# ----------------------------------------------------------------------------- chart 2


def model_sphere(subdivisions=range(0, 8)):
    """An analytic sphere against icospheres: triangles, bytes, Mrays/s, t error, disagreement
    with the exact sphere (camera rays, float32, default methods)."""
    center, radius = np.array([0.5, -0.25, 1.0]), 1.0
    origins, directions = camera_rays(center - radius, center + radius, CAMERA, CAMERA)
    o32, d32 = catalogue.f32(origins), catalogue.f32(directions)
    count = len(o32)
    exact = reference.sphere(o32, d32, center, radius, np.zeros(count), np.full(count, np.inf))
    rows = []

    def measure_scene(name, triangles, scene):
        scene.build()
        scene.intersect(o32[:1000], d32[:1000])
        seconds, hits = best_time(scene.intersect, o32, d32, repeats=3)
        t = hits.t.astype(np.float64)
        both = np.isfinite(t) & np.isfinite(exact)
        error = np.abs(t[both] - exact[both]) / exact[both]
        # stats() counts BVHs and triangles; an analytic shape adds its parameter row
        row_bytes = 0 if triangles else PARAM_WIDTH * np.dtype(np.float32).itemsize
        rows.append({"name": name, "triangles": triangles,
                     "bytes": scene.stats()["bytes"] + row_bytes, "mrays": _mrays(seconds, count),
                     "t_error_median": float(np.median(error)),
                     "t_error_max": float(error.max()),
                     "disagreement": float(np.mean(np.isfinite(t) != np.isfinite(exact)))})

    scene = Scene(dtype="float32")
    scene.add_sphere(center, radius)
    measure_scene("analytic sphere", 0, scene)
    for level in subdivisions:
        mesh = trimesh.creation.icosphere(subdivisions=level, radius=radius)
        scene = Scene(dtype="float32")
        scene.add_mesh(mesh.vertices + center, mesh.faces)
        measure_scene(f"icosphere {level}", len(mesh.faces), scene)
        _log(f"model: icosphere {level}")
    return rows


def model_instances(counts=(1, 4, 16, 64, 256)):
    """N copies of one mesh on a grid: as instances of one mesh, and flattened into one mesh
    (float32): bytes, build seconds, Mrays/s on camera rays framing the grid."""
    mesh = shared_mesh("spot")
    if mesh is None:
        sphere = trimesh.creation.icosphere(subdivisions=4)
        mesh = (np.asarray(sphere.vertices), np.asarray(sphere.faces))
    vertices, faces = mesh
    extent = vertices.max(axis=0) - vertices.min(axis=0)
    step = 1.5 * extent.max()
    rows = []
    for n in counts:
        side = int(np.ceil(np.sqrt(n)))
        rng = np.random.default_rng(n)
        transforms = []
        for k in range(n):
            angle = rng.uniform(0, 2 * np.pi)
            matrix = np.eye(4)
            matrix[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                              [-np.sin(angle), 0, np.cos(angle)]]
            matrix[:3, 3] = [step * (k % side), 0.0, step * (k // side)]
            transforms.append(matrix)
        instanced = Scene(dtype="float32")
        prototype = instanced.add_mesh(vertices, faces, visible=False)
        for matrix in transforms:
            instanced.add_instance(prototype, matrix)
        flat = Scene(dtype="float32")
        flat.add_mesh(np.concatenate([vertices @ m[:3, :3].T + m[:3, 3] for m in transforms]),
                      np.concatenate([faces + k * len(vertices) for k in range(n)]))
        world = np.concatenate([vertices @ m[:3, :3].T + m[:3, 3] for m in transforms])
        origins, directions = camera_rays(world.min(axis=0), world.max(axis=0), CAMERA, CAMERA)
        o32, d32 = origins.astype(np.float32), directions.astype(np.float32)
        for name, scene in (("instances", instanced), ("flattened", flat)):
            start = time.perf_counter()
            scene.build()
            build = time.perf_counter() - start
            scene.intersect(o32[:1000], d32[:1000])
            seconds, hits = best_time(scene.intersect, o32, d32, repeats=2)
            rows.append({"name": name, "n": n, "triangles": n * len(faces),
                         "bytes": scene.stats()["bytes"], "build_s": build,
                         "mrays": _mrays(seconds, len(o32)), "hit": float(hits.hit.mean())})
        _log(f"model: {n} copies")
    return rows


def chart_model(spheres, instances, path):
    fig, axes = plt.subplots(2, 3, figsize=(16, 9), constrained_layout=True)
    analytic = spheres[0]
    meshes = spheres[1:]
    tris = [r["triangles"] for r in meshes]
    for ax, key, label in ((axes[0, 0], "mrays", "throughput, Mrays/s"),
                           (axes[0, 1], "bytes", "memory (BVH + triangles), bytes"),
                           (axes[0, 2], "t_error_median", "relative t error vs the exact sphere")):
        ax.plot(tris, [r[key] for r in meshes], "o-", color="tab:blue",
                label="tessellated sphere (icosphere 0..7)")
        if key == "t_error_median":
            ax.plot(tris, [r["t_error_max"] for r in meshes], "o--", color="tab:blue",
                    alpha=0.5, label="tessellated, max")
            ax.plot(tris, [max(r["disagreement"], 1e-7) for r in meshes], "^:",
                    color="tab:green", label="tessellated, hit/miss disagreement")
        ax.axhline(max(analytic[key], 1e-12), color="tab:red", ls="-",
                   label=f"analytic sphere ({_sci(analytic[key])})")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("triangles")
        ax.set_title(label, fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8)
    for ax, key, label in ((axes[1, 0], "bytes", "memory (BVHs + triangles), bytes"),
                           (axes[1, 1], "build_s", "build time, s"),
                           (axes[1, 2], "mrays", "throughput, Mrays/s")):
        for name, style in (("instances", "o-"), ("flattened", "s--")):
            rows = [r for r in instances if r["name"] == name]
            ax.plot([r["n"] for r in rows], [r[key] for r in rows], style, label=name)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("copies of the mesh (spot, 5,856 triangles)")
        ax.set_title(label, fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Model no more than the scene needs: a sphere as a primitive vs tessellated "
                 "(top); N instances vs one flattened mesh (bottom); float32, 512 x 512 camera "
                 "rays", fontsize=11)
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)


def table_model(spheres, instances):
    lines = ["# Model no more than the scene needs", "",
             "Generated by `make chart` (`benchmarks/speed_accuracy.py`); do not edit.", "",
             "![model what you need](model-what-you-need.png)", "",
             "## A sphere: analytic primitive or tessellation", "",
             "float32, 512 x 512 camera rays framing a unit sphere; t compared with the exact "
             "sphere (`tests/primitives/reference.py`).", "",
             "| geometry | triangles | bytes | Mrays/s | median rel. t error | max rel. t error "
             "| hit/miss disagreement |", "|---|---:|---:|---:|---:|---:|---:|"]
    for r in spheres:
        lines.append(f"| {r['name']} | {r['triangles']:,} | {r['bytes']:,} | {r['mrays']:.3g} "
                     f"| {_sci(r['t_error_median'])} | {_sci(r['t_error_max'])} "
                     f"| {_pct(r['disagreement'])} |")
    lines += ["", "## N copies of one mesh: instances or one flattened mesh", "",
              "float32; the copies stand on a grid, each turned about the vertical axis; "
              "512 x 512 camera rays framing them all.", "",
              "| copies | triangles | layout | bytes | build s | Mrays/s | rays that hit |",
              "|---:|---:|---|---:|---:|---:|---:|"]
    for r in instances:
        lines.append(f"| {r['n']} | {r['triangles']:,} | {r['name']} | {r['bytes']:,} "
                     f"| {r['build_s']:.3f} | {r['mrays']:.3g} | {100 * r['hit']:.1f} % |")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- main


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DOCS, help="output folder (docs/)")
    parser.add_argument("--dump", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if shared_mesh("nefertiti") is None:
        raise SystemExit(f"{catalogue.SHARED_MESHES} is missing: the charts need the shared "
                         "meshes beside the repository")
    start = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    _log("throughput")
    speed, hit_fraction = throughput()
    _log("accuracy")
    results, cases = accuracy()
    _log("secondary rays")
    spawn = secondary_rays()
    rows = []
    for (label, dtype), outcomes in results.items():
        if label == QUADRIC.label:
            continue
        family = label.split()[0] if " " in label else "anchor"
        row = {"label": label, "dtype": dtype, "family": family,
               "mrays": speed.get((label, dtype), float("nan")),
               "claims": label in ("triangle watertight", "sphere precise")}
        row.update(summarize(outcomes, cases))
        rows.append(row)
    order = list(COLORS)
    rows.sort(key=lambda r: (order.index(r["label"]), r["dtype"]))
    if args.dump:
        import pickle

        args.dump.write_bytes(pickle.dumps(rows))
    chart_speed_accuracy(rows, args.out / "speed-vs-accuracy.png")
    _log("model")
    spheres = model_sphere()
    instances = model_instances()
    chart_model(spheres, instances, args.out / "model-what-you-need.png")
    (args.out / "model-what-you-need.md").write_text(table_model(spheres, instances))
    seconds = time.perf_counter() - start
    (args.out / "speed-vs-accuracy.md").write_text(
        table_speed_accuracy(rows, results, cases, spawn, seconds, hit_fraction))
    _log(f"wrote {args.out}/speed-vs-accuracy.png/.md and model-what-you-need.png/.md "
         f"in {seconds:.0f} s")


if __name__ == "__main__":
    main()
