"""``make image-test``: build the container image from docker/Dockerfile and exercise it.

1. A base image: Debian bookworm (python3 3.11, python3-venv, ca-certificates) made with
   debootstrap and ``podman import``, since no registry can be reached; kept between runs.
2. ``podman build --isolation chroot --build-arg BASE=<that image>``: the Dockerfile's own build,
   ``raycore warmup`` and the check that the service then compiles nothing included.
3. The image run as a container would run it, without a container engine: ``podman create`` and
   ``podman mount`` give the image's filesystem with a writable layer on top; the image's
   command runs under chroot as the image's user, with the image's environment and working
   directory, on a free loopback port (the host's network), in its own process group.
4. ``raycore info`` in the container and /readyz: Numba's TBB threading layer.
   Over HTTP: /healthz (and the image's HEALTHCHECK command), a mesh upload, scenes, ray batches
   as JSON and .npy, PNG renders, each kind of request twice, timed: the first request to the
   fresh container must not compile kernels.  Proof: the timings, and Numba's cache directory
   in the container is left exactly as the image had it (a compiled kernel would be written
   there).  Then the image with docker/compose.yaml's environment and two uvicorn workers.
5. The server is stopped (SIGTERM, as a container engine does) and everything is unmounted and
   removed, also when a step fails.

Needs root, podman and debootstrap (the Makefile installs them); standard library only, so it
runs with any Python 3.11.  ``--help`` lists options (an existing base image, a Debian mirror).
"""

import argparse
import ast
import contextlib
import http.client
import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
BASE_IMAGE = "localhost/raycore-base:bookworm"
IMAGE = "localhost/raycore:image-test"
HOST_CA = "/etc/ssl/certs/ca-certificates.crt"
DEBIAN_MIRROR = "http://deb.debian.org/debian"
#: A first request slower than this compiled something (compiling the kernels takes minutes).
FIRST_REQUEST_LIMIT_S = 20.0
NPY = "application/x-npy"


class TestFailed(Exception):
    pass


def log(message):
    print(f"==> {message}", flush=True)


PASSED = []


def passed(what):
    PASSED.append(what)
    print(f"ok {len(PASSED)} - {what}", flush=True)


def run(command, timeout, **kwargs):
    print("$ " + " ".join(map(str, command)), flush=True)
    return subprocess.run(command, timeout=timeout, check=True, **kwargs)


def output(command, timeout=120):
    return subprocess.run(command, timeout=timeout, check=True, capture_output=True,
                          text=True).stdout.strip()


# ----------------------------------------------------------------------------- the image


def image_exists(name):
    return subprocess.run(["podman", "image", "exists", name]).returncode == 0


def unmount_below(path):
    """Unmount whatever is mounted under ``path`` (deepest first)."""
    path = os.path.realpath(path)
    with open("/proc/self/mounts") as mounts:
        targets = [line.split()[1] for line in mounts]
    for target in sorted(targets, key=len, reverse=True):
        if target == path or target.startswith(path + "/"):
            subprocess.run(["umount", "-l", target], check=False)


def build_base(name, mirror):
    """A Debian bookworm image with Python 3.11, from Debian's packages (no registry needed)."""
    log(f"base image {name}: debootstrap bookworm from {mirror}")
    started = time.monotonic()
    work = tempfile.mkdtemp(prefix="raycore-base-", dir="/var/tmp")
    try:
        root = os.path.join(work, "rootfs")
        with open(os.path.join(work, "debootstrap.log"), "w") as debootstrap_log:
            result = subprocess.run(
                ["debootstrap", "--variant=minbase",
                 "--include=python3,python3-venv,ca-certificates", "bookworm", root, mirror],
                stdout=debootstrap_log, stderr=subprocess.STDOUT, timeout=1800)
        if result.returncode != 0:
            with open(os.path.join(work, "debootstrap.log")) as debootstrap_log:
                print("".join(debootstrap_log.readlines()[-30:]), file=sys.stderr)
            raise TestFailed(f"debootstrap failed with {result.returncode}")
        unmount_below(root)
        for leftover in ("var/cache/apt/archives", "var/lib/apt/lists"):
            for entry in Path(root, leftover).glob("*"):
                if entry.is_file():
                    entry.unlink()
        tar = subprocess.Popen(["tar", "-C", root, "--numeric-owner", "-c", "."],
                               stdout=subprocess.PIPE)
        run(["podman", "import", "--change", 'CMD ["/usr/bin/python3"]', "--message",
             "Debian bookworm minbase with python3, python3-venv, ca-certificates", "-", name],
            timeout=600, stdin=tar.stdout, stdout=subprocess.DEVNULL)
        tar.stdout.close()
        if tar.wait() != 0:
            raise TestFailed("tar of the base filesystem failed")
    finally:
        unmount_below(work)
        shutil.rmtree(work, ignore_errors=True)
    log(f"base image built in {time.monotonic() - started:.0f} s")


