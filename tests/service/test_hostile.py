"""Hostile input (issue 7): each request is refused with a 4xx and a message naming the problem,
and the service still answers a normal request afterwards.  Nothing it was not given is read."""

import io
import json
import socket
import struct
import sys
import time
import zlib

import httpx
import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient

from service.app import create_app
from service.config import Settings
from service.process import running_service

from .data import SETTINGS, SPEC, sphere_file

RAY = {"origins": [[0, 0, 0]], "directions": [[0, 0, 1]]}
RENDER = {"camera": {"type": "perspective", "position": [0, 0, -4], "look_at": [0, 0, 0],
                     "fov": 40, "width": 8, "height": 8}, "shading": "lambert",
          "light_direction": [0.4, 1.0, 0.6], "ambient": 0.1}
ORTHO = {"camera": {"type": "orthographic", "position": [0, 0, -4], "look_at": [0, 0, 0],
                    "up": [0, 1, 0], "view_height": 3, "width": 8, "height": 8},
         "background": [0, 0, 0]}
INTERSECT = {**RAY, "tmin": 0.5, "tmax": 100.0, "query": "closest"}
INTERSECT_LISTS = {**RAY, "tmin": [0.5], "tmax": [100.0]}
MESH_OBJECTS = {"objects": [
    {"type": "mesh", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]]},
    {"type": "instance", "mesh": 0, "transform": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0],
                                                  [0, 0, 0, 1]]}]}


@pytest.fixture(scope="module")
def hostile():
    """A client, the URL of a scene, and a check that the service still serves normally."""
    with TestClient(create_app(SETTINGS)) as client:
        scene = client.post("/v1/scenes", json=SPEC).json()["id"]
        url = f"/v1/scenes/{scene}"

        def refused(response, status=None, *words):
            assert 400 <= response.status_code < 500, response.text
            if status is not None:
                assert response.status_code == status, response.text
            detail = response.json()["detail"]
            for word in words:
                assert word.lower() in detail.lower(), (word, detail)
            normal = client.post(f"{url}/intersect", json=RAY)
            assert normal.status_code == 200 and normal.json()["geom_id"] == [0], normal.text
            return detail

        yield client, url, refused


def post_raw(client, url, content, content_type="application/json"):
    return client.post(url, content=content, headers={"content-type": content_type})


# ---------------------------------------------------------------------- JSON


@pytest.mark.parametrize("path", ["", "/intersect", "/render"])
@pytest.mark.parametrize(("body", "words"), [
    (b"{", ["json"]), (b'{"objects": [{"type": "sphere", "center": [0, 0', ["json"]),
    (b"\xff\xfe\x00garbage", []), (b"\xc3\x28", []), (b"", []), (b"null", []), (b"[]", []),
    (b"[" * 50_000 + b"]" * 50_000, ["recursion"]),
    (b'{"a":' * 20_000 + b"1" + b"}" * 20_000, ["recursion"]),
])
def test_malformed_truncated_and_nested_json(hostile, path, body, words):
    client, url, refused = hostile
    target = "/v1/scenes" if path == "" else url + path
    refused(post_raw(client, target, body), None, *words)


def test_huge_json_is_refused_by_size(hostile):
    client, url, refused = hostile
    body = json.dumps({"origins": [[0, 0, 0]] * 120_000, "directions": [[0, 0, 1]] * 120_000})
    refused(post_raw(client, f"{url}/intersect", body.encode()), 413, "limit")


