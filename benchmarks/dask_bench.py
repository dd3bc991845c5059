"""raycore.dask on a local cluster against Scene.intersect in process, same scene and rays.

nefertiti (99,938 triangles, from ../shared/meshes) in float32; ``--rays`` random rays from
inside its bounds (the fraction that hits is recorded), made once on the client as NumPy
arrays.  Three ways, in interleaved rounds after a warm-up of each, best of ``--rounds``:

* ``in_process``: ``Scene.intersect(origins, directions)`` (every core on Numba's threads);
* ``local_cluster``: ``raycore.dask.intersect`` on a ``distributed.LocalCluster`` of
  ``--workers`` processes of one Dask thread each (each call on Numba's threads, so that the
  processes share the cores), rays in chunks of ``--chunk``, scattered to the workers before the
  clock starts, t, geom_id and prim_id gathered back to the client (the scene's transfer is
  part of every round: a new graph sends it again);
* ``dask_threads``: the same graph on Dask's threaded scheduler, in this process.

Prints rays per second and writes benchmarks/results/dask.json.  Run with
``python -m benchmarks.dask_bench``.
"""

import argparse
import json
import os
import platform

import dask
import dask.array as da
import numpy as np
from distributed import Client, LocalCluster

import raycore.dask
from benchmarks.meshes import load
from benchmarks.timing import interleaved_best_times
from raycore import Scene

RESULTS = os.path.join(os.path.dirname(__file__), "results", "dask.json")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=4_000_000)
    parser.add_argument("--chunk", type=int, default=250_000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    vertices, faces = load("nefertiti")
    scene = Scene("float32")
    scene.add_mesh(vertices, faces)
    scene.build()
    rng = np.random.default_rng(0)
    lo, hi = scene.bounds
    origins = rng.uniform(lo, hi, (args.rays, 3)).astype(np.float32)
    directions = rng.normal(size=(args.rays, 3)).astype(np.float32)
    hit_fraction = float(scene.occluded(origins, directions).mean())

    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        chunks = (args.chunk, 3)
        remote_o = client.persist(da.from_array(origins, chunks=chunks))
        remote_d = client.persist(da.from_array(directions, chunks=chunks))
        local_o = da.from_array(origins, chunks=chunks)
        local_d = da.from_array(directions, chunks=chunks)

        def on_cluster():
            hits = raycore.dask.intersect(scene, remote_o, remote_d)
            return dask.compute(hits, scheduler=client.get)[0]

        def on_threads():
            hits = raycore.dask.intersect(scene, local_o, local_d)
            return dask.compute(hits, scheduler="threads")[0]

        calls = {"in_process": lambda: scene.intersect(origins, directions),
                 "local_cluster": on_cluster, "dask_threads": on_threads}
        interleaved_best_times(calls, rounds=1)  # warm-up: kernels loaded in every process
        best, results = interleaved_best_times(calls, rounds=args.rounds)
    expected = results["in_process"]
    for name in ("local_cluster", "dask_threads"):
        assert np.array_equal(results[name]["t"], expected.t), name
    rates = {name: args.rays / seconds for name, seconds in best.items()}
    for name, rate in rates.items():
        print(f"{name:14s} {rate / 1e6:6.2f} Mrays/s  ({best[name]:.3f} s for {args.rays:,d} "
              f"rays, {rate / rates['in_process']:.2f}x in-process)")
    with open(RESULTS, "w") as out:
        json.dump({"machine": platform.processor() or platform.machine(),
                   "cpus": os.cpu_count(), "load_average": os.getloadavg(),
                   "rays": args.rays, "chunk": args.chunk, "workers": args.workers,
                   "hit_fraction": hit_fraction, "seconds": best,
                   "rays_per_second": rates}, out, indent=1)
        out.write("\n")


if __name__ == "__main__":
    main()
