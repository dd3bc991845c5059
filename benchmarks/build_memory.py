"""Peak memory of one build, measured in a fresh process (Linux: reads /proc/self/status).

``python -m benchmarks.build_memory MESH CONTENDER`` prints one JSON object.  The process
imports the contender's library, makes one warm-up build of a small mesh (so that loading
Numba's cache or Embree's thread pool is not counted), converts the mesh to the contender's
native inputs, and then measures the build (mesh added, tree built, one ray traced, as in
``benchmarks.contenders``): its peak resident memory above the resident memory before it.  For
raycore it also gives the finished tree's size (``Scene.stats()["bytes"]``): the peak minus the
tree is what the build's temporaries took (the scene's own copy of the input included).
"""

import argparse
import gc
import json

import numpy as np

from benchmarks import contenders, meshes

#: contender -> (native inputs from (vertices, faces), build from those inputs)
BUILDS = {
    "raycore": (lambda v, f: contenders.raycore_mesh(v, f, np.float32),
                lambda mesh: contenders.raycore_build(mesh, np.float32)),
    "open3d": (contenders.open3d_mesh, contenders.open3d_build),
    "embreex": (contenders.embreex_mesh, contenders.embreex_build),
}


def memory_kib():
    """(resident, peak resident) memory of this process in KiB."""
    fields = {}
    with open("/proc/self/status") as status:
        for line in status:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                fields[key] = int(value.split()[0])
    return fields["VmRSS"], fields["VmHWM"]


def reset_peak():
    """Start the peak resident memory (VmHWM) afresh from the current resident memory."""
    with open("/proc/self/clear_refs", "w") as clear_refs:
        clear_refs.write("5")


def measure(mesh_name, contender):
    """Peak and retained memory of building ``mesh_name`` with ``contender``, in bytes."""
    native, build = BUILDS[contender]
    build(native(*meshes.warm_up_mesh()))
    vertices, faces = meshes.load(mesh_name)
    inputs = native(vertices, faces)
    del vertices, faces
    gc.collect()
    reset_peak()
    before, _ = memory_kib()
    scene = build(inputs)
    after, peak = memory_kib()
    report = {"mesh": mesh_name, "contender": contender, "peak_extra_bytes": (peak - before) * 1024,
              "retained_extra_bytes": (after - before) * 1024}
    if contender == "raycore":
        report["tree_bytes"] = scene.stats()["bytes"]
        report["temporaries_bytes"] = report["peak_extra_bytes"] - report["tree_bytes"]
    return report


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh", help="a name from benchmarks.meshes")
    parser.add_argument("contender", choices=sorted(BUILDS))
    args = parser.parse_args(argv)
    print(json.dumps(measure(args.mesh, args.contender)))


if __name__ == "__main__":
    main()