@pytest.mark.parametrize(("path", "body", "where"), [
    ("/intersect", {"origins": [[0, 0]] * 60_000, "directions": [[0, 0, 1]] * 60_000},
     "body.origins.0"),
    ("/intersect", {**RAY, "tmin": ["x"] * 60_000}, "body.tmin.list[float].0"),
    ("", {"objects": [{"type": "sphere"}] * 40_000}, "body.objects.0.sphere"),
    ("", {"objects": [{"type": "mesh", "vertices": [[0, 0]] * 60_000, "faces": [[0, 1, 2]]}]},
     "body.objects.0.mesh.vertices.0"),
])
def test_a_long_list_of_bad_items_is_refused_at_its_first(hostile, path, body, where):
    """Validation stops at a long list's first bad item: a million of them took 27 s (holding
    every other request) to refuse with a million errors."""
    client, url, refused = hostile
    detail = refused(client.post(url + path if path else "/v1/scenes", json=body), 422)
    assert where in detail, detail
    assert "more)" not in detail, detail  # one error, or one per member of a union


def test_huge_streamed_body_is_refused(hostile):
    client, url, refused = hostile
    chunks = iter([b"[" + b"0," * 300_000] * 4)  # no Content-Length: counted as it arrives
    refused(client.post("/v1/scenes", content=chunks,
                        headers={"content-type": "application/json"}), 413, "limit")