def build_image(base, tag):
    command = ["podman", "build", "--isolation", "chroot", "--format", "docker",
               "--file", str(REPO / "docker/Dockerfile"),
               "--ignorefile", str(REPO / "docker/Dockerfile.dockerignore"),
               "--build-arg", f"BASE={base}"]
    # pip in the build trusts what this machine trusts (e.g. a TLS-intercepting proxy's CA):
    # the bundle is mounted for the build's RUN steps only and does not enter the image.
    if os.path.exists(HOST_CA):
        command += ["--volume", f"{HOST_CA}:/run/host-ca.crt:ro",
                    "--build-arg", "PIP_CERT=/run/host-ca.crt"]
    for name in ("PIP_INDEX_URL", "PIP_EXTRA_INDEX_URL"):
        if os.environ.get(name):
            command += ["--build-arg", f"{name}={os.environ[name]}"]
    started = time.monotonic()
    # the first stages get tags of their own, so that pruning old builds keeps them cached
    for stage in ("deps", "wheel"):
        run(command + ["--target", stage, "--tag", f"{tag}-{stage}", str(REPO)], timeout=3600)
    run(command + ["--tag", tag, str(REPO)], timeout=3600)
    log(f"image {tag} built in {time.monotonic() - started:.0f} s")


def image_config(tag):
    info = json.loads(output(["podman", "image", "inspect", tag]))[0]
    config = info.get("Config") or {}
    return {"user": config.get("User") or "0:0",
            "env": dict(item.split("=", 1) for item in config.get("Env") or []),
            "command": (config.get("Entrypoint") or []) + (config.get("Cmd") or []),
            "workdir": config.get("WorkingDir") or "/",
            "healthcheck": info.get("Healthcheck") or info.get("HealthCheck")}


# ----------------------------------------------------------------------------- the container


def remove_stale_containers():
    """Containers of an earlier run that was killed: their servers, mounts and layers."""
    names = output(["podman", "ps", "--all", "--filter", "name=^raycore-image-test-",
                    "--format", "{{.Names}}"]).split()
    for name in names:
        root = output(["podman", "mount", name])
        for entry in Path("/proc").iterdir():
            with contextlib.suppress(OSError, ValueError):
                if entry.name.isdigit() and os.readlink(entry / "root") == root:
                    os.kill(int(entry.name), signal.SIGKILL)
        unmount_below(root)
        subprocess.run(["podman", "rm", "--force", name], stdout=subprocess.DEVNULL,
                       check=False)
        log(f"removed {name}, left by an earlier run")


