"""Check that ``raycore warmup`` left nothing for the service to compile.

``raycore warmup`` compiles every kernel that raycore's public calls reach, through the library
alone.  This script drives the service's own app (``service.app.create_app``, settings from the
environment, the demo scene included) through Starlette's TestClient with a matrix of requests
that reaches every route with every kind of input: scene builds (every shape, uploaded and
inline meshes, instances), closest hits with each surface field, any, all and count queries
with each triangle test, JSON and .npy ray batches (float32 and float64, (N, 6) and (N, 8),
Fortran-ordered, scalar and per-ray tmin/tmax, JSON and .npy answers), and renders with every
shading and camera, one and four samples a pixel, smooth and flat.  The routes hand the
kernels the array types, layouts and dtypes that requests give them, which is what Numba
specialises on.

Two checks:

* by default, in a fresh interpreter after ``raycore warmup`` (the image's build): nothing may
  compile, every kernel must come from Numba's cache;
* ``--after-warmup`` runs the warm-up in this process first, then fails if the requests reach
  any kernel signature that it did not, whether compiled or loaded from the cache: the same
  coverage on any cache, cold or warm (``make test`` runs it, tests/test_warmup.py).

Needs the service and httpx (for the TestClient); the image installs httpx for this step only.
"""

import argparse
import io
import json
import os
import sys
import time

import numpy as np

DTYPES = ("float32", "float64")
TRIANGLE_TESTS = ("watertight", "moller", "geometric")
NPY = "application/x-npy"


# ----------------------------------------------------------------------------- inputs


