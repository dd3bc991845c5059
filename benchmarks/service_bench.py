"""HTTP service overhead: the service's answers against in-process ``Scene`` calls, same scene.

A real ``raycore serve`` (uvicorn) on loopback, driven with the service's Python client
(:class:`service.client.Client`), and a ~100k-triangle scene
(nefertiti from ../shared/meshes when present, else a procedural torus of 100k triangles) on a
floor plane:

* intersect: ~1M rays (1024x1024 camera rays, and 1M random rays from inside the bounds) as a
  float32 (N, 6) .npy body, answered as .npy; end to end (encode, send, trace, answer, decode)
  against ``Scene.intersect`` on the same arrays.  Bar: HTTP throughput >= 50 % of in-process.
* render: a 512x512 lambert PNG with shadows against the in-process time of tracing its primary
  and shadow rays (``Scene.intersect`` + ``Scene.occluded`` inside ``raycore.render``).
  Bar: HTTP time <= 1.5x.

The service's own share of each HTTP time (its Server-Timing header: from the request's arrival,
body included, to the answer's start) is recorded as ``http_server_s``.  Best of a few
interleaved runs each (the machine's load average is recorded: on a shared machine the ratios
move with it).  Prints the ratios and writes benchmarks/results/service.json.
Run with ``python -m benchmarks.service_bench [--repeats N]``.
"""

import argparse
import io
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import trimesh

from benchmarks.rays import camera_rays, random_rays
from raycore import Scene
from raycore.camera import perspective_rays
from raycore.mesh import load_trimesh
from raycore.render import render
from service.client import Client
from service.demo import torus
from service.process import running_service

NEFERTITI = Path(__file__).resolve().parents[2] / "shared" / "meshes" / "nefertiti.obj"
RESULTS = Path(__file__).resolve().parent / "results" / "service.json"
RENDER_SIZE = 512
BARS = {"intersect_throughput_ratio_min": 0.5, "render_time_ratio_max": 1.5}


def mesh_file():
    """(name, PLY bytes) of the benchmark mesh."""
    if NEFERTITI.exists():
        name, mesh = "nefertiti", trimesh.load(NEFERTITI, force="mesh", process=False)
    else:
        vertices, faces = torus(rings=250, sides=200)
        name, mesh = "torus-100k", trimesh.Trimesh(vertices, faces, process=False)
    stream = io.BytesIO()
    mesh.export(stream, file_type="ply")
    return name, stream.getvalue()


def floor_under(lo, hi):
    """A plane just below the mesh, facing +y, so that the render has cast shadows."""
    return {"point": [0.0, lo[1] - 0.01 * (hi[1] - lo[1]), 0.0], "normal": [0.0, 1.0, 0.0]}


class TimedScene:
    """A Scene whose ``intersect`` and ``occluded`` calls add up their wall time."""

    def __init__(self, scene):
        self.scene = scene
        self.seconds = 0.0

    def __getattr__(self, name):
        return getattr(self.scene, name)

    def __len__(self):
        return len(self.scene)

    def _timed(self, method, *args, **kwargs):
        start = time.perf_counter()
        result = method(*args, **kwargs)
        self.seconds += time.perf_counter() - start
        return result

    def intersect(self, *args, **kwargs):
        return self._timed(self.scene.intersect, *args, **kwargs)

    def occluded(self, *args, **kwargs):
        return self._timed(self.scene.occluded, *args, **kwargs)


def server_seconds(client):
    """The service's own time for the client's last request, from its Server-Timing header."""
    return float(client.last_headers["server-timing"].split("dur=")[1]) / 1000


def stopwatch(function):
    """Wall time of one call, and its result."""
    start = time.perf_counter()
    result = function()
    return time.perf_counter() - start, result


def bench_intersect(client, scene_id, scene, rays, repeats):
    origins, directions = (np.ascontiguousarray(a, dtype=np.float32) for a in rays)
    local = remote = server = np.inf
    for _ in range(repeats):  # interleaved, so that drifts in machine load hit both
        seconds, hits = stopwatch(lambda: scene.intersect(origins, directions))
        local = min(local, seconds)
        seconds, table = stopwatch(lambda: client.intersect(scene_id, origins, directions))
        remote, server = min(remote, seconds), min(server, server_seconds(client))
    np.testing.assert_array_equal(table["t"], hits.t)  # the same answers
    count = len(origins)
    return {"rays": count, "hit_fraction": float(hits.hit.mean()),
            "in_process_s": local, "http_s": remote, "http_server_s": server,
            "in_process_mrays_s": count / local / 1e6, "http_mrays_s": count / remote / 1e6,
            "ratio": local / remote}