class Container:
    """The image's filesystem, writable, with /proc and the usual /dev nodes: chroot runs in it."""

    def __init__(self, tag, config, stack):
        self.config = config
        self.name = f"raycore-image-test-{os.getpid()}"
        run(["podman", "create", "--name", self.name, "--no-healthcheck", tag], timeout=300,
            stdout=subprocess.DEVNULL)
        stack.callback(subprocess.run, ["podman", "rm", "--force", self.name],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        self.root = output(["podman", "mount", self.name])
        stack.callback(subprocess.run, ["podman", "umount", self.name],
                       stdout=subprocess.DEVNULL, check=False)
        stack.callback(unmount_below, self.root)
        self._mount(["-t", "proc", "proc"], "proc")
        for node in ("null", "zero", "random", "urandom"):
            target = Path(self.root, "dev", node)
            if not target.exists():
                target.touch()
            self._mount(["--bind", f"/dev/{node}"], f"dev/{node}")
        Path(self.root, "dev/shm").mkdir(exist_ok=True)  # multiprocessing (workers) needs it
        self._mount(["-t", "tmpfs", "-o", "mode=1777,size=64m", "tmpfs"], "dev/shm")

    def _mount(self, how, target):
        subprocess.run(["mount", *how, os.path.join(self.root, target)], check=True)

    def command(self, argv, environment):
        """argv run in the container, as the image's user, in its working directory."""
        env = [f"{key}={value}" for key, value in {**self.config["env"], **environment}.items()]
        return ["chroot", f"--userspec={self.config['user']}", self.root,
                "/usr/bin/env", "-i", "-C", self.config["workdir"], *env, *argv]

    def snapshot(self, directory):
        """{path: (size, mtime)} of the files under ``directory`` inside the container."""
        top = Path(self.root) / directory.lstrip("/")
        return {str(path.relative_to(top)): (path.stat().st_size, path.stat().st_mtime_ns)
                for path in top.rglob("*") if path.is_file()}


class Server:
    """The image's command, started in its own process group; stopped with SIGTERM."""

    def __init__(self, container, environment, log_path):
        self.port = free_port()
        self.url = f"127.0.0.1:{self.port}"
        self.log_path = log_path
        self.log_file = open(log_path, "wb")
        command = container.command(container.config["command"], {
            **environment, "UVICORN_HOST": "127.0.0.1", "UVICORN_PORT": str(self.port)})
        print("$ " + " ".join(command[:4]) + " ... " + " ".join(container.config["command"]),
              flush=True)
        self.started = time.monotonic()
        self.process = subprocess.Popen(command, stdout=self.log_file, stderr=subprocess.STDOUT,
                                        start_new_session=True)

    def wait_healthy(self, timeout=180):
        deadline = time.monotonic() + timeout
        while True:
            if self.process.poll() is not None:
                raise TestFailed(f"the server exited with {self.process.returncode}\n" +
                                 self.output())
            try:
                status, _, body = request(self.url, "GET", "/healthz", timeout=5)
                if status == 200:
                    return time.monotonic() - self.started
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise TestFailed(f"/healthz did not answer within {timeout} s\n" + self.output())
            time.sleep(0.1)

    def stop(self, timeout=60):
        """SIGTERM to the process group; SIGKILL if it lingers.  Returns the exit status."""
        if self.process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.process.pid, signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
                raise TestFailed(f"the server did not stop within {timeout} s of SIGTERM") \
                    from None
        with contextlib.suppress(ProcessLookupError):  # workers left behind, if any
            os.killpg(self.process.pid, signal.SIGKILL)
        self.log_file.close()
        return self.process.returncode

    def output(self):
        if not self.log_file.closed:
            self.log_file.flush()
        return Path(self.log_path).read_text(errors="replace")[-6000:]

    def memory(self):
        """Resident memory of each process of the server, in MiB, as text."""
        sizes = []
        for pid, _ in sorted(self.processes()):
            with contextlib.suppress(OSError):
                status = Path(f"/proc/{pid}/status").read_text()
                rss = next((int(line.split()[1]) for line in status.splitlines()
                            if line.startswith("VmRSS:")), 0)
                sizes.append(f"{rss / 1024:.0f}")
        return " + ".join(sizes) + " MiB"

    def processes(self):
        """(pid, uid) of the server's process group."""
        found = []
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                stat = (entry / "stat").read_text()
                status = (entry / "status").read_text()
            except OSError:
                continue
            group = int(stat.rsplit(")", 1)[1].split()[2])
            if group == self.process.pid:
                uid = next(line.split()[1] for line in status.splitlines()
                           if line.startswith("Uid:"))
                found.append((int(entry.name), uid))
        return found


@contextlib.contextmanager
def serving(server):
    """Run the block against ``server``; print its output if the block fails, then stop it and
    check that it shut down cleanly."""
    try:
        yield server
    except BaseException:
        print(server.output(), file=sys.stderr)
        raise
    finally:
        code = server.stop()
    check_clean_stop(server, code)


def check_clean_stop(server, code):
    """uvicorn shuts down on SIGTERM, then raises the signal again: the exit is by SIGTERM."""
    if code not in (0, -signal.SIGTERM) or "Application shutdown complete" not in server.output():
        raise TestFailed(f"the server did not shut down cleanly on SIGTERM (exit {code})\n"
                         + server.output())
    passed("the server shuts down cleanly on SIGTERM")


def free_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


# ----------------------------------------------------------------------------- HTTP


def request(url, method, path, body=None, content_type=None, accept=None, timeout=120,
            connection=None):
    """(status, content type, body); ``connection`` keeps one keep-alive connection."""
    headers = {}
    if content_type:
        headers["Content-Type"] = content_type
    if accept:
        headers["Accept"] = accept
    own = connection is None
    if own:
        connection = http.client.HTTPConnection(url, timeout=timeout)
    try:
        connection.request(method, path, body=body, headers=headers)
        response = connection.getresponse()
        return response.status, response.getheader("Content-Type", ""), response.read()
    finally:
        if own:
            connection.close()


class Client:
    """Requests to the server, each timed; fails on an unexpected status."""

    def __init__(self, url):
        self.url = url
        self.timings = {}  # kind -> [seconds of the 1st, 2nd, ... request]

    def __call__(self, kind, method, path, body=None, content_type=None, accept=None,
                 expect=(200, 201)):
        if isinstance(body, (dict, list)):
            body, content_type = json.dumps(body).encode(), "application/json"
        started = time.perf_counter()
        status, media, data = request(self.url, method, path, body, content_type, accept)
        self.timings.setdefault(kind, []).append(time.perf_counter() - started)
        if status not in expect:
            raise TestFailed(f"{kind}: {method} {path} answered {status}: {data[:800]!r}")
        return json.loads(data) if media.startswith("application/json") else data


# ----------------------------------------------------------------------------- data


def icosphere(subdivisions, center=(0.0, 0.0, 0.0), radius=1.0):
    """A closed icosphere: vertices as (x, y, z) tuples, faces as 0-based index triples."""
    t = (1 + 5**0.5) / 2
    vertices = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
                (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]

    def unit(v):
        length = sum(c * c for c in v) ** 0.5
        return tuple(c / length for c in v)

    vertices = [unit(v) for v in vertices]
    midpoints = {}  # vertex pair -> index of the vertex between them

    def middle(a, b):
        key = (min(a, b), max(a, b))
        if key not in midpoints:
            vertices.append(unit([p + q for p, q in zip(vertices[a], vertices[b], strict=True)]))
            midpoints[key] = len(vertices) - 1
        return midpoints[key]

    for _ in range(subdivisions):
        refined = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            refined += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = refined
    vertices = [tuple(o + radius * c for o, c in zip(center, v, strict=True)) for v in vertices]
    return vertices, faces


def obj_file(vertices, faces):
    return ("".join(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in vertices) +
            "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)).encode()


def npy_rays(rows, dtype="<f4"):
    """.npy (version 1.0) of an (N, 6) float array."""
    header = repr({"descr": dtype, "fortran_order": False, "shape": (len(rows), 6)})
    header = header.encode() + b" " * (63 - (len(header) + 10) % 64) + b"\n"
    letter = {"<f4": "f", "<f8": "d"}[dtype]
    data = struct.pack(f"<{6 * len(rows)}{letter}", *(value for row in rows for value in row))
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + data


def read_npy_table(data):
    """Columns of a .npy structured array of scalar and fixed-shape numeric fields."""
    if not data.startswith(b"\x93NUMPY"):
        raise TestFailed("the answer is not an .npy file")
    major = data[6]
    length, start = ((struct.unpack("<H", data[8:10])[0], 10) if major == 1 else
                     (struct.unpack("<I", data[8:12])[0], 12))
    header = ast.literal_eval(data[start:start + length].decode("latin1"))
    (count,) = header["shape"]
    fields, fmt = [], "<"
    for field in header["descr"]:
        name, code = field[0], field[1]
        shape = field[2] if len(field) > 2 else ()
        items = 1
        for size in shape:
            items *= size
        letter = {"<f4": "f", "<f8": "d", "<i4": "i", "<i8": "q", "|b1": "?"}[code]
        fields.append((name, items))
        fmt += letter * items
    row = struct.Struct(fmt)
    body = data[start + length:]
    if len(body) != row.size * count:
        raise TestFailed(f".npy body has {len(body)} bytes, expected {row.size * count}")
    columns = {name: [] for name, _ in fields}
    for values in row.iter_unpack(body):
        index = 0
        for name, items in fields:
            part = values[index:index + items]
            columns[name].append(part[0] if items == 1 else part)
            index += items
    return columns


def decode_png(data):
    """(width, height) of an 8-bit RGB PNG, after decoding and unfiltering every row."""
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        raise TestFailed("the render is not a PNG")
    position, chunks = 8, {}
    while position < len(data):
        (length,) = struct.unpack(">I", data[position:position + 4])
        kind = data[position + 4:position + 8]
        payload = data[position + 8:position + 8 + length]
        (crc,) = struct.unpack(">I", data[position + 8 + length:position + 12 + length])
        if zlib.crc32(kind + payload) != crc:
            raise TestFailed(f"PNG chunk {kind!r} has a bad CRC")
        chunks.setdefault(kind, []).append(payload)
        position += 12 + length
    width, height, depth, color = struct.unpack(">IIBB", chunks[b"IHDR"][0][:10])
    if (depth, color) != (8, 2) or b"IEND" not in chunks:
        raise TestFailed(f"PNG is not 8-bit RGB (depth {depth}, colour type {color})")
    raw = zlib.decompress(b"".join(chunks[b"IDAT"]))
    stride = 1 + 3 * width
    if len(raw) != stride * height or any(raw[row * stride] > 4 for row in range(height)):
        raise TestFailed(f"PNG data does not decode to {width}x{height}")
    return width, height


def ray_batch(xs, y):
    """Rays from z = -10 along +z, one per x."""
    return [[x, y, -10.0] for x in xs], [[0.0, 0.0, 1.0] for _ in xs]


# ----------------------------------------------------------------------------- the checks


def exercise(client):
    """The API end to end, each kind of request at least twice; raises TestFailed."""
    def check(condition, message):
        if not condition:
            raise TestFailed(message)

    status = client("GET /healthz", "GET", "/healthz")
    check(status == {"status": "ok"}, f"/healthz answered {status}")
    meshes = []
    for vertices, faces in (icosphere(3), icosphere(4, radius=0.8)):
        info = client("POST /v1/meshes (OBJ file)", "POST", "/v1/meshes",
                      obj_file(vertices, faces), "model/obj")
        check(info["faces"] == len(faces) and info["closed"], f"mesh info {info}")
        meshes.append(info["id"])
    passed("OBJ meshes upload")

    def shift(x):
        return [[1, 0, 0, x], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]

    def spec(dtype, mesh, instance_x):
        # along z at y = 0: a cone or sphere at x = -4, the mesh at 0, an instance at 4
        if dtype == "float32":
            left = {"type": "sphere", "center": [-4, 0, 0], "radius": 1}
        else:
            left = {"type": "cone", "base_center": [-4, -1, 0], "apex": [-4, 1, 0], "radius": 1}
        return {"dtype": dtype, "objects": [
            {"type": "mesh", "mesh": mesh, "material": {"color": [0.9, 0.6, 0.2]}},
            {"type": "instance", "mesh": mesh, "transform": shift(instance_x)},
            left,
            {"type": "plane", "point": [0, -1.5, 0], "normal": [0, 1, 0]},
            {"type": "box", "lo": [-1, -1.5, 3], "hi": [1, 1, 4]}]}

    scenes = {}
    for dtype, mesh in (("float32", meshes[0]), ("float64", meshes[1])):
        for instance_x in (4.0, 4.001):  # the second: another scene, built anew
            info = client(f"POST /v1/scenes ({dtype})", "POST", "/v1/scenes",
                          spec(dtype, mesh, instance_x))
            check(len(info["geom_ids"]) == 5, f"scene info {info}")
        scenes[dtype] = info
    passed("scenes build, float32 and float64, from uploaded meshes, instances and shapes")

    xs = [-4.0, 0.0, 4.0, 10.0, -10.0] * 40  # 200 rays: three objects hit, two misses
    for dtype, scene in scenes.items():
        path = f"/v1/scenes/{scene['id']}/intersect"
        ids = scene["geom_ids"]
        expected = {-4.0: ids[2], 0.0: ids[0], 4.0: ids[1], 10.0: -1, -10.0: -1}
        for y in (0.0, 0.05):
            origins, directions = ray_batch(xs, y)
            answer = client(f"POST intersect JSON, closest+normal ({dtype})", "POST", path,
                            {"origins": origins, "directions": directions,
                             "fields": ["normal"]})
            for x, t, geom, normal in zip(xs, answer["t"], answer["geom_id"], answer["normal"],
                                          strict=True):
                check(geom == expected[x], f"{dtype}: ray at x={x} hit geometry {geom}, "
                                           f"expected {expected[x]}")
                if geom == -1:
                    check(t is None and normal is None, f"a miss has t={t}, normal={normal}")
                else:
                    check(8.9 < t < 9.6 and normal[2] < -0.5, f"ray at x={x}: t={t}, n={normal}")
            table = read_npy_table(client(f"POST intersect .npy, closest+normal ({dtype})",
                                          "POST", path + "?fields=normal",
                                          npy_rays([o + d for o, d in
                                                    zip(origins, directions, strict=True)]),
                                          NPY, accept=NPY))
            check(table["geom_id"] == answer["geom_id"], "the .npy answer's ids differ from JSON")
            for t_npy, t_json in zip(table["t"], answer["t"], strict=True):
                check((t_json is None and t_npy == float("inf")) or
                      (t_json is not None and abs(t_npy - t_json) <= 1e-6 * t_json),
                      f".npy t {t_npy} differs from JSON t {t_json}")
            every = client(f"POST intersect JSON, all hits ({dtype})", "POST", path,
                           {"origins": origins[:5], "directions": directions[:5],
                            "query": "all"})
            # through the front and back of each object, then the box behind the mesh
            check(every["counts"] == [2, 4, 2, 0, 0], f"all hits: counts {every['counts']}")
    passed("ray batches, JSON and .npy, closest and all hits: the expected hits, equal answers")

    cameras = [{"type": "perspective", "position": [0, 3, -12], "look_at": [0, 0, 0],
                "fov": 50, "width": 160, "height": 120},
               {"type": "orthographic", "position": [0, 0, -10], "look_at": [0, 0, 0],
                "view_height": 6, "width": 200, "height": 90}]
    for dtype, scene in scenes.items():
        for camera, shading in zip(cameras, ("lambert", "normal"), strict=True):
            png = client(f"POST render, PNG ({dtype})", "POST",
                         f"/v1/scenes/{scene['id']}/render", {"camera": camera, "shading": shading})
            size = decode_png(png)
            check(size == (camera["width"], camera["height"]),
                  f"the PNG is {size}, asked for {camera['width']}x{camera['height']}")
    passed("renders are PNGs that decode to the requested size")

    # clients at once: the worker's compute slots run their kernels side by side
    path = f"/v1/scenes/{scenes['float32']['id']}/render"
    body = json.dumps({"camera": cameras[0], "shading": "lambert"}).encode()
    alone = request(client.url, "POST", path, body, "application/json")
    answers = []

    def send():
        answers.extend(request(client.url, "POST", path, body, "application/json")
                       for _ in range(4))

    senders = [threading.Thread(target=send) for _ in range(8)]
    for sender in senders:
        sender.start()
    for sender in senders:
        sender.join()
    check(alone[0] == 200 and len(answers) == 32 and all(a == alone for a in answers),
          "renders sent at once differ from the one sent alone (or failed)")
    passed("8 clients rendering at once get the image that one alone gets")


def print_timings(timings, title):
    print(f"\n{title:<46} {'first':>9} {'second':>9}")
    for kind, seconds in timings.items():
        second = f"{seconds[1] * 1000:6.0f} ms" if len(seconds) > 1 else ""
        print(f"{kind:<46} {seconds[0] * 1000:6.0f} ms {second:>9}")
    print(flush=True)


def numba_cache_dir(config):
    directory = config["env"].get("NUMBA_CACHE_DIR")
    if not directory:
        raise TestFailed("the image sets no NUMBA_CACHE_DIR: the test cannot see its kernels")
    return directory


def check_threading_layer(container, server):
    """The image runs Numba's TBB layer, thread-safe and fork-safe: as `raycore info` says in
    the container, and as the service's /readyz says."""
    run = subprocess.run(container.command(["raycore", "info", "--json"], {}), timeout=120,
                         capture_output=True, text=True)
    if run.returncode != 0:
        raise TestFailed(f"raycore info failed in the container:\n{run.stderr[-2000:]}")
    info = json.loads(run.stdout)
    if (info["threading_layer"], info["thread_safe"], info["fork_safe"]) != ("tbb", True, True):
        raise TestFailed(f"the image runs Numba's {info['threading_layer']} layer, not tbb")
    status, _, body = request(server.url, "GET", "/readyz")
    ready = json.loads(body)
    if status != 200 or ready.get("threading_layer") != "tbb" or not ready.get("threads"):
        raise TestFailed(f"/readyz answered {status}: {ready}")
    passed(f"the image runs on Numba's TBB layer with {ready['threads']} threads (raycore info, "
           "/readyz)")


def test_single_worker(container, work):
    config = container.config
    cache_dir = numba_cache_dir(config)
    before = container.snapshot(cache_dir)
    if not any(name.endswith(".nbi") for name in before):
        raise TestFailed(f"the image holds no Numba cache in {cache_dir}")
    log(f"start the image's command ({len(before)} files in its Numba cache), demo scene off")
    server = Server(container, {"RAYCORE_DEMO": "false"}, work / "server.log")
    with serving(server):
        startup = server.wait_healthy()
        passed(f"/healthz answers, {startup:.1f} s after the start")
        users = {uid for _, uid in server.processes()}
        expected_uid = config["user"].split(":")[0]
        if users != {expected_uid}:
            raise TestFailed(f"the server runs as uid {users}, the image says {expected_uid}")
        passed(f"the server runs as uid {expected_uid}")
        test = config["healthcheck"]["Test"]
        argv = ["/bin/sh", "-c", test[1]] if test[0] == "CMD-SHELL" else test[1:]
        check = container.command(argv, {
            "UVICORN_HOST": "127.0.0.1", "UVICORN_PORT": str(server.port)})
        if subprocess.run(check, timeout=60).returncode != 0:
            raise TestFailed("the image's HEALTHCHECK failed on a healthy server")
        passed("the image's HEALTHCHECK passes")
        check_threading_layer(container, server)
        client = Client(server.url)
        exercise(client)
        log(f"resident memory after the requests: {server.memory()}")
    if subprocess.run(check, timeout=60, stderr=subprocess.DEVNULL).returncode == 0:
        raise TestFailed("the image's HEALTHCHECK passed with the server stopped")
    passed("the image's HEALTHCHECK fails once the server is stopped")

    print_timings(client.timings, f"request (fresh container, uid {expected_uid})")
    after = container.snapshot(cache_dir)
    changed = _written(before, after)
    if changed:
        raise TestFailed("the service compiled kernels at run time; Numba cache files written: "
                         + changed)
    passed(f"Numba's cache is untouched: every kernel came from the image ({len(after)} files)")
    slow = {kind: s[0] for kind, s in client.timings.items() if s[0] > FIRST_REQUEST_LIMIT_S}
    if slow:
        raise TestFailed(f"first requests slower than {FIRST_REQUEST_LIMIT_S} s: {slow}")
    passed(f"every first request answered within {FIRST_REQUEST_LIMIT_S:.0f} s")


#: Run with the image's Python: docker/compose.yaml as JSON, and the service's setting names.
_READ_COMPOSE = ("import dataclasses, json, sys, yaml; from service.config import Settings; "
                 "print(json.dumps({'compose': yaml.safe_load(sys.stdin), "
                 "'settings': [field.name for field in dataclasses.fields(Settings)]}))")


def _written(before, after):
    """The names of the Numba cache files that differ between two snapshots (at most 20,
    joined), or "" when none does."""
    return ", ".join(sorted(name for name in set(before) | set(after)
                            if before.get(name) != after.get(name))[:20])


def compose_environment(container):
    """docker/compose.yaml's service environment, checked against the image and the service,
    with ``${NAME:-default}`` resolved to the defaults (unset entries left out)."""
    read = subprocess.run(container.command(["python", "-c", _READ_COMPOSE], {}), check=True,
                          input=(REPO / "docker/compose.yaml").read_text(), text=True,
                          capture_output=True, timeout=120)
    parsed = json.loads(read.stdout)
    services = parsed["compose"]["services"]
    if list(services) != ["raycore"]:
        raise TestFailed(f"compose.yaml: expected the one service raycore, got {list(services)}")
    service = services["raycore"]

    def resolve(value):
        return re.sub(r"\$\{\w+(?::?-([^}]*))?\}", lambda match: match.group(1) or "",
                      str(value))

    build = service["build"]
    if (REPO / "docker" / build["context"]).resolve() != REPO or \
            build["dockerfile"] != "docker/Dockerfile":
        raise TestFailed(f"compose.yaml builds {build}, not docker/Dockerfile from the repo")
    image_port = container.config["env"].get("UVICORN_PORT")
    ports = [resolve(port).rsplit(":", 1)[-1] for port in service["ports"]]
    if ports != [image_port]:
        raise TestFailed(f"compose.yaml publishes container ports {ports}, the image listens "
                         f"on {image_port}")
    environment = {name: resolve(value) for name, value in service["environment"].items()
                   if value is not None}
    unknown = [name for name in service["environment"] if name.startswith("RAYCORE_")
               and name[len("RAYCORE_"):].lower() not in parsed["settings"]]
    if unknown:
        raise TestFailed(f"compose.yaml sets {unknown}, which the service does not read")
    mounted = [str(volume).split(":")[1] for volume in service.get("volumes", [])]
    if environment.get("RAYCORE_DATA_DIR") not in mounted:
        raise TestFailed(f"compose.yaml mounts {mounted}, not a volume at RAYCORE_DATA_DIR "
                         f"({environment.get('RAYCORE_DATA_DIR')})")
    passed("compose.yaml builds docker/Dockerfile, publishes the image's port, sets only "
           "settings the service reads, mounts a volume at RAYCORE_DATA_DIR")
    return environment


def test_compose_workers(container, work):
    environment = {**compose_environment(container), "UVICORN_WORKERS": "2"}
    log("docker/compose.yaml's environment, with UVICORN_WORKERS=2: " +
        " ".join(f"{name}={value}" for name, value in environment.items()))
    cache_dir = numba_cache_dir(container.config)
    before = container.snapshot(cache_dir)
    # the volume: a directory of the host's, as a container engine mounts one
    volume = work / "volume"
    volume.mkdir()
    os.chown(volume, 10001, 10001)
    container._mount(["--bind", str(volume)], environment["RAYCORE_DATA_DIR"].lstrip("/"))
    server = Server(container, environment, work / "server-compose.log")
    with serving(server):
        startup = server.wait_healthy()
        deadline = time.monotonic() + 180
        # one worker's readiness: a request that the other takes while loading waits for its demo
        while request(server.url, "GET", "/readyz")[0] != 200:
            if time.monotonic() > deadline:
                raise TestFailed("/readyz did not answer 200 within 180 s")
            time.sleep(0.2)
        # the supervisor and two workers (and multiprocessing's helper)
        while len(server.processes()) < 3 and time.monotonic() < deadline:
            time.sleep(0.2)
        processes = server.processes()
        if len(processes) < 3:
            raise TestFailed(f"expected a supervisor and two workers, found {processes}")
        # one keep-alive connection stays with one worker, whose store holds the scene
        connection = http.client.HTTPConnection(server.url, timeout=120)
        camera = {"type": "perspective", "position": [7, 5, -9], "look_at": [0, 1, 0],
                  "width": 64, "height": 48}
        status, _, png = request(server.url, "POST", "/v1/scenes/demo/render",
                                 json.dumps({"camera": camera}).encode(), "application/json",
                                 connection=connection)
        if status != 200 or decode_png(png) != (64, 48):
            raise TestFailed(f"the demo render answered {status}: {png[:300]!r}")
        # a mesh beside the sphere: the restart below reads trees back from the volume
        spec = {"objects": [{"type": "sphere", "center": [0, 0, 0], "radius": 1},
                            {"type": "mesh", "vertices": [[0, 0, 9], [1, 0, 9], [0, 1, 9]],
                             "faces": [[0, 1, 2]]}]}
        status, _, body = request(server.url, "POST", "/v1/scenes", json.dumps(spec).encode(),
                                  "application/json", connection=connection)
        if status not in (200, 201):
            raise TestFailed(f"POST /v1/scenes answered {status}: {body[:300]!r}")
        scene = json.loads(body)["id"]
        rays = {"origins": [[0, 0, -5]], "directions": [[0, 0, 1]]}
        status, _, body = request(server.url, "POST", f"/v1/scenes/{scene}/intersect",
                                  json.dumps(rays).encode(), "application/json",
                                  connection=connection)
        if status != 200 or json.loads(body)["t"] != [4.0]:
            raise TestFailed(f"intersect answered {status}: {body[:300]!r}")
        connection.close()
        passed(f"two workers: {len(processes)} processes ({server.memory()}), healthy after "
               f"{startup:.1f} s, ready, render the demo, answer queries")
    stored = sorted(path.name for path in volume.rglob("*.rcf"))
    if stored != [f"{scene}.rcf"]:
        raise TestFailed(f"the volume holds {stored}, not the scene {scene}")
    restarted_finds_scene(container, environment, work, scene)
    changed = _written(before, container.snapshot(cache_dir))
    if changed:
        raise TestFailed("with compose.yaml's environment the service compiled kernels; Numba "
                         "cache files written: " + changed)
    passed("with compose.yaml's environment too, Numba's cache is untouched")


def restarted_finds_scene(container, environment, work, scene):
    """The container started again on the same volume answers for ``scene`` on fresh
    connections (each may reach either worker), without it being sent again."""
    server = Server(container, environment, work / "server-restarted.log")
    with serving(server):
        server.wait_healthy()
        rays = {"origins": [[0, 0, -5]], "directions": [[0, 0, 1]]}
        for _ in range(6):
            status, _, body = request(server.url, "POST", f"/v1/scenes/{scene}/intersect",
                                      json.dumps(rays).encode(), "application/json")
            if status != 200 or json.loads(body)["t"] != [4.0]:
                raise TestFailed(f"after a restart, intersect answered {status}: {body[:300]!r}")
        passed("restarted on the same volume, the service answers for its scene (6 of 6 fresh "
               "connections)")


def show_cold_start(container, work):
    """For comparison: the first requests with an empty Numba cache (they compile)."""
    log("for comparison: the same requests with an empty Numba cache (compiling)")
    server = Server(container, {"RAYCORE_DEMO": "false", "NUMBA_CACHE_DIR": "/tmp/numba-cold"},
                    work / "server-cold.log")
    try:
        server.wait_healthy()
        client = Client(server.url)
        exercise(client)
    finally:
        check_clean_stop(server, server.stop())
    print_timings(client.timings, "request (empty Numba cache)")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", help="base image to build on (default: make and reuse "
                                       f"{BASE_IMAGE} with debootstrap)")
    parser.add_argument("--rebuild-base", action="store_true",
                        help=f"make {BASE_IMAGE} again even if it exists")
    parser.add_argument("--mirror", default=os.environ.get("DEBIAN_MIRROR", DEBIAN_MIRROR),
                        help="Debian mirror for debootstrap (default: $DEBIAN_MIRROR or "
                             f"{DEBIAN_MIRROR})")
    parser.add_argument("--tag", default=IMAGE, help=f"the image to build (default {IMAGE})")
    parser.add_argument("--no-build", action="store_true", help="test the image --tag as it is")
    parser.add_argument("--cold", action="store_true",
                        help="also time the requests with an empty Numba cache, for comparison")
    args = parser.parse_args(argv)
    if os.geteuid() != 0:
        print("image-test needs root (chroot, mount, podman's root storage)", file=sys.stderr)
        return 2
    for tool in ("podman", "debootstrap", "chroot", "mount"):
        if shutil.which(tool) is None:
            print(f"image-test needs {tool} (apt-get install podman debootstrap)", file=sys.stderr)
            return 2
    started = time.monotonic()
    # a CI timeout's SIGTERM unwinds like an error: the server is stopped, mounts are undone
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    try:
        remove_stale_containers()
        if not args.no_build:
            base = args.base or BASE_IMAGE
            if args.base is None and (args.rebuild_base or not image_exists(BASE_IMAGE)):
                build_base(BASE_IMAGE, args.mirror)
            elif args.base is None:
                log(f"base image {BASE_IMAGE} exists: reused (--rebuild-base makes it again)")
            build_image(base, args.tag)
            passed("the image builds; its Numba cache is warm (checked in a fresh process)")
        config = image_config(args.tag)
        if config["user"].split(":")[0] in ("", "0", "root"):
            raise TestFailed(f"the image runs as {config['user']!r}, not as a non-root user")
        if not config["healthcheck"] or not config["healthcheck"].get("Test"):
            raise TestFailed("the image has no HEALTHCHECK")
        passed(f"the image runs as user {config['user']} and has a HEALTHCHECK")
        with contextlib.ExitStack() as stack, tempfile.TemporaryDirectory(
                prefix="raycore-image-test-", dir="/var/tmp") as work:
            container = Container(args.tag, config, stack)
            test_single_worker(container, Path(work))
            test_compose_workers(container, Path(work))
            if args.cold:
                show_cold_start(container, Path(work))
        # the image is kept (its layers are the next build's cache); older builds' are not
        subprocess.run(["podman", "image", "prune", "--force"], stdout=subprocess.DEVNULL,
                       check=False)
    except (TestFailed, subprocess.CalledProcessError, subprocess.TimeoutExpired) as error:
        print(f"image-test FAILED: {error}", file=sys.stderr)
        print(f"image-test: {len(PASSED)} passed, 1 failed", flush=True)
        return 1
    log(f"image-test passed in {time.monotonic() - started:.0f} s")
    print(f"image-test: {len(PASSED)} passed, 0 failed", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
