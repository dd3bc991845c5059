"""Against a real ``raycore serve`` (uvicorn) on 127.0.0.1: upload a mesh file, query, render,
concurrent requests, stop."""

import io
from concurrent.futures import ThreadPoolExecutor

import httpx
import numpy as np
import pytest
import trimesh
from PIL import Image

from raycore import Scene
from raycore.mesh import load_trimesh
from service.process import running_service

from .data import rays


@pytest.fixture(scope="module")
def server():
    """Base URL of a running service; stopped (and checked to stop cleanly) afterwards."""
    with running_service({"RAYCORE_MAX_RAYS": "100000"}) as url:
        yield url


@pytest.fixture(scope="module")
def mesh_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("meshes") / "torus.ply"
    trimesh.creation.torus(major_radius=1.0, minor_radius=0.3).apply_translation(
        [0.0, 0.0, 3.0]).export(path)
    return path


@pytest.fixture(scope="module")
def scene_and_reference(server, mesh_file):
    """A scene on the server with the uploaded mesh and a sphere, and the same in process."""
    with open(mesh_file, "rb") as file:
        upload = httpx.post(f"{server}/v1/meshes", files={"file": (mesh_file.name, file)})
    assert upload.status_code == 201, upload.text
    spec = {"objects": [{"type": "mesh", "mesh": upload.json()["id"]},
                        {"type": "sphere", "center": [0.0, 0.0, 3.0], "radius": 0.5}]}
    created = httpx.post(f"{server}/v1/scenes", json=spec)
    assert created.status_code == 201, created.text
    reference = Scene()
    loaded = load_trimesh(str(mesh_file))
    reference.add_mesh(loaded.vertices, loaded.faces)
    reference.add_sphere([0.0, 0.0, 3.0], 0.5)
    return f"{server}/v1/scenes/{created.json()['id']}", reference


def test_json_answers_equal_scene(scene_and_reference):
    url, reference = scene_and_reference
    origins, directions = rays()
    answer = httpx.post(f"{url}/intersect", json={
        "origins": origins.tolist(), "directions": directions.tolist(), "fields": ["normal"]})
    assert answer.status_code == 200, answer.text
    hits = reference.intersect(origins, directions, fields=("normal",))
    assert {0, 1, -1} <= set(hits.geom_id.tolist())
    got = answer.json()
    np.testing.assert_array_equal([np.inf if t is None else t for t in got["t"]], hits.t)
    np.testing.assert_array_equal(got["prim_id"], hits.prim_id)
    np.testing.assert_array_equal([n for n in got["normal"] if n is not None],
                                  hits.normal[hits.hit])


def test_npy_answers_equal_scene(scene_and_reference):
    url, reference = scene_and_reference
    origins, directions = rays(20000, seed=1)
    buffer = io.BytesIO()
    np.save(buffer, np.hstack([origins, directions]).astype(np.float32))
    answer = httpx.post(f"{url}/intersect?query=all", content=buffer.getvalue(),
                        headers={"content-type": "application/x-npy",
                                 "accept": "application/x-npy"})
    assert answer.status_code == 200, answer.text
    table = np.load(io.BytesIO(answer.content), allow_pickle=False)
    hits = reference.intersect_all(origins, directions)
    assert hits.counts.max() == 2 and set(hits.geom_id.tolist()) == {0, 1}  # in and out
    for name in ("ray_index", "t", "geom_id", "prim_id"):
        np.testing.assert_array_equal(table[name], getattr(hits, name))


def test_concurrent_requests_are_all_answered(scene_and_reference):
    url, reference = scene_and_reference
    batches = [rays(3000, seed=seed) for seed in range(6)]

    def ask(batch):
        origins, directions = batch
        return httpx.post(f"{url}/intersect", timeout=120, json={
            "origins": origins.tolist(), "directions": directions.tolist(), "query": "count"})

    with ThreadPoolExecutor(len(batches)) as pool:
        answers = list(pool.map(ask, batches))
    for (origins, directions), answer in zip(batches, answers, strict=True):
        np.testing.assert_array_equal(answer.json()["count"],
                                      reference.count(origins, directions))


def test_render_shows_the_scene(scene_and_reference, server):
    url, reference = scene_and_reference
    camera = {"type": "orthographic", "position": [0, 0, 0], "look_at": [0, 0, 1],
              "view_height": 3, "width": 90, "height": 90}
    answer = httpx.post(f"{url}/render", json={"camera": camera, "shading": "id"})
    assert answer.headers["content-type"] == "image/png"
    image = np.asarray(Image.open(io.BytesIO(answer.content)))
    # along z the sphere (radius 0.5) shows inside the torus's hole, the torus around it
    covered = np.any(image != 0, axis=2)
    pixel = 3 / 90
    hole, ring = (1 - 0.3) / pixel, (1 + 0.3) / pixel
    expected = np.pi * (0.5 / pixel) ** 2 + np.pi * (ring**2 - hole**2)
    assert covered.sum() == pytest.approx(expected, rel=0.03)
    assert len(np.unique(image.reshape(-1, 3), axis=0)) == 3
    demo = httpx.post(f"{server}/v1/scenes/demo/render",
                      json={"camera": {**camera, "position": [6, 4, -8], "look_at": [0, 1, 0]}})
    assert demo.status_code == 200


def test_errors_over_http(server):
    assert httpx.get(f"{server}/v1/scenes/nothing").status_code == 404
    broken = httpx.post(f"{server}/v1/scenes", content=b"{", headers={
        "content-type": "application/json"})
    assert broken.status_code == 422 and broken.json()["detail"]
