"""Health, readiness and the demo scene."""

import io
import threading
import time
from dataclasses import replace

import numpy as np
import trimesh
from fastapi.testclient import TestClient

import raycore
import service.app
from service.app import create_app
from service.demo import DEMO_CAMERA, demo_spec, load_demo, torus

from .data import SETTINGS, SPEC, rays
from .test_render_png import decode


def test_healthz_and_readyz_without_demo(client):
    assert client.get("/healthz").json() == {"status": "ok"}
    # the layer and thread count, and nothing more: the probe needs no key
    report = raycore.info()
    assert client.get("/readyz").json() == {
        "status": "ready", "threading_layer": report["threading_layer"],
        "threads": report["threads"]}


def wait_ready(client, timeout=600):
    deadline = time.monotonic() + timeout
    while (response := client.get("/readyz")).status_code == 503:
        assert response.json()["status"] == "starting"
        assert time.monotonic() < deadline, "the demo scene did not load"
        time.sleep(0.1)
    assert response.json()["status"] == "ready"


def test_demo_scene_is_served_and_renders():
    settings = replace(SETTINGS, demo=True, max_render_pixels=DEMO_CAMERA["width"]
                       * DEMO_CAMERA["height"])
    with TestClient(create_app(settings)) as client:
        assert client.get("/healthz").status_code == 200
        wait_ready(client)
        info = client.get("/v1/scenes/demo").json()
        assert info["objects"] == len(demo_spec().objects) and info["triangles"] > 2000
        assert client.get(f"/v1/scenes/{info['id']}").json() == info
        image = decode(client.post("/v1/scenes/demo/render", json={"camera": DEMO_CAMERA}))
        # the floor plane fills the lower image; every object shows in its own colour
        ids = decode(client.post("/v1/scenes/demo/render",
                                 json={"camera": DEMO_CAMERA, "shading": "id"}))
        assert np.all(image[-1] != 0)
        assert len(np.unique(ids.reshape(-1, 3), axis=0)) == info["objects"] + 1  # + background


def test_demo_loads_in_a_compute_slot(monkeypatch):
    # the demo's work holds a compute slot like a request's (with RAYCORE_COMPUTE_SLOTS=1, a
    # request waits for it)
    loading, released_at = threading.Event(), []

    def slow_demo(state):
        loading.set()
        time.sleep(1.0)
        released_at.append(time.monotonic())
        state.ready.set()

    monkeypatch.setattr(service.app, "load_demo", slow_demo)
    with TestClient(create_app(replace(SETTINGS, demo=True))) as client:
        assert loading.wait(10)
        assert client.get("/healthz").status_code == 200 and not released_at
        assert client.post("/v1/scenes", json=SPEC).status_code == 201
        assert released_at and time.monotonic() > released_at[0]
        wait_ready(client)


def test_a_request_for_the_demo_waits_while_it_loads(monkeypatch):
    # With several workers, /readyz answered by one says nothing of the one that takes the next
    # request: that one may still be loading the demo, and must not answer 404.
    loading = threading.Event()

    def slow_demo(state):
        loading.set()
        time.sleep(0.5)
        load_demo(state)

    monkeypatch.setattr(service.app, "load_demo", slow_demo)
    with TestClient(create_app(replace(SETTINGS, demo=True))) as client:
        assert loading.wait(10)
        assert client.get("/readyz").status_code == 503
        response = client.get("/v1/scenes/demo")
        assert response.status_code == 200
        assert response.json()["objects"] == len(demo_spec().objects)
        assert client.get("/v1/scenes/unknown").status_code == 404


def test_torus_is_closed_and_consistently_wound():
    vertices, faces = torus()
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


def test_answers_carry_the_service_time(client):
    for response in (client.get("/healthz"), client.get("/v1/scenes/none")):
        name, duration = response.headers["server-timing"].split(";dur=")
        assert name == "app" and float(duration) >= 0


def test_intersect_says_where_its_time_went(client, scene_id):
    origins, directions = rays()
    body = io.BytesIO()
    np.save(body, np.hstack([origins, directions]).astype(np.float32))
    answer = client.post(f"/v1/scenes/{scene_id}/intersect", content=body.getvalue(),
                         headers={"content-type": "application/x-npy"})
    assert answer.status_code == 200, answer.text
    metrics = dict(part.strip().split(";dur=") for part in
                   answer.headers["server-timing"].split(","))
    assert list(metrics) == ["body", "compute", "app"]
    body_ms, compute_ms, app_ms = (float(metrics[name]) for name in metrics)
    # the route's two parts lie within the app's time (each rounded to 0.1 ms)
    assert min(body_ms, compute_ms) >= 0 and body_ms + compute_ms <= app_ms + 0.2