def numeric_paths(value, path=()):
    """Paths of every number in a JSON value."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from numeric_paths(item, (*path, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from numeric_paths(item, (*path, index))
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield path


def replaced(value, path, new):
    body = json.loads(json.dumps(value))
    node = body
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = new
    return body


BODIES = {"scene": SPEC, "mesh objects": MESH_OBJECTS, "intersect": INTERSECT,
          "intersect lists": INTERSECT_LISTS, "render": RENDER, "ortho": ORTHO}
NUMERIC_CASES = [(kind, path) for kind, body in BODIES.items() for path in numeric_paths(body)]


@pytest.mark.parametrize(("kind", "path"), NUMERIC_CASES,
                         ids=[f"{kind}:{'.'.join(map(str, path))}" for kind, path in NUMERIC_CASES])
def test_non_finite_numbers_in_every_numeric_field(hostile, kind, path):
    client, url, refused = hostile
    target = {"scene": "/v1/scenes", "mesh objects": "/v1/scenes"}.get(
        kind, f"{url}/intersect" if kind.startswith("intersect") else f"{url}/render")
    name = next(str(key) for key in reversed(path) if isinstance(key, str))
    for bad in ("NaN", "Infinity", "-Infinity", "1e999"):
        text = json.dumps(replaced(BODIES[kind], path, "BAD")).replace('"BAD"', bad)
        refused(post_raw(client, target, text.encode()), 422, name)


@pytest.mark.parametrize("query", ["tmin=nan", "tmin=inf", "tmax=-inf", "tmax=1e999"])
def test_non_finite_url_options(hostile, query):
    client, url, refused = hostile
    refused(post_raw(client, f"{url}/intersect?{query}", npy(np.zeros((1, 6))),
                     "application/x-npy"), 422, query.split("=")[0])


def test_non_finite_npy_rays(hostile):
    client, url, refused = hostile
    for column, name in [(0, "origins"), (4, "directions"), (6, "tmin"), (7, "tmax")]:
        rays = np.array([[0, 0, 0, 0, 0, 1, 0, 10]], np.float64)
        rays[0, column] = np.nan
        refused(post_raw(client, f"{url}/intersect", npy(rays), "application/x-npy"), 422,
                name)


# ---------------------------------------------------------------------- .npy bodies


def npy(array):
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def npy_with_header(header, data=b""):
    """An .npy file with a header that says whatever it is given."""
    text = repr(header).encode()
    pad = -(10 + len(text) + 1) % 64
    return (b"\x93NUMPY\x01\x00" + (len(text) + pad + 1).to_bytes(2, "little") + text
            + b" " * pad + b"\n" + data)


class Detonator:
    """Unpickling this would set a flag: object arrays must never be unpickled."""

    fired = False

    def __reduce__(self):
        return (Detonator.fire, ())

    @staticmethod
    def fire():
        Detonator.fired = True


@pytest.mark.parametrize(("content", "status", "words"), [
    (npy(np.zeros((3, 5))), 422, ["shape"]),
    (npy(np.zeros(6)), 422, ["shape"]),
    (npy(np.zeros((1, 6, 1))), 422, ["shape"]),
    (npy(np.zeros((1, 6), np.int32)), 400, ["dtype"]),
    (npy(np.zeros((1, 6), np.float16)), 400, ["dtype"]),
    (npy(np.zeros((1, 6), np.complex128)), 400, ["dtype"]),
    (npy(np.zeros(1, [("o", "<f8", 3), ("d", "<f8", 3)])), 400, ["dtype"]),
    (npy_with_header({"descr": "<f8", "fortran_order": False, "shape": (100, 6)},
                     b"\0" * 48), 400, ["shape", "bytes"]),
    (npy_with_header({"descr": "<f8", "fortran_order": False, "shape": (1, 6)},
                     b"\0" * 4800), 400, ["bytes"]),
    (npy_with_header({"descr": "<f8", "fortran_order": False, "shape": (2**62, 8)}), 400,
     ["shape"]),
    (npy_with_header({"descr": "<f8", "fortran_order": False, "shape": (-1, 0)}), 400,
     ["negative"]),
    (npy_with_header({"descr": "<f8", "fortran_order": False, "shape": (0, -6)}), 400,
     ["negative"]),
    (npy(np.zeros((4, 6)))[:-5], 400, ["bytes"]),
    (npy(np.zeros((4, 6)))[:20], 400, ["npy"]),
    (b"\x93NUMPY\x03\x00" + b"\0" * 64, 400, ["version"]),
    (npy_with_header({"descr": "<f8"}), 400, ["npy"]),
    (npy_with_header("__import__('os').system('false')"), 400, ["npy"]),
    (b"not an npy file at all", 400, ["npy"]),
])
def test_hostile_npy_bodies(hostile, content, status, words):
    client, url, refused = hostile
    refused(post_raw(client, f"{url}/intersect", content, "application/x-npy"), status, *words)


def test_object_npy_is_never_unpickled(hostile):
    client, url, refused = hostile
    array = np.empty((1, 6), dtype=object)
    array[0, 0] = Detonator()
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    refused(post_raw(client, f"{url}/intersect", buffer.getvalue(), "application/x-npy"), 400,
            "dtype")
    assert not Detonator.fired


# ---------------------------------------------------------------------- mesh files


def ply(vertex_count, face_count, body, encoding="ascii"):
    return (f"ply\nformat {encoding} 1.0\nelement vertex {vertex_count}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {face_count}\n"
            "property list uchar int vertex_indices\nend_header\n").encode() + body


def glb(gltf, binary):
    """A binary glTF file of a JSON document and a binary chunk."""
    document = json.dumps(gltf, separators=(",", ":")).encode()
    document += b" " * (-len(document) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = (struct.pack("<I4s", len(document), b"JSON") + document
              + struct.pack("<I4s", len(binary), b"BIN\0") + binary)
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


TRIANGLE_BIN = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
                + np.array([0, 1, 2], "<u4").tobytes())


def triangle_gltf(nodes, roots, buffer=None, index_count=3):
    """A glTF document of one triangle mesh placed by ``nodes``."""
    return {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": roots}],
            "nodes": nodes, "meshes": [{"primitives": [{"attributes": {"POSITION": 0},
                                                         "indices": 1}]}],
            "buffers": [buffer or {"byteLength": 48}],
            "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                            {"buffer": 0, "byteOffset": 36, "byteLength": 12}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                           "min": [0, 0, 0], "max": [1, 1, 0]},
                          {"bufferView": 1, "componentType": 5125, "count": index_count,
                           "type": "SCALAR"}]}


TRIANGLE_PLY = b"0 0 0\n1 0 0\n0 1 0\n"


@pytest.mark.parametrize(("file_type", "content", "status", "words"), [
    ("obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n", 422, ["index"]),
    ("obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n", 422, ["index"]),
    ("obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", 422, ["no triangles"]),
    ("obj", b"", 422, []),
    ("ply", ply(3, 1, TRIANGLE_PLY + b"3 0 1 7\n"), 422, ["index", "vertices"]),
    ("ply", ply(3, 1, TRIANGLE_PLY + b"3 0 1 -1\n"), 422, ["index", "vertices"]),
    ("ply", ply(3, 0, TRIANGLE_PLY), 422, ["no triangles"]),
    ("ply", ply(10**12, 10**12, TRIANGLE_PLY + b"3 0 1 2\n"), 422, []),
    ("ply", ply(3, 10**9, np.zeros(9, "<f4").tobytes() + b"\x03" + bytes(12),
                "binary_little_endian"), 422, ["length"]),
    ("ply", ply(10**12, 1, b"", "binary_little_endian"), 422, []),
    ("stl", bytes(80) + struct.pack("<I", 2**31) + bytes(50), 422, []),
    ("off", b"OFF\n1000000000 1000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", 422, []),
    ("off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", 422, ["index"]),
    ("glb", b"glTF\x02\x00\x00\x00" + b"\xff" * 100, 422, []),
    ("glb", glb(triangle_gltf([{"mesh": 0}], [0], index_count=2**31), TRIANGLE_BIN), 422, []),
    ("zip", b"PK\x03\x04" + bytes(100), 422, ["format"]),
    ("3mf", b"PK\x03\x04" + bytes(100), 422, ["format"]),
])
def test_hostile_mesh_files(hostile, file_type, content, status, words):
    client, _, refused = hostile
    refused(post_raw(client, f"/v1/meshes?format={file_type}", content, "application/octet-stream"),
            status, *words)


@pytest.mark.parametrize("file_type", ["obj", "ply", "stl", "off", "glb"])
def test_binary_garbage_mesh_files(hostile, file_type):
    client, _, refused = hostile
    garbage = np.random.default_rng(7).integers(0, 256, 5000, dtype=np.uint8).tobytes()
    for content in (garbage, sphere_file(file_type)[0][: 300]):
        refused(post_raw(client, f"/v1/meshes?format={file_type}", content,
                         "application/octet-stream"))


def test_glb_instancing_bomb_is_refused_before_flattening(hostile):
    """One triangle placed at 50 000 nodes: 50 000 triangles from a 600 kB file."""
    client, _, refused = hostile
    count = 50_000
    bomb = glb(triangle_gltf([{"mesh": 0}] * count, list(range(count))), TRIANGLE_BIN)
    assert len(bomb) < SETTINGS.max_body_bytes
    refused(post_raw(client, "/v1/meshes?format=glb", bomb, "model/gltf-binary"), 413,
            "50000 triangles")


def test_glb_node_graph_bomb(hostile):
    """Each node's two children are the same node: 2**30 paths to one triangle, in 1 kB."""
    client, _, _ = hostile
    nodes = [{"children": [index + 1, index + 1]} for index in range(30)] + [{"mesh": 0}]
    response = post_raw(client, "/v1/meshes?format=glb",
                        glb(triangle_gltf(nodes, [0]), TRIANGLE_BIN), "model/gltf-binary")
    assert response.status_code in (201, 200, 413, 422), response.text


