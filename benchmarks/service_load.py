"""Load test of the service (issue 7): concurrent clients against a real ``raycore serve``
(uvicorn) on 127.0.0.1, mixing intersect (JSON and .npy), render and scene builds (each a new
20k-triangle scene, so that the store fills up and evicts) for a while.

Reports throughput and p50/p99 latency, overall and per kind of request, and the service
process's resident memory (sampled every 0.2 s).  Fails (exit status 1) on any error answer or
when the peak resident memory exceeds the store budget (``--store-mib``) plus ``--margin-mib``,
the stated margin for Python, NumPy, Numba's compiled kernels and the requests in flight (about
600 MiB resident after warm-up here, before anything is stored).  Writes
benchmarks/results/load.json.  Run with ``python -m benchmarks.service_load [--seconds 60]``
(``make load``).
"""

import argparse
import asyncio
import io
import json
import os
import platform
import random
import time
from pathlib import Path

import httpx
import numpy as np
import psutil
import trimesh

from service.process import running_service

MIB = 2**20
RESULTS = Path(__file__).resolve().parent / "results" / "load.json"
CAMERA = {"type": "perspective", "position": [0, 1.5, -4], "look_at": [0, 0, 0], "fov": 50,
          "width": 96, "height": 96}


def server_process():
    """The ``raycore serve`` child of this process."""
    children = [child for child in psutil.Process().children(recursive=True)
                if "serve" in " ".join(child.cmdline())]
    assert len(children) == 1, children
    return children[0]


async def setup(client):
    """Upload a mesh, build a scene of it and a sphere; the scene's URL."""
    stream = io.BytesIO()
    trimesh.creation.icosphere(subdivisions=4).export(stream, file_type="ply")
    mesh = await client.post("/v1/meshes?format=ply", content=stream.getvalue())
    mesh.raise_for_status()
    scene = await client.post("/v1/scenes", json={"objects": [
        {"type": "mesh", "mesh": mesh.json()["id"]},
        {"type": "sphere", "center": [1.5, 0, 0], "radius": 0.5},
        {"type": "plane", "point": [0, -1, 0], "normal": [0, 1, 0]}]})
    scene.raise_for_status()
    return f"/v1/scenes/{scene.json()['id']}"


def requests(scene, rng):
    """The kinds of request clients pick from, each a function of a client."""
    json_rays = {"origins": rng.uniform(-0.2, 0.2, (256, 3)).round(4).tolist(),
                 "directions": np.column_stack([rng.uniform(-1, 1, (256, 2)),
                                                np.ones(256)]).round(4).tolist(),
                 "fields": ["normal"]}
    npy = io.BytesIO()
    origins = np.tile([0.0, 0.0, -4.0], (8192, 1))
    np.save(npy, np.hstack([origins, rng.normal(size=(8192, 3)) * [0.3, 0.3, 1] + [0, 0, 3]])
            .astype(np.float32))
    npy_rays = npy.getvalue()
    sphere = trimesh.creation.icosphere(subdivisions=5)
    faces = sphere.faces.tolist()

    def build(client):
        # a new scene each time (a random offset): the store fills and evicts as it goes
        offset = rng.uniform(-100, 100, 3)
        return client.post("/v1/scenes", json={"objects": [{
            "type": "mesh", "vertices": (sphere.vertices + offset).round(6).tolist(),
            "faces": faces}]})

    return {
        "build_scene": build,
        "intersect_json": lambda client: client.post(f"{scene}/intersect", json=json_rays),
        "intersect_npy": lambda client: client.post(
            f"{scene}/intersect?query=count", content=npy_rays,
            headers={"content-type": "application/x-npy", "accept": "application/x-npy"}),
        "render": lambda client: client.post(f"{scene}/render",
                                             json={"camera": CAMERA, "shading": "lambert"}),
    }


async def client_loop(url, kinds, deadline, seed, latencies, errors, built):
    rng = random.Random(seed)
    async with httpx.AsyncClient(base_url=url, timeout=60) as client:
        while time.monotonic() < deadline:
            kind = rng.choice(list(kinds))
            start = time.perf_counter()
            try:
                response = await kinds[kind](client)
                ok = response.status_code in (200, 201)
                detail = f"{response.status_code} {response.text[:200]}"
            except httpx.HTTPError as error:
                ok, detail = False, repr(error)
            latencies.setdefault(kind, []).append(time.perf_counter() - start)
            if not ok:
                errors.append(f"{kind}: {detail}")
            elif kind == "build_scene":
                built.append(response.json()["bytes"])


async def sample_memory(process, deadline, samples):
    while time.monotonic() < deadline:
        samples.append(process.memory_info().rss)
        await asyncio.sleep(0.2)


def summary(values):
    values = np.asarray(values)
    return {"requests": len(values), "p50_ms": round(1000 * float(np.percentile(values, 50)), 1),
            "p99_ms": round(1000 * float(np.percentile(values, 99)), 1)}


async def run(seconds, clients, store_bytes, margin):
    environment = {"RAYCORE_DEMO": "false", "RAYCORE_STORE_BYTES": str(store_bytes)}
    with running_service(environment) as url:
        process = server_process()
        async with httpx.AsyncClient(base_url=url, timeout=600) as client:
            scene = await setup(client)
            kinds = requests(scene, np.random.default_rng(0))
            for request in kinds.values():  # compile and warm before the clock starts
                (await request(client)).raise_for_status()
        baseline = process.memory_info().rss
        latencies, errors, samples, built = {}, [], [], []
        start = time.monotonic()
        deadline = start + seconds
        await asyncio.gather(sample_memory(process, deadline, samples), *[
            client_loop(url, kinds, deadline, seed, latencies, errors, built)
            for seed in range(clients)])
        elapsed = time.monotonic() - start
    everything = [value for values in latencies.values() for value in values]
    peak = max(samples)
    bound = store_bytes + margin
    return {
        "seconds": round(elapsed, 1), "clients": clients,
        "throughput_per_s": round(len(everything) / elapsed, 1),
        "all": summary(everything), **{kind: summary(values) for kind, values in latencies.items()},
        "errors": len(errors), "first_errors": errors[:5],
        "scenes_built_mib": round(sum(built) / MIB),
        "rss_mib": {"after_warmup": round(baseline / MIB), "peak": round(peak / MIB),
                    "at_each_quarter": [round(max(samples[:max(1, len(samples) * q // 4)]) / MIB)
                                        for q in (1, 2, 3, 4)],
                    "bound": round(bound / MIB)},
        "store_bytes": store_bytes, "margin_bytes": margin, "within_bound": peak <= bound,
        "machine": {"cpus": os.cpu_count(), "load_average": os.getloadavg(),
                    "python": platform.python_version()},
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60)
    parser.add_argument("--clients", type=int, default=16)
    parser.add_argument("--store-mib", type=int, default=128)
    parser.add_argument("--margin-mib", type=int, default=768)
    parser.add_argument("--output", default=str(RESULTS))
    args = parser.parse_args(argv)
    report = asyncio.run(run(args.seconds, args.clients, args.store_mib * MIB,
                             args.margin_mib * MIB))
    print(json.dumps(report, indent=2))
    if args.output != "-":
        Path(args.output).write_text(json.dumps(report, indent=2) + "\n")
    failed = report["errors"] or not report["within_bound"]
    if failed:
        print("FAILED: " + ("errors " if report["errors"] else "") +
              ("" if report["within_bound"] else "resident memory over its bound"))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
