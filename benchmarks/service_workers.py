"""One uvicorn worker with two compute slots against two workers: throughput and memory.

Each configuration serves ``uvicorn --factory service.app:create_app`` on 127.0.0.1 and is
driven for ``--seconds`` by ``--clients`` concurrent clients with benchmarks/service_load.py's
mix (JSON and .npy intersects, lambert renders, new 20k-triangle scenes that fill the store).
Every client makes its own scene on its own keep-alive connection, so that with two workers
each worker holds the scenes of the clients it serves (and a 404 makes the client send its
scene again, as the README tells clients to).  Configurations run in interleaved rounds, so
that a machine shared with other work disturbs them alike.  Reports requests per second, p50
and p99 latency, and the resident memory of all the server's processes (peak of their sum).

Two mixes: service_load's whole mix, and its queries and renders only (no scene builds, whose
JSON parsing holds the GIL and so gains from a second process, not from a second slot).

Run with ``python -m benchmarks.service_workers [--seconds 30] [--rounds 2]``; writes
benchmarks/results/service_workers.json.
"""

import argparse
import asyncio
import json
import os
import platform
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import psutil

from benchmarks.service_load import requests, setup
from service.process import free_port

MIB = 2**20
RESULTS = Path(__file__).resolve().parent / "results" / "service_workers.json"
#: name -> (uvicorn workers, RAYCORE_COMPUTE_SLOTS, NUMBA_NUM_THREADS)
CONFIGURATIONS = {
    "1 worker, 1 slot, 2 threads": (1, 1, 2),
    "1 worker, 2 slots, 2 threads": (1, 2, 2),
    "2 workers, 1 slot, 2 threads each": (2, 1, 2),
    "2 workers, 1 slot, 1 thread each": (2, 1, 1),
}
#: The requests of the "queries" mix: those that mostly run kernels (no scene builds, whose
#: JSON parsing holds the GIL).
QUERIES = ("intersect_json", "intersect_npy", "render")


def start(workers, slots, threads, store_bytes):
    port = free_port()
    environment = {**os.environ, "RAYCORE_DEMO": "false", "RAYCORE_COMPUTE_SLOTS": str(slots),
                   "NUMBA_NUM_THREADS": str(threads), "RAYCORE_STORE_BYTES": str(store_bytes)}
    process = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "--factory", "service.app:create_app", "--host",
         "127.0.0.1", "--port", str(port), "--workers", str(workers), "--log-level", "warning"],
        env=environment, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 600
    while True:
        try:
            if httpx.get(f"{url}/readyz", timeout=5).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"the server did not start ({process.poll()})")
        time.sleep(0.2)
    # every worker answers: the supervisor plus ``workers`` children (and multiprocessing's
    # helper) are up
    while workers > 1 and len(psutil.Process(process.pid).children(recursive=True)) < workers:
        time.sleep(0.2)
    return process, url


def stop(process):
    os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(60)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def resident(process):
    total = 0
    for member in [process, *process.children(recursive=True)]:
        try:
            total += member.memory_info().rss
        except psutil.NoSuchProcess:
            pass
    return total


class Start:
    """The clock starts when every client has warmed its worker (its scene built, each kind of
    request answered once)."""

    def __init__(self, clients, seconds):
        self.waiting, self.seconds = clients, seconds
        self.go = asyncio.Event()
        self.deadline = None

    async def ready(self):
        self.waiting -= 1
        if self.waiting == 0:
            self.deadline = time.monotonic() + self.seconds
            self.go.set()
        await self.go.wait()


def request_kinds(scene, seed, mix):
    kinds = requests(scene, np.random.default_rng(seed))
    return kinds if mix == "all" else {kind: kinds[kind] for kind in QUERIES}


async def client_loop(url, start, seed, mix, latencies, errors):
    rng = random.Random(seed)
    async with httpx.AsyncClient(base_url=url, timeout=120,
                                 limits=httpx.Limits(max_connections=1)) as client:
        kinds = request_kinds(await setup(client), seed, mix)
        for request in kinds.values():
            (await request(client)).raise_for_status()
        await start.ready()
        while time.monotonic() < start.deadline:
            kind = rng.choice(list(kinds))
            began = time.perf_counter()
            response = await kinds[kind](client)
            if response.status_code == 404:  # the scene was evicted: send it again
                kinds = request_kinds(await setup(client), seed, mix)
                continue
            if response.status_code not in (200, 201):
                errors.append(f"{kind}: {response.status_code} {response.text[:200]}")
            latencies.append(time.perf_counter() - began)


async def sample(process, start, samples):
    await start.go.wait()
    while time.monotonic() < start.deadline:
        samples.append(resident(process))
        await asyncio.sleep(0.2)


async def measure(url, process, seconds, clients, mix):
    start = Start(clients, seconds)
    latencies, errors, samples = [], [], []
    await asyncio.gather(
        sample(psutil.Process(process.pid), start, samples),
        *[client_loop(url, start, seed, mix, latencies, errors) for seed in range(clients)])
    values = np.asarray(latencies)
    return {"requests_per_s": round(len(values) / seconds, 1),
            "p50_ms": round(1000 * float(np.percentile(values, 50)), 1),
            "p99_ms": round(1000 * float(np.percentile(values, 99)), 1),
            "peak_rss_mib": round(max(samples) / MIB), "errors": len(errors),
            "first_errors": errors[:3]}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--clients", type=int, default=16)
    parser.add_argument("--store-mib", type=int, default=256)
    parser.add_argument("--mix", action="append", choices=["all", "queries"],
                        help="service_load's whole mix, or its queries and renders only "
                             "(default: both)")
    parser.add_argument("--output", default=str(RESULTS))
    args = parser.parse_args(argv)
    mixes = args.mix or ["all", "queries"]
    runs = {f"{mix}: {name}": [] for mix in mixes for name in CONFIGURATIONS}
    for round_ in range(args.rounds):
        for mix in mixes:
            for name, (workers, slots, threads) in CONFIGURATIONS.items():
                process, url = start(workers, slots, threads, args.store_mib * MIB)
                try:
                    result = asyncio.run(measure(url, process, args.seconds, args.clients, mix))
                finally:
                    stop(process)
                runs[f"{mix}: {name}"].append(result)
                print(f"round {round_ + 1} {mix}: {name}: {json.dumps(result)}", flush=True)
    report = {"seconds": args.seconds, "clients": args.clients, "store_mib": args.store_mib,
              "runs": runs,
              "machine": {"cpus": os.cpu_count(), "load_average": os.getloadavg(),
                          "python": platform.python_version()}}
    if args.output != "-":
        Path(args.output).write_text(json.dumps(report, indent=2) + "\n")
    return 1 if any(run["errors"] for results in runs.values() for run in results) else 0


if __name__ == "__main__":
    raise SystemExit(main())
