"""Answers do not depend on the CPU's SIMD extensions.

CI and development machines are AVX2-only EPYCs and AVX-512 Zen 4s.  A child process here
computes as an AVX2-only machine does, whatever this one is: OpenBLAS's Haswell kernels (which
OpenBLAS also picks for Zen 1-3), Numba kernels compiled for an AVX2 Zen 2 with every AVX-512
feature off (into an empty cache, so they are compiled for that target), and NumPy's loops
without AVX-512.  It runs the brute-force comparison on the instances and transformed boxes of
the seed-1 scene, where a fresh clone failed on the AVX2 machine (ray 583, float64: a 1e-14
difference in t), and its answers there and on the whole scene (every kind of object) must equal
this process's bit for bit, as must the rays the library makes for cameras and LiDAR scans
(:func:`sensor_rays`: a camera's rays differed for one field of view in 200).

The child compiles its kernels from scratch: about a minute on an idle 2-core machine (up to 4
under load); the queries themselves take a few seconds.
"""

import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from raycore import camera, sensors

from .brute import SceneSpec, compare_all, compare_closest, random_scene, scene_rays

SEED = 1
ROOT = Path(__file__).resolve().parents[2]
#: NumPy's dispatch targets beyond AVX2 (unknown names are ignored, with an ImportWarning).
NUMPY_AVX512 = "X86_V4 AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR"


def transformed_objects(seed):
    """The instances (with their prototypes) and transformed boxes of :func:`random_scene`."""
    spec, _ = random_scene(seed)
    part = SceneSpec()
    prototypes = {}
    for obj in spec.objects:
        if obj.kind == "instance":
            if obj.mesh not in prototypes:
                proto = spec.objects[obj.mesh]
                prototypes[obj.mesh] = part.mesh(proto.vertices, proto.faces, visible=False)
            part.instance(prototypes[obj.mesh], obj.transform)
        elif obj.kind == "tbox":
            part.tbox(*obj.args)
    return part


def answers(dtype, path):
    """Check the queries on :func:`transformed_objects` against brute force, and save their
    answers and those on the whole seeded scene to ``path`` (.npz)."""
    spec = transformed_objects(SEED)
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    ref = spec.reference(origins, directions, dtype=dtype, tmin=tmin, tmax=tmax)
    fields = ("uv", "normal", "point")
    saved = {}
    for name, scene in [("transformed", spec.scene(dtype)),
                        ("scene", random_scene(SEED)[0].scene(dtype))]:
        hits = scene.intersect(origins, directions, tmin, tmax, fields=fields)
        all_hits = scene.intersect_all(origins, directions, tmin, tmax)
        saved.update({f"{name}_{key}": value for key, value in [
            ("t", hits.t), ("geom", hits.geom_id), ("prim", hits.prim_id), ("uv", hits.uv),
            ("normal", hits.normal), ("point", hits.point), ("all_t", all_hits.t),
            ("all_geom", all_hits.geom_id), ("all_prim", all_hits.prim_id)]})
        if name == "transformed":
            excused = (compare_closest(hits, ref, spec, fields=fields)
                       + compare_all(all_hits, ref, spec))
            assert excused <= 0.02 * len(origins)
    # the data: hits on instances and on boxes
    assert np.sum(ref.instance) > 500 and np.sum(~ref.instance) > 50
    saved.update(sensor_rays())
    np.savez(path, **saved)


def sensor_rays():
    """Rays that the library makes from a few numbers: cameras of many fields of view (NumPy's
    float64 ``tan`` runs SVML's loop on AVX-512 CPUs, which differed from the AVX2 loop in the
    last bit for about one angle in 200), the cameras that frame a box, and LiDAR scans from
    tilted poses."""
    saved = {}
    fovs = np.linspace(1.0, 179.0, 397)
    cameras = [camera.perspective_camera((0.3, -1.7, 4.1), (0.2, 0.5, -0.9), (0.1, 1.0, 0.2), fov,
                                         16, 9) for fov in fovs]
    saved["camera_scales"] = np.array([(c.x_scale, c.y_scale) for c in cameras])
    saved["camera_axes"] = np.array([(c.center, c.right, c.up) for c in cameras])
    # 253: one whose scales NumPy's two loops made differently
    saved["camera_rays"] = np.stack(cameras[253].rays("float64", samples=4, seed=7))
    framed = [camera.frame_box((-1.3, 0.2, -0.7), (2.9, 1.1, 0.4), 64, 48, fov=fov)
              for fov in fovs[::8]]
    saved["framed_positions"] = np.array([position for position, _, _ in framed])
    saved["framed_heights"] = np.array([height for _, _, height in framed])
    for k, (forward, up) in enumerate([((1.0, 0.3, -0.2), (0.1, -0.2, 1.0)),
                                       ((-0.4, 2.0, 0.7), (0.3, 0.9, -0.1))]):
        scan = sensors.lidar((0.5, -2.0, 1.2), forward, up, preset="velodyne-vlp16", columns=720)
        saved[f"lidar_{k}"] = scan.directions
    return saved


def avx2_environment(cache):
    """The environment of a process that computes as an AVX2-only x86-64 CPU."""
    import llvmlite.binding as llvm

    def avx512(name):
        return name.startswith(("avx512", "avx10", "amx", "evex512"))

    features = llvm.get_host_cpu_features()
    return dict(
        os.environ,
        OPENBLAS_CORETYPE="Haswell",
        NUMBA_CPU_NAME="znver2",
        NUMBA_CPU_FEATURES=",".join(("+" if on and not avx512(name) else "-") + name
                                    for name, on in sorted(features.items())),
        NUMBA_CACHE_DIR=str(cache),
        NPY_DISABLE_CPU_FEATURES=NUMPY_AVX512,
        PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    )


def host_has_avx2():
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    import llvmlite.binding as llvm

    return bool(llvm.get_host_cpu_features().get("avx2"))


@pytest.mark.skipif(not host_has_avx2(), reason="forces an AVX2 x86-64 target")
def test_an_avx2_only_cpu_gives_the_same_answers(tmp_path):
    child = tmp_path / "avx2.npz"
    run = subprocess.run(
        [sys.executable, "-c", "import sys; from tests.scene.test_other_cpu import answers; "
         "answers('float64', sys.argv[1])", str(child)],
        cwd=ROOT, env=avx2_environment(tmp_path / "numba"), capture_output=True, text=True,
        timeout=1200)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    # the child really compiled for its own target, into its own cache
    assert any((tmp_path / "numba").rglob("*.nbi"))
    here = tmp_path / "native.npz"
    answers("float64", here)
    with np.load(child) as theirs, np.load(here) as ours:
        for name in ours.files:
            assert np.array_equal(theirs[name], ours[name], equal_nan=True), name
