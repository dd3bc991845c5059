"""Queries from many threads at once, and from children forked after a query.

raycore runs Numba's parallel loops on the TBB layer, or on workqueue with one parallel loop at
a time where TBB cannot load (:mod:`raycore._threading`).  Whatever the layer: threads querying
one scene at once get the answers of one thread, nothing aborts, and a child forked after a
query answers.  ``test_the_same_with_workqueue_forced`` runs this module again in a process
where ``NUMBA_THREADING_LAYER=workqueue``.
"""

import multiprocessing
import os
import re
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

import raycore
from raycore._threading import tbb_library_path

from .scene.brute import random_scene, scene_rays

THREADS = 8
DTYPES = ("float32", "float64")
#: Long enough for a cold start (Numba compiling every kernel); only a hang takes longer.
HANG_SECONDS = 1800
ROOT = Path(__file__).resolve().parents[1]


def answers(scene, rays):
    """Every query's answer to ``rays``: {name: array}."""
    closest = scene.intersect(*rays)
    every = scene.intersect_all(*rays)
    return {"t": closest.t, "geom_id": closest.geom_id, "prim_id": closest.prim_id,
            "occluded": scene.occluded(*rays), "all_ray": every.ray_index, "all_t": every.t,
            "all_geom": every.geom_id, "all_prim": every.prim_id, "count": scene.count(*rays)}


def assert_same(got, expected):
    assert got.keys() == expected.keys()
    for name, value in expected.items():
        assert np.array_equal(got[name], value), f"{name} differs from the serial answer"


def rays():
    origins, directions, tmin, tmax, _ = scene_rays(0)
    return origins, directions, tmin, tmax


def serial_answers(dtype):
    scene = random_scene(0)[0].scene(dtype)
    expected = answers(scene.build(), rays())
    # the comparisons mean something only if the rays reach the interesting cases
    assert 0 < np.isfinite(expected["t"]).sum() < len(expected["t"])
    assert expected["count"].max() > 1
    return expected


def at_once(function, count=THREADS, rounds=3):
    """Results of ``function()`` from ``count`` threads started together, ``rounds`` each."""
    start = threading.Barrier(count)
    results, errors = [], []

    def work():
        try:
            start.wait()
            for _ in range(rounds):
                results.append(function())
        except Exception as error:  # reported by the test, not lost in the thread
            errors.append(error)

    threads = [threading.Thread(target=work) for _ in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    assert len(results) == count * rounds
    return results


def test_the_layer_is_thread_and_fork_safe():
    report = raycore.info()
    forced = os.environ.get("NUMBA_THREADING_LAYER")
    if forced:
        assert report["threading_layer"] == forced
    elif tbb_library_path() is not None:
        assert report["threading_layer"] == "tbb"
    else:
        assert report["threading_layer"] == "workqueue"
    assert report["thread_safe"] and report["fork_safe"]
    assert report["threads"] >= 1


@pytest.mark.parametrize("dtype", DTYPES)
def test_threads_query_one_built_scene_at_once(dtype):
    expected = serial_answers(dtype)
    scene = random_scene(0)[0].scene(dtype).build()
    batch = rays()
    for got in at_once(lambda: answers(scene, batch)):
        assert_same(got, expected)


@pytest.mark.parametrize("dtype", DTYPES)
def test_threads_build_a_scene_lazily_at_once(dtype):
    expected = serial_answers(dtype)
    scene = random_scene(0)[0].scene(dtype)  # not built: the first queries build it
    batch = rays()
    for got in at_once(lambda: answers(scene, batch), rounds=1):
        assert_same(got, expected)


#: Set before forking: the children inherit it (as gunicorn's preloaded workers do).
_FORKED = {}


def _child_answers(dtype):
    return answers(_FORKED[dtype], rays())


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_child_forked_after_a_query_answers(dtype):
    scene = random_scene(0)[0].scene(dtype)
    expected = answers(scene, rays())  # the parent's threads have run a parallel loop
    _FORKED[dtype] = scene
    context = multiprocessing.get_context("fork")
    # Python 3.12+ warns that forking a process with threads (here Numba's) may deadlock the
    # child: exactly what this test checks does not happen
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        with context.Pool(2) as pool:
            pending = pool.map_async(_child_answers, [dtype] * 2)
            children = pending.get(timeout=HANG_SECONDS)
    for got in children:
        assert_same(got, expected)


@pytest.mark.skipif(os.environ.get("NUMBA_THREADING_LAYER") == "workqueue",
                    reason="this is the run with the workqueue layer forced")
def test_the_same_with_workqueue_forced():
    """Workqueue aborts the process on concurrent parallel loops unless raycore serialises them:
    this module's tests, in a process on that layer."""
    tests = [f"{__file__}::{name}" for name in (
        "test_the_layer_is_thread_and_fork_safe", "test_threads_query_one_built_scene_at_once",
        "test_threads_build_a_scene_lazily_at_once", "test_a_child_forked_after_a_query_answers")]
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests],
        env={**os.environ, "NUMBA_THREADING_LAYER": "workqueue"}, cwd=ROOT, capture_output=True,
        text=True, timeout=HANG_SECONDS)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-4000:]
    assert re.search(r"\b7 passed", run.stdout), run.stdout[-2000:]


#: The least TBB interface Numba's TBB layer takes (numba/np/ufunc/parallel.py).
NUMBA_LEAST_TBB = 12060
#: Imports open3d, then raycore; prints the interface of the libtbb that answers to its name
#: (what Numba checks: the first loaded under it) and the layer raycore runs on.
OPEN3D_FIRST = """
import ctypes, sys, open3d, raycore
from raycore._threading import _TBB_LIBRARY
version = ctypes.CDLL(_TBB_LIBRARY[sys.platform]).TBB_runtime_interface_version
version.restype = ctypes.c_int
print(version(), raycore.info()["threading_layer"])
"""


@pytest.mark.skipif(tbb_library_path() is None, reason="no tbb wheel on this platform")
def test_open3d_imported_first():
    """Open3D's wheel carries a libtbb of its own (interface 12050 in Open3D 0.20):
    imported before raycore, it holds the library's name, and one older than Numba's TBB layer
    needs makes Numba refuse TBB.  raycore then runs on workqueue and says why and what to do;
    with a new enough one, on TBB, silently."""
    pytest.importorskip("open3d", reason="Open3D has no wheel for this Python")
    env = {name: value for name, value in os.environ.items()
           if name != "NUMBA_THREADING_LAYER"}
    run = subprocess.run([sys.executable, "-W", "always", "-c", OPEN3D_FIRST], env=env,
                         cwd=ROOT, capture_output=True, text=True, timeout=HANG_SECONDS)
    assert run.returncode == 0, run.stderr[-4000:]
    version, layer = run.stdout.split()[-2:]
    named = "Import raycore before open3d to run on TBB" in run.stderr
    if int(version) < NUMBA_LEAST_TBB:
        assert (layer, named) == ("workqueue", True), run.stderr[-4000:]
    else:
        assert (layer, named) == ("tbb", False), run.stderr[-4000:]