def bench_render(client, scene_id, scene, camera, repeats):
    # as the service makes them, in the scene's precision
    rays = perspective_rays(camera["position"], camera["look_at"], camera["up"], camera["fov"],
                            RENDER_SIZE, RENDER_SIZE, scene.dtype)
    trace = full = remote = server = np.inf
    for _ in range(repeats):
        timed = TimedScene(scene)
        seconds, image = stopwatch(lambda timed=timed: render(timed, *rays, RENDER_SIZE,
                                                              RENDER_SIZE))
        trace, full = min(trace, timed.seconds), min(full, seconds)
        seconds, png = stopwatch(lambda: client.render(scene_id, camera, "lambert"))
        remote, server = min(remote, seconds), min(server, server_seconds(client))
    shadowed = float(np.mean(np.all(image == image.reshape(-1, 3).min(axis=0), axis=2)))
    return {"pixels": RENDER_SIZE**2, "in_process_trace_s": trace, "in_process_render_s": full,
            "http_s": remote, "http_server_s": server, "png_bytes": len(png),
            "darkest_pixel_fraction": shadowed, "ratio": remote / trace}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10,
                        help="interleaved runs per intersect measurement; renders (cheaper) get "
                             "three times as many")
    args = parser.parse_args(argv)

    name, data = mesh_file()
    mesh = load_trimesh(io.BytesIO(data), "ply")
    lo, hi = mesh.bounds
    floor = floor_under(lo, hi)
    scene = Scene(dtype="float32")
    scene.add_mesh(mesh.vertices, mesh.faces)
    scene.add_plane(**floor)
    scene.build()
    center, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    camera = {"type": "perspective", "position": (center + 2.5 * radius * np.array(
        [0.3, 0.5, 1.0]) / np.linalg.norm([0.3, 0.5, 1.0])).tolist(), "look_at": center.tolist(),
        "up": [0.0, 1.0, 0.0], "fov": 45.0, "width": RENDER_SIZE, "height": RENDER_SIZE}
    # 1024x1024 camera rays make 1,048,576 rays: raise the default limit to fit them
    with running_service({"RAYCORE_MAX_RAYS": str(2**21)}) as url, Client(
            url, timeout=600) as client:
        upload = client.upload_mesh(data, "ply")
        scene_id = client.create_scene({"dtype": "float32", "objects": [
            {"type": "mesh", "mesh": upload["id"]}, {"type": "plane", **floor}]})["id"]
        report = {
            "mesh": name, "triangles": int(len(mesh.faces)),
            "repeats": {"intersect": args.repeats, "render": 3 * args.repeats},
            "machine": {"python": platform.python_version(), "processor": platform.machine(),
                        "cpus": os.cpu_count(), "load_average_1min": os.getloadavg()[0]},
            "intersect": {
                "camera": bench_intersect(client, scene_id, scene,
                                          camera_rays(lo, hi, 1024, 1024), args.repeats),
                "random": bench_intersect(client, scene_id, scene, random_rays(lo, hi, 2**20),
                                          args.repeats)},
            "render": bench_render(client, scene_id, scene, camera, 3 * args.repeats),
            "bars": BARS,
        }
    ratios = [report["intersect"][kind]["ratio"] for kind in ("camera", "random")]
    report["passed"] = bool(min(ratios) >= BARS["intersect_throughput_ratio_min"]
                            and report["render"]["ratio"] <= BARS["render_time_ratio_max"])
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(report, indent=2) + "\n")
    print(f"{name}, {report['triangles']} triangles")
    for kind in ("camera", "random"):
        row = report["intersect"][kind]
        print(f"intersect {kind:6s} {row['rays']} rays: in-process {row['in_process_mrays_s']:.2f}"
              f" Mrays/s, HTTP {row['http_mrays_s']:.2f} Mrays/s (service's own time "
              f"{row['http_server_s']:.3f} of {row['http_s']:.3f} s), ratio {row['ratio']:.2f} "
              f"(bar >= {BARS['intersect_throughput_ratio_min']})")
    row = report["render"]
    print(f"render {RENDER_SIZE}x{RENDER_SIZE} lambert: in-process trace "
          f"{row['in_process_trace_s']:.3f} s (whole render {row['in_process_render_s']:.3f} s), "
          f"HTTP {row['http_s']:.3f} s (service's own time {row['http_server_s']:.3f} s), "
          f"ratio {row['ratio']:.2f} "
          f"(bar <= {BARS['render_time_ratio_max']})")
    print(f"{'PASS' if report['passed'] else 'FAIL'}; written to {RESULTS}")
    return report


if __name__ == "__main__":
    main()
