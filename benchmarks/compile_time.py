"""Compile time of raycore's kernels, cold and warm, and the time to a first answer.

Numba compiles a kernel at its first call and caches it on disk; a new installation (or a new
kind of CPU) compiles, later processes load.  Each measurement below runs in a fresh Python
process whose Numba cache is a new, empty directory (``NUMBA_CACHE_DIR``), so that "cold" means
what a user meets after ``pip install``:

* ``first answer, build()`` and ``first answer, intersect builds``: import raycore, add a
  512-triangle mesh, build it (or let ``intersect`` build it), cast 10 float32 rays; the wall time
  of the whole process, as the user waits for it, and its parts;
* ``warmup``: ``raycore warmup --dtype float32``, in a cache of its own;
* ``warm``: the first-answer script, then warmup again, in warmup's cache;
* ``shipped``: the first answers and the warm-up again, each in a fresh process, in a new virtual
  environment where the wheel that carries the kernels (``make wheel``,
  release/ship_kernels.py) is installed, with no Numba cache on the machine for it: what a user
  of that wheel meets after ``pip install``.

Per kernel, "cold" is the seconds Numba spent compiling it during warmup (its compile events,
less the kernels compiled inside it), summed over its signatures; "warm" is the seconds its
cache took to load in the warm process.  Writes benchmarks/results/compile.json and prints the
figures.  Run with ``python -m benchmarks.compile_time`` (part of ``make bench``).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "compile.json"
SHIP = Path(__file__).resolve().parents[1] / "release" / "ship_kernels.py"
#: Cells per side of the first answer's grid mesh: 2 * 16**2 = 512 triangles.
GRID = 16
RAYS = 10
#: Kernels listed in the printed table (the JSON has them all).
TOP = 20


def _grid_mesh():
    """(vertices, faces) of a wavy square of 2 * GRID**2 triangles."""
    import numpy as np

    u, v = np.meshgrid(np.linspace(0, 1, GRID + 1), np.linspace(0, 1, GRID + 1))
    vertices = np.column_stack([u.ravel(), v.ravel(), 0.1 * np.sin(3 * u.ravel())])
    corner = (np.arange(GRID)[:, None] * (GRID + 1) + np.arange(GRID)).ravel()
    faces = np.concatenate([np.column_stack([corner, corner + 1, corner + GRID + 2]),
                            np.column_stack([corner, corner + GRID + 2, corner + GRID + 1])])
    return vertices, faces


class _CompileClock:
    """Exclusive seconds of each kernel's compiles in this process, from Numba's compile events
    (a kernel's compile holds those of the kernels it calls, which are subtracted)."""

    def __init__(self):
        from numba.core import event

        self.seconds = defaultdict(float)
        self._open = []
        clock = self

        class Listener(event.Listener):
            def on_start(self, ev):
                clock._open.append([_kernel_name(ev.data["dispatcher"].py_func),
                                    time.perf_counter(), 0.0])

            def on_end(self, ev):
                name, began, inner = clock._open.pop()
                spent = time.perf_counter() - began
                clock.seconds[name] += spent - inner
                if clock._open:
                    clock._open[-1][2] += spent

        event.register("numba:compile", Listener())


def _kernel_name(function):
    return f"{function.__module__}.{function.__qualname__}"


class _LoadClock:
    """Seconds each kernel's cache took to load in this process (Numba's ``Cache``, wrapped)."""

    def __init__(self):
        from numba.core import caching

        self.seconds = defaultdict(float)
        load = caching.Cache.load_overload
        clock = self

        def timed(cache, sig, target_context):
            began = time.perf_counter()
            try:
                return load(cache, sig, target_context)
            finally:
                clock.seconds[_kernel_name(cache._py_func)] += time.perf_counter() - began

        caching.Cache.load_overload = timed


def _first_answer(build_first):
    """Seconds to import raycore, to build (when ``build_first``) and to answer, in turn."""
    began = time.perf_counter()
    import numpy as np

    import raycore

    imported = time.perf_counter()
    vertices, faces = _grid_mesh()
    scene = raycore.Scene("float32")
    scene.add_mesh(vertices, faces)
    if build_first:
        scene.build()
    built = time.perf_counter()
    origins = np.tile(np.float32([0.5, 0.5, 1.0]), (RAYS, 1))
    directions = np.tile(np.float32([0.0, 0.0, -1.0]), (RAYS, 1))
    hits = scene.intersect(origins, directions)
    answered = time.perf_counter()
    assert np.all(hits.geom_id == 0), "the first answer missed the mesh"
    return {"import_s": imported - began, "build_s": built - imported,
            "intersect_s": answered - built}


def _child(mode):
    """Run one measurement in this process and print its figures as JSON."""
    compiles = _CompileClock()
    loads = _LoadClock() if mode == "warm" else None
    figures = {}
    if mode != "warmup":  # warm: the script again, then the warm-up, on warmup's cache
        figures.update(_first_answer(build_first=mode != "answer-intersect"))
    if mode in ("warmup", "warm"):
        from raycore._warmup import warm_up

        figures["warmup_s"] = warm_up(("float32",), report=lambda line: None)
    if loads is not None:
        figures["load_s"] = dict(loads.seconds)
    figures["compile_s"] = dict(compiles.seconds)
    print(json.dumps(figures))


def _run(mode, cache=None, python=sys.executable):
    """Figures of ``_child(mode)`` in a fresh process of ``python`` on Numba cache ``cache``
    (None: the one beside raycore's sources), with the wall time of the whole process
    (``process_s``)."""
    # this file runs by its path (it imports nothing but the standard library at the top), in
    # an empty folder, so that the interpreter's own raycore is the one measured
    environment = {key: value for key, value in os.environ.items()
                   if key not in ("NUMBA_CACHE_DIR", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    if cache is not None:
        environment["NUMBA_CACHE_DIR"] = cache
    began = time.perf_counter()
    with tempfile.TemporaryDirectory() as empty:
        done = subprocess.run([python, __file__, "--child", mode], cwd=empty, env=environment,
                              capture_output=True, text=True, check=True)
    figures = json.loads(done.stdout.splitlines()[-1])
    figures["process_s"] = time.perf_counter() - began
    return figures


def measure():
    with tempfile.TemporaryDirectory() as first, tempfile.TemporaryDirectory() as second, \
            tempfile.TemporaryDirectory() as warmed:
        document = {
            "first_answer_build": _run("answer-build", first),
            "first_answer_intersect_builds": _run("answer-intersect", second),
            "warmup": _run("warmup", warmed),
            "warm": _run("warm", warmed),
        }
    with tempfile.TemporaryDirectory() as shipped:
        began = time.perf_counter()
        subprocess.run([sys.executable, str(SHIP), "--dest", f"{shipped}/dist",
                        "--install-into", f"{shipped}/venv"], capture_output=True, check=True)
        document["make_wheel_s"] = time.perf_counter() - began
        python = f"{shipped}/venv/bin/python"
        document["shipped"] = {mode: _run(mode, python=python) for mode in
                               ("answer-build", "answer-intersect", "warmup")}
    document.update(machine_cpus=os.cpu_count(), load_average=os.getloadavg(),
                    python=sys.version.split()[0], triangles=2 * GRID**2, rays=RAYS)
    return document


def _report(document):
    for key in ("first_answer_build", "first_answer_intersect_builds", "warm"):
        row = document[key]
        print(f"{key:30s} process {row['process_s']:6.1f} s  (import {row['import_s']:.1f}, "
              f"build {row['build_s']:.1f}, intersect {row['intersect_s']:.1f}; compiling "
              f"{sum(row['compile_s'].values()):.1f} s)")
    warmup, warm = document["warmup"], document["warm"]
    print(f"{'warmup --dtype float32':30s} process {warmup['process_s']:6.1f} s  (compiling "
          f"{sum(warmup['compile_s'].values()):.1f} s); warm cache: {warm['warmup_s']:.1f} s, "
          f"loading {sum(warm['load_s'].values()):.1f} s")
    for mode, row in document["shipped"].items():
        print(f"{'wheel with kernels, ' + mode:30s} process {row['process_s']:6.1f} s  "
              f"(compiling {sum(row['compile_s'].values()):.1f} s)")
    cold = warmup["compile_s"]
    print(f"\n{'kernel':56s} {'cold s':>7s} {'warm ms':>8s}")
    for name in sorted(cold, key=cold.get, reverse=True)[:TOP]:
        print(f"{name:56s} {cold[name]:7.2f} {1e3 * warm['load_s'].get(name, 0.0):8.1f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        _child(args.child)
        return
    document = measure()
    RESULTS.write_text(json.dumps(document, indent=1) + "\n")
    _report(document)


if __name__ == "__main__":
    main()