@pytest.fixture
def opened_paths():
    """Paths the process opens while the fixture is active (an audit hook, once installed)."""
    seen = []
    if not hasattr(sys, "_hostile_audit"):
        active = []

        def hook(event, args):
            if event == "open" and active:
                active[-1].append(str(args[0]))

        sys.addaudithook(hook)
        sys._hostile_audit = active
    sys._hostile_audit.append(seen)
    yield seen
    sys._hostile_audit.remove(seen)


@pytest.mark.parametrize(("file_type", "content"), [
    ("obj", b"mtllib SECRET.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
    ("obj", b"mtllib /etc/SECRET\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
    ("glb", glb(triangle_gltf([{"mesh": 0}], [0], {"byteLength": 48, "uri": "SECRET.bin"}), b"")),
    ("glb", glb(triangle_gltf([{"mesh": 0}], [0], {"byteLength": 48,
                                                  "uri": "file:///etc/SECRET"}), b"")),
    ("glb", glb(triangle_gltf([{"mesh": 0}], [0], {"byteLength": 48,
                                                  "uri": "../../../../etc/SECRET"}), b"")),
])
def test_mesh_files_cannot_name_server_side_files(hostile, opened_paths, file_type, content):
    client, _, _ = hostile
    response = post_raw(client, f"/v1/meshes?format={file_type}", content,
                        "application/octet-stream")
    assert response.status_code in (200, 201, 422), response.text
    assert not [path for path in opened_paths if "SECRET" in path]


# ---------------------------------------------------------------------- limits


def test_over_the_ray_limit(hostile):
    client, url, refused = hostile
    count = SETTINGS.max_rays + 1
    refused(post_raw(client, f"{url}/intersect", npy(np.tile([0.0, 0, 0, 0, 0, 1], (count, 1))),
                     "application/x-npy"), 413, str(count), "rays")
    # as JSON, the count is a maxItems of the document's schema: invalid (422), not too large
    refused(client.post(f"{url}/intersect", json={"origins": [[0, 0, 0]] * count,
                                                  "directions": [[0, 0, 1]] * count}),
            422, "rays")


def test_over_the_byte_limit(hostile):
    client, url, refused = hostile
    body = bytes(SETTINGS.max_body_bytes + 1)
    for target, kind in [(f"{url}/intersect", "application/x-npy"),
                         ("/v1/meshes?format=stl", "model/stl"),
                         ("/v1/scenes", "application/json")]:
        refused(post_raw(client, target, body, kind), 413, "bytes")


def test_over_the_triangle_limit(hostile):
    client, url, refused = hostile
    content, mesh = sphere_file("ply", subdivisions=5)
    assert len(mesh.faces) > SETTINGS.max_triangles
    refused(post_raw(client, "/v1/meshes?format=ply", content, "model/ply"), 413, "triangles")
    # one mesh object over the limit breaks the document's maxItems (422); a scene whose
    # objects are each within it but together over it is too large (413)
    count = SETTINGS.max_triangles + 1
    triangle = {"type": "mesh", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]]}
    refused(client.post("/v1/scenes", json={"objects": [{**triangle,
                                                         "faces": [[0, 1, 2]] * count}]}),
            422, "triangles")
    half = {**triangle, "faces": [[0, 1, 2]] * (count // 2 + 1)}
    refused(client.post("/v1/scenes", json={"objects": [half, half]}), 413, "triangles")


def test_over_the_plane_limit(hostile):
    """Every ray tests every plane: a scene of 100,000 took 27 s to render at 256x256."""
    client, url, refused = hostile
    planes = [{"type": "plane", "point": [0, 0, k], "normal": [0, 0, 1]}
              for k in range(SETTINGS.max_planes + 1)]
    refused(client.post("/v1/scenes", json={"objects": planes}), 413, "planes", "limit")
    created = client.post("/v1/scenes", json={"objects": planes[1:]})
    assert created.status_code == 201, created.text


def test_over_the_pixel_limit(hostile):
    client, url, refused = hostile
    camera = {**RENDER["camera"], "width": 129, "height": 128}
    refused(client.post(f"{url}/render", json={"camera": camera}), 413, "pixels")
    # a side over the limit breaks the document's maximum: invalid (422)
    for width, height in [(10**9, 10**9), (10**30, 1)]:
        camera = {**RENDER["camera"], "width": width, "height": height}
        refused(client.post(f"{url}/render", json={"camera": camera}), 422, "width")


def test_over_the_store_budget():
    """A scene bigger than the whole store is refused; many tiny scenes evict the oldest (each
    entry is charged for its Python objects, not only its arrays)."""
    settings = Settings(**{**SETTINGS.__dict__, "store_bytes": 2**20})
    with TestClient(create_app(settings)) as client:
        mesh = trimesh.creation.icosphere(subdivisions=4)  # three within the triangle limit
        spec = {"objects": [{"type": "mesh", "vertices": mesh.vertices.tolist(),
                             "faces": mesh.faces.tolist()}] * 3}
        response = client.post("/v1/scenes", json=spec)
        assert response.status_code == 413 and "store" in response.json()["detail"]
        ids = []
        for index in range(300):
            sphere = {"objects": [{"type": "sphere", "center": [0, 0, index], "radius": 1}]}
            created = client.post("/v1/scenes", json=sphere)
            assert created.status_code == 201, created.text
            ids.append(created.json()["id"])
        assert client.app.state.runtime.store.nbytes <= settings.store_bytes
        assert client.get(f"/v1/scenes/{ids[-1]}").status_code == 200
        assert client.get(f"/v1/scenes/{ids[0]}").status_code == 404


# ---------------------------------------------------------------------- a real server


def test_stalled_uploads_time_out_on_a_real_server():
    """Against uvicorn: a client that stops sending its body mid-way gets a 408 once the body
    deadline passes, and others are served meanwhile and afterwards."""
    with running_service({"RAYCORE_BODY_SECONDS": "1", "RAYCORE_DEMO": "false"}) as url:
        port = int(url.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), timeout=30) as stalled:
            stalled.sendall(b"POST /v1/scenes HTTP/1.1\r\nhost: x\r\ncontent-type: "
                            b"application/json\r\ncontent-length: 1000\r\n\r\n{\"objects\": [")
            served = httpx.post(f"{url}/v1/scenes", json=SPEC, timeout=30)
            assert served.status_code == 201, served.text
            start = time.monotonic()
            answer = b""
            while b"\r\n\r\n" not in answer or not answer.rstrip().endswith(b"}"):
                chunk = stalled.recv(4096)
                if not chunk:
                    break
                answer += chunk
            assert time.monotonic() - start < 10
        head, _, body = answer.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 408"), answer
        assert "did not all arrive" in json.loads(body)["detail"]
        scene = httpx.post(f"{url}/v1/scenes/{served.json()['id']}/intersect", json=RAY)
        assert scene.status_code == 200 and scene.json()["geom_id"] == [0]


def test_glb_textures_are_never_decoded(hostile, monkeypatch):
    """A 40 kB glTF whose texture is a 6000x6000 PNG (108 MB decoded): the geometry is read,
    the image never opened."""
    client, _, _ = hostile
    import PIL.Image

    opened = []
    monkeypatch.setattr(PIL.Image, "open", lambda *args, **kwargs: opened.append(args))
    side = 6000
    rows = zlib.compress(bytes(side + 1) * side, 9)

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))

    header = struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0)  # 8-bit grey
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", rows)
           + chunk(b"IEND", b""))
    uv = np.array([[0, 0], [1, 0], [0, 1]], "<f4").tobytes()
    gltf = triangle_gltf([{"mesh": 0}], [0], {"byteLength": 72 + len(png)})
    gltf["meshes"][0]["primitives"][0].update(material=0)
    gltf["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = 2
    gltf["bufferViews"] += [{"buffer": 0, "byteOffset": 48, "byteLength": 24},
                            {"buffer": 0, "byteOffset": 72, "byteLength": len(png)}]
    gltf["accessors"].append({"bufferView": 2, "componentType": 5126, "count": 3,
                              "type": "VEC2"})
    gltf.update(materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
                textures=[{"source": 0}], images=[{"bufferView": 3, "mimeType": "image/png"}])
    response = post_raw(client, "/v1/meshes?format=glb", glb(gltf, TRIANGLE_BIN + uv + png),
                        "model/gltf-binary")
    assert response.status_code in (200, 201) and response.json()["faces"] == 1, response.text
    assert not opened
