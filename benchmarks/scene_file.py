"""Loading a saved scene against building it, and the file's size against a pickle's.

For each mesh (every shared mesh, and nefertiti subdivided to 1.6M triangles unless
``--no-large``): a float32 Scene of that one mesh, timed in interleaved rounds (best of
``--rounds``) after a warm-up of every call in the same process, so that no time is Numba's
compiling or cache loading:

* ``build``: ``Scene(...).add_mesh(v, f)`` then ``build()`` (validation, BVH, leaf blocks);
* ``load``: ``Scene.load(path)`` (read, checksums, every index checked, record assembled);
* ``load_mmap``: the same with ``mmap=True`` (pages read when touched; checksums read them all);
* ``unpickle``: ``pickle.loads`` of the pickled Scene;
* ``read``: ``raycore.arrayfile.read(path)``, the part of a load before the scene: the file read,
  its checksums and header checked, its arrays viewed;
* ``read_bytes``: ``Path.read_bytes()``, the file's bytes in one plain read and nothing else:
  for a small file, about the least that any loader of it in Python takes (``read`` reads a
  file of ``arrayfile.THREADED_BYTES`` or more on threads, into huge pages, and beats it).

A load that is not followed by equal answers would be worthless: each loaded scene answers
10,000 random rays and must match the built one.  Prints a table and writes
benchmarks/results/scene_file.json.  Run with ``python -m benchmarks.scene_file``.
"""

import argparse
import json
import os
import pickle
import platform
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.meshes import load, shared_mesh_names, warm_up_mesh
from benchmarks.timing import interleaved_best_times
from raycore import Scene, arrayfile

RESULTS = Path(__file__).resolve().parent / "results" / "scene_file.json"


def built(vertices, faces):
    scene = Scene("float32")
    scene.add_mesh(vertices, faces)
    return scene.build()


def measure(name, vertices, faces, directory, rounds):
    path = Path(directory) / f"{name}.rcs"
    scene = built(vertices, faces)
    scene.save(path)
    pickled = pickle.dumps(scene)
    best, results = interleaved_best_times({
        "build": lambda: built(vertices, faces),
        "load": lambda: Scene.load(path),
        "load_mmap": lambda: Scene.load(path, mmap=True),
        "unpickle": lambda: pickle.loads(pickled),
        "read": lambda: arrayfile.read(path),
        "read_bytes": path.read_bytes,
    }, rounds=rounds)
    rng = np.random.default_rng(0)
    lo, hi = scene.bounds
    origins = rng.uniform(lo, hi, (10_000, 3))
    directions = rng.normal(size=(10_000, 3))
    expected = scene.intersect(origins, directions)
    for kind in ("load", "load_mmap", "unpickle"):
        hits = results[kind].intersect(origins, directions)
        assert np.array_equal(hits.t, expected.t) and np.array_equal(hits.prim_id,
                                                                     expected.prim_id), kind
    return {"mesh": name, "triangles": len(faces), "file_bytes": path.stat().st_size,
            "pickle_bytes": len(pickled), **{f"{k}_s": v for k, v in best.items()},
            "build_over_load": best["build"] / best["load"],
            "build_over_load_mmap": best["build"] / best["load_mmap"],
            "build_over_unpickle": best["build"] / best["unpickle"]}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # 9, as the README's figures: with 3, `make bench` on the AVX-512 EPYC gave spot 7x and
    # teapot 10x where runs of 9 gave 12-13x (a best of 0.2-0.3 ms moves with the machine)
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--no-large", action="store_true")
    args = parser.parse_args(argv)
    names = shared_mesh_names() + ([] if args.no_large else ["nefertiti-1.6M"])
    rows = []
    with tempfile.TemporaryDirectory() as directory:
        measure("warm-up", *warm_up_mesh(), directory, 1)
        for name in names:
            rows.append(measure(name, *load(name), directory, args.rounds))
            row = rows[-1]
            print(f"{name:16s} {row['triangles']:>9,d} tris  build {row['build_s']:.4f} s  "
                  f"load {row['load_s']:.4f} s ({row['build_over_load']:.0f}x)  "
                  f"mmap {row['load_mmap_s']:.4f} s ({row['build_over_load_mmap']:.0f}x)  "
                  f"unpickle {row['unpickle_s']:.4f} s  read {row['read_s'] * 1e6:.0f} us "
                  f"(bytes {row['read_bytes_s'] * 1e6:.0f} us)  file {row['file_bytes']:,d} B  "
                  f"pickle {row['pickle_bytes']:,d} B", flush=True)
    RESULTS.write_text(json.dumps({"machine": platform.processor() or platform.machine(),
                                   "cpus": os.cpu_count(), "load_average": os.getloadavg(),
                                   "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