def icosphere(subdivisions=1):
    """A closed unit icosphere: (V, 3) float64 vertices, (F, 3) int64 faces."""
    t = (1 + 5**0.5) / 2
    vertices = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
             [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
             [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    vertices = [np.array(v, float) / np.linalg.norm(v) for v in vertices]
    midpoints = {}  # vertex pair -> index of the vertex between them

    def middle(a, b):
        key = (min(a, b), max(a, b))
        if key not in midpoints:
            point = vertices[a] + vertices[b]
            vertices.append(point / np.linalg.norm(point))
            midpoints[key] = len(vertices) - 1
        return midpoints[key]

    for _ in range(subdivisions):
        refined = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            refined += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = refined
    return np.array(vertices), np.array(faces, dtype=np.int64)


def obj_bytes(vertices, faces):
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return ("\n".join(lines) + "\n").encode()


def stl_bytes(vertices, faces):
    """Binary STL."""
    triangles = vertices[faces].astype("<f4")
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    record = np.zeros(len(faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    record["n"], record["v"] = normals, triangles
    return b"\0" * 80 + np.uint32(len(faces)).tobytes() + record.tobytes()


def npy_bytes(array):
    stream = io.BytesIO()
    np.save(stream, array, allow_pickle=False)
    return stream.getvalue()


def rays(count, seed):
    """Rays aimed at the middle of the scenes from around them, some missing: (N, 3) twice."""
    rng = np.random.default_rng(seed)
    origins = rng.normal(size=(count, 3))
    origins = 8 * origins / np.linalg.norm(origins, axis=1, keepdims=True) + [0, 2, 0]
    targets = rng.uniform(-3, 3, size=(count, 3)) + [0, 1, 0]
    return origins, targets - origins


def scenes(mesh_id):
    """Scene specs, per dtype: every kind of object together, meshes only, shapes only."""
    inline_v, inline_f = icosphere(0)
    shift = [[1, 0, 0, 2.5], [0, 1, 0, 0.5], [0, 0, 1, -1], [0, 0, 0, 1]]
    turn = [[0, -1, 0, 0], [1, 0, 0, 1], [0, 0, 1, 2], [0, 0, 0, 1]]
    red = {"color": [0.9, 0.2, 0.2]}
    shapes = [
        {"type": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]},
        {"type": "sphere", "center": [0, 1.2, 0], "radius": 0.8, "material": red},
        {"type": "disk", "center": [0, 0.01, 2.6], "normal": [0, 1, 0], "radius": 0.9},
        {"type": "box", "lo": [1.8, 0, -0.6], "hi": [3.0, 1.2, 0.6]},
        {"type": "box", "lo": [-1, 0, -1], "hi": [1, 1, 1], "transform": turn},
        {"type": "cylinder", "p0": [-1.5, 0, -2.2], "p1": [-1.5, 1.6, -2.2], "radius": 0.45},
        {"type": "cone", "base_center": [1.2, 0, -2.4], "apex": [1.2, 1.8, -2.4], "radius": 0.6},
    ]

    def meshes(first):  # the objects, from index ``first`` of the scene's objects on
        return [
            {"type": "mesh", "mesh": mesh_id, "material": red},
            {"type": "instance", "mesh": mesh_id, "transform": shift},
            {"type": "mesh", "vertices": (inline_v - [2, -1, 0]).tolist(),
             "faces": inline_f.tolist()},
            {"type": "instance", "mesh": first + 2, "transform": turn},
        ]

    for dtype in DTYPES:
        yield dtype, {"dtype": dtype, "objects": shapes + meshes(len(shapes))}
        yield dtype, {"dtype": dtype, "objects": meshes(0)}
        yield dtype, {"dtype": dtype, "objects": shapes}


def intersect_requests(seed):
    """(description, body, content type, accept, URL query) of every kind of ray batch."""
    origins, directions = rays(48, seed)
    n = len(origins)
    tmax = np.full(n, 20.0)
    tmax[::3] = np.inf
    for query in ("closest", "any", "all", "count"):
        fieldsets = ([[], ["normal"], ["uv", "normal", "point"]] if query == "closest" else [[]])
        for test in TRIANGLE_TESTS:
            for fields in fieldsets:
                base = {"query": query, "triangle_test": test, "fields": fields}
                body = {**base, "origins": origins.tolist(), "directions": directions.tolist()}
                yield f"json {query} {test} {fields}", json.dumps(body).encode(), \
                    "application/json", None, None
                per_ray = {**body, "tmin": [0.0] * n,
                           "tmax": [None if not np.isfinite(t) else t for t in tmax]}
                yield f"json per-ray {query} {test} {fields}", json.dumps(per_ray).encode(), \
                    "application/json", NPY, None
                # through the middle, where every scene has something to hit
                one = {**base, "origins": [[0, 0.5, -8]], "directions": [[0, 0, 1]],
                       "tmin": 0.5, "tmax": 30.0}
                yield f"json one ray {query} {test} {fields}", json.dumps(one).encode(), \
                    "application/json", None, None
                for ray_dtype in DTYPES:
                    six = np.hstack([origins, directions]).astype(ray_dtype)
                    eight = np.hstack([six, np.zeros((n, 1)), tmax[:, None]]).astype(ray_dtype)
                    params = {"query": query, "triangle_test": test}
                    if fields:
                        params["fields"] = fields
                    for accept in (None, NPY):
                        yield (f"npy {ray_dtype} (N, 6) {query} {test} {fields} {accept}",
                               npy_bytes(six), NPY, accept, params)
                        yield (f"npy {ray_dtype} (N, 6) tmax {query} {test} {fields} {accept}",
                               npy_bytes(six), NPY, accept, {**params, "tmin": 0.1, "tmax": 15})
                        yield (f"npy {ray_dtype} (N, 8) {query} {test} {fields} {accept}",
                               npy_bytes(eight), NPY, accept, params)
                        fortran = np.asfortranarray(six)
                        yield (f"npy {ray_dtype} fortran {query} {test} {fields} {accept}",
                               npy_bytes(fortran), NPY, accept, params)
    # rays that the service makes from a sensor (raycore.sensors)
    sensors = [
        {"type": "perspective", "position": [7, 5, -9], "look_at": [0, 1, 0], "width": 16,
         "height": 12},
        {"type": "orthographic", "position": [0, 6, -9], "look_at": [0, 1, 0],
         "view_height": 8, "width": 16, "height": 12},
        {"type": "lidar", "position": [0, 0.5, -8], "forward": [0, 0, 1], "up": [0, 1, 0],
         "vertical_fov": [-20, 20], "channels": 8, "columns": 32, "max_range": 40},
        {"type": "points", "sources": [[0, 0.5, -8]], "targets": [[0, 0.5, 8], [3, 1, 0]]}]
    for sensor in sensors:
        for query in ("closest", "any"):
            body = json.dumps({"rays": sensor, "query": query}).encode()
            yield f"rays {sensor['type']} {query}", body, "application/json", NPY, None
    cloud = json.dumps({"rays": {**sensors[2], "point_cloud": True}}).encode()
    for accept in (None, NPY, "model/ply"):
        yield f"rays lidar point cloud {accept}", cloud, "application/json", accept, None


def render_requests():
    views = [{"type": "perspective", "position": [7, 5, -9], "look_at": [0, 1, 0], "fov": 45},
             {"type": "orthographic", "position": [0, 6, -9], "look_at": [0, 1, 0],
              "view_height": 8}]
    for camera in views:
        for shading in ("depth", "normal", "lambert", "id"):
            tests = TRIANGLE_TESTS if shading == "lambert" else ("watertight",)
            for test in tests:
                for samples in (1, 4):
                    for smooth in (True, False):
                        yield {"camera": {**camera, "width": 24, "height": 16},
                               "shading": shading, "samples": samples, "smooth": smooth,
                               "triangle_test": test, "background": [10, 20, 30]}


# ----------------------------------------------------------------------------- the run


class CompileLog:
    """Records each function Numba compiles (not those it loads from its cache)."""

    def __init__(self):
        from numba.core import event

        outer = self

        class Listener(event.Listener):
            def on_start(self, ev):
                dispatcher = ev.data["dispatcher"]
                outer.compiled.append(f"{dispatcher.py_func.__module__}."
                                      f"{dispatcher.py_func.__qualname__}{ev.data['args']}")

            def on_end(self, ev):
                pass

        self.compiled = []
        event.register("numba:compile", Listener())


def kernel_signatures():
    """{(module.function, argument types)} of every kernel of raycore loaded in this process,
    compiled or from the cache."""
    from numba.core.dispatcher import Dispatcher

    found = set()
    for name, module in list(sys.modules.items()):
        if name != "raycore" and not name.startswith("raycore."):
            continue
        for attribute, value in vars(module).items():
            if isinstance(value, Dispatcher):
                found.update((f"{name}.{attribute}", types) for types in value.overloads)
    return found


def exercise(client):
    """Send every request; returns how many.  Raises on an unexpected answer."""
    sent = 0

    def call(what, method, path, ok=(200, 201), accept=None, **request):
        nonlocal sent
        headers = {**request.pop("headers", {}), **({"accept": accept} if accept else {})}
        response = client.request(method, path, headers=headers, **request)
        sent += 1
        if response.status_code not in ok:
            raise RuntimeError(f"{what}: {method} {path} answered {response.status_code}: "
                               f"{response.content[:500]!r}")
        if accept == NPY and response.headers["content-type"] != NPY:
            raise RuntimeError(f"{what}: asked for .npy, got {response.headers['content-type']}")
        return response

    deadline = time.monotonic() + 600
    while client.get("/readyz").status_code != 200:
        if time.monotonic() > deadline:
            raise RuntimeError("/readyz did not answer 200 within 600 s")
        time.sleep(0.1)
    call("healthz", "GET", "/healthz")
    vertices, faces = icosphere(2)
    mesh = call("upload obj", "POST", "/v1/meshes", content=obj_bytes(vertices, faces),
                headers={"content-type": "model/obj"}).json()
    call("upload stl form", "POST", "/v1/meshes",
         files={"file": ("sphere.stl", stl_bytes(*icosphere(1)), "application/octet-stream")})
    call("get mesh", "GET", f"/v1/meshes/{mesh['id']}")
    for number, (dtype, spec) in enumerate(scenes(mesh["id"])):
        scene = call(f"scene {number}", "POST", "/v1/scenes", json=spec).json()
        path = f"/v1/scenes/{scene['id']}"
        for what, body, content_type, accept, query in intersect_requests(number):
            call(f"scene {number} {what}", "POST", f"{path}/intersect", content=body,
                 headers={"content-type": content_type}, accept=accept, params=query)
        for request in render_requests():
            png = call(f"scene {number} render {request}", "POST", f"{path}/render",
                       json=request).content
            if not png.startswith(b"\x89PNG\r\n\x1a\n"):
                raise RuntimeError(f"render {request} is not a PNG")
        print(f"  scene {number} ({dtype}, {len(spec['objects'])} objects): done", flush=True)
    call("demo render", "POST", "/v1/scenes/demo/render",
         json={"camera": {"type": "perspective", "position": [7, 5, -9], "look_at": [0, 1, 0],
                          "width": 32, "height": 24}})
    return sent


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--after-warmup", action="store_true",
                        help="warm up in this process first, then check that the requests "
                             "reach no kernel signature the warm-up did not")
    args = parser.parse_args(argv)
    print(f"NUMBA_CACHE_DIR={os.environ.get('NUMBA_CACHE_DIR', '(unset: next to the sources)')}",
          flush=True)
    log = CompileLog()
    from starlette.testclient import TestClient

    from raycore._warmup import warm_up
    from service.app import create_app

    if args.after_warmup:
        warm_up()
    warmed = kernel_signatures()
    del log.compiled[:]  # the warm-up's
    started = time.perf_counter()
    with TestClient(create_app()) as client:
        sent = exercise(client)
    print(f"{sent} requests in {time.perf_counter() - started:.1f} s, "
          f"{len(log.compiled)} functions compiled", flush=True)
    if args.after_warmup:
        missed = sorted(map(str, kernel_signatures() - warmed))
        if missed:
            print("the requests reached kernel signatures that `raycore warmup` does not:\n  "
                  + "\n  ".join(missed), file=sys.stderr)
            return 1
        print("the requests reached no kernel signature beyond the warm-up's", flush=True)
    elif log.compiled:
        print("compiled although `raycore warmup` should have:\n  " + "\n  ".join(log.compiled),
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
