"""The Python client (service.client) against a real ``raycore serve`` on 127.0.0.1: its answers
equal ``Scene``'s in process, and it reports refusals, keeps its connection and reopens it."""

import io
import time

import numpy as np
import pytest
import trimesh
from PIL import Image

from raycore import Scene
from service.client import Client, ServiceError
from service.process import running_service

from .data import SPEC, rays, scene_in_process

KEY = "client-test-key"
MAX_RAYS = 20_000


@pytest.fixture(scope="module")
def server():
    with running_service({"RAYCORE_API_KEY": KEY, "RAYCORE_MAX_RAYS": str(MAX_RAYS),
                          "RAYCORE_DEMO": "false"}) as url:
        yield url


@pytest.fixture(scope="module")
def client(server):
    with Client(server, api_key=KEY) as client:
        yield client


@pytest.fixture(scope="module", params=["float32", "float64"])
def scene(request, client):
    """(id on the server, the same scene in process) of SPEC, in both precisions."""
    created = client.create_scene({**SPEC, "dtype": request.param})
    return created["id"], scene_in_process(request.param)


@pytest.mark.parametrize("ray_dtype", [np.float32, np.float64])
def test_closest_hits_equal_scene(client, scene, ray_dtype):
    scene_id, reference = scene
    origins, directions = (a.astype(ray_dtype) for a in rays(5000, seed=3))
    fields = ("uv", "normal", "point")
    table = client.intersect(scene_id, origins, directions, fields=fields)
    hits = reference.intersect(origins, directions, fields=fields)
    assert len(np.unique(hits.geom_id)) == 9  # every object and misses
    assert table.dtype.names == ("t", "geom_id", "prim_id", *fields)
    for name in ("t", "geom_id", "prim_id", *fields):
        np.testing.assert_array_equal(table[name], getattr(hits, name))


def test_per_ray_bounds_and_every_query_equal_scene(client, scene):
    scene_id, reference = scene
    origins, directions = rays(3000, seed=4)
    tmin = np.random.default_rng(5).uniform(0.0, 4.0, len(origins))
    tmax = np.where(np.arange(len(origins)) % 3 == 0, np.inf, tmin + 2.0)
    hits = reference.intersect(origins, directions, tmin, tmax, triangle_test="moller")
    table = client.intersect(scene_id, origins, directions, tmin, tmax, triangle_test="moller")
    np.testing.assert_array_equal(table["t"], hits.t)
    np.testing.assert_array_equal(table["prim_id"], hits.prim_id)
    assert np.array_equal(
        client.intersect(scene_id, origins, directions, tmax=3.0, query="any")["occluded"],
        reference.occluded(origins, directions, tmax=3.0))
    assert np.array_equal(client.intersect(scene_id, origins, directions, query="count")["count"],
                          reference.count(origins, directions))
    crossings = client.intersect(scene_id, origins, directions, 1.0, query="all")
    every = reference.intersect_all(origins, directions, 1.0)
    for name in ("ray_index", "t", "geom_id", "prim_id"):
        np.testing.assert_array_equal(crossings[name], getattr(every, name))


def test_mesh_upload_from_a_path(client, tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=2)
    path = tmp_path / "sphere.stl"
    mesh.export(path)
    uploaded = client.upload_mesh(path)
    assert (uploaded["faces"], uploaded["closed"]) == (len(mesh.faces), True)
    scene_id = client.create_scene({"objects": [{"type": "mesh", "mesh": uploaded["id"]}]})["id"]
    assert client.scene(scene_id)["triangles"] == len(mesh.faces)
    origins, directions = rays(500)
    hits = Scene.from_file(path).intersect(origins - [0.0, 0.0, 3.0], directions)
    assert hits.hit.sum() > 20
    np.testing.assert_array_equal(
        client.intersect(scene_id, origins - [0.0, 0.0, 3.0], directions)["t"], hits.t)
    client.delete_scene(scene_id)
    with pytest.raises(ServiceError) as refused:
        client.scene(scene_id)
    assert refused.value.status == 404 and scene_id in refused.value.detail


def test_render_is_a_png_of_the_asked_size(client, scene):
    scene_id, _ = scene
    camera = {"type": "perspective", "position": np.array([0.0, 0.0, -2.0]),
              "look_at": [0.0, 0.0, 4.0], "fov": 60.0, "width": 40, "height": 30}
    image = np.asarray(Image.open(io.BytesIO(client.render(scene_id, camera, "id"))))
    assert image.shape == (30, 40, 3)
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 3  # several objects and background


def test_refusals_raise_service_errors_and_the_client_goes_on(client, scene, server):
    scene_id, reference = scene
    origins, directions = rays(MAX_RAYS + 1)
    with pytest.raises(ServiceError) as refused:
        client.intersect(scene_id, origins, directions)
    assert refused.value.status == 413 and str(MAX_RAYS) in refused.value.detail
    with pytest.raises(ServiceError) as refused:
        client.intersect(scene_id, origins[:5], directions[:5], fields=["colour"])
    assert refused.value.status == 422
    with Client(server) as keyless, pytest.raises(ServiceError) as refused:
        keyless.create_scene(SPEC)
    assert refused.value.status == 401
    origins, directions = rays(10)
    np.testing.assert_array_equal(client.intersect(scene_id, origins, directions)["t"],
                                  reference.intersect(origins, directions).t)


def test_bad_arguments_are_refused_before_sending(client):
    with pytest.raises(ValueError, match="origins"):
        client.intersect("demo", np.zeros((4, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="directions"):
        client.intersect("demo", np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="tmax"):
        client.intersect("demo", np.zeros((4, 3)), np.ones((4, 3)), tmax=np.ones(3))
    with pytest.raises(ValueError, match="format"):
        client.upload_mesh(b"solid nothing")
    with pytest.raises(ValueError):  # JSON has no NaN
        client.create_scene({"objects": [{"type": "sphere", "center": [np.nan, 0, 0],
                                          "radius": 1}]})
    with pytest.raises(ValueError, match="url"):
        Client("https://example.org")


def test_a_connection_the_server_closed_while_idle_is_reopened(server, scene):
    scene_id, reference = scene
    origins, directions = rays(50)
    with Client(server) as client:
        client.intersect(scene_id, origins, directions)
        time.sleep(5.5)  # uvicorn closes connections idle for 5 s
        table = client.intersect(scene_id, origins, directions)
    np.testing.assert_array_equal(table["t"], reference.intersect(origins, directions).t)
