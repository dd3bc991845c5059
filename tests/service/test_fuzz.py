"""Whatever a client sends, the answer is never a 500: random JSON, mutated valid bodies, bytes."""

import copy
import io
import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.app import create_app

from .data import SETTINGS, SPEC

FUZZ = settings(max_examples=60, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])

scalars = (st.none() | st.booleans() | st.integers(-10**20, 10**20)
           | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=8))
json_values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=5)
                           | st.dictionaries(st.text(max_size=8), inner, max_size=5),
                           max_leaves=20)

VALID = {
    "scene": SPEC,
    "intersect": {"origins": [[0, 0, 0], [0, 1, 0]], "directions": [[0, 0, 1], [0, 0, 1]],
                  "tmin": 0, "tmax": None, "query": "closest", "fields": ["normal"]},
    "render": {"camera": {"type": "perspective", "position": [0, 0, -4], "look_at": [0, 0, 0],
                          "fov": 40, "width": 8, "height": 8}, "shading": "lambert"},
}


@pytest.fixture(scope="module")
def fuzz_client():
    with TestClient(create_app(SETTINGS)) as client:
        scene = client.post("/v1/scenes", json=SPEC).json()["id"]
        yield client, {"scene": "/v1/scenes", "intersect": f"/v1/scenes/{scene}/intersect",
                       "render": f"/v1/scenes/{scene}/render"}


def post_json(client, url, body):
    # allow_nan: send NaN and Infinity the way JavaScript's JSON.stringify would not, but
    # Python's json module and other lax encoders do
    response = client.post(url, content=json.dumps(body, allow_nan=True),
                           headers={"content-type": "application/json"})
    assert response.status_code < 500, (url, body, response.text)
    if response.status_code >= 400:
        assert response.json()["detail"]
    return response


def mutate(data, value):
    """A valid body with one node, chosen by ``data``, replaced by ``value``."""
    body = copy.deepcopy(value)
    node, key = body, None
    while isinstance(node, (dict, list)) and node:
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        key = data.draw(st.sampled_from(keys))
        if data.draw(st.booleans()) or not isinstance(node[key], (dict, list)):
            node[key] = data.draw(json_values)
            return body
        node = node[key]
    return body


@FUZZ
@given(kind=st.sampled_from(sorted(VALID)), body=json_values)
def test_random_json(fuzz_client, kind, body):
    client, urls = fuzz_client
    post_json(client, urls[kind], body)


@FUZZ
@given(kind=st.sampled_from(sorted(VALID)), data=st.data())
def test_mutated_valid_bodies(fuzz_client, kind, data):
    client, urls = fuzz_client
    post_json(client, urls[kind], mutate(data, VALID[kind]))


@FUZZ
@given(body=st.binary(max_size=300), query=st.sampled_from(["", "?query=all", "?tmax=1"]))
def test_random_npy_bodies(fuzz_client, body, query):
    client, urls = fuzz_client
    header = (b"\x93NUMPY\x01\x00" + len(body).to_bytes(2, "little")) if len(body) % 2 else b""
    response = client.post(urls["intersect"] + query, content=header + body,
                           headers={"content-type": "application/x-npy"})
    assert response.status_code < 500, response.text


@FUZZ
@given(rays=st.lists(st.lists(st.floats(width=32), min_size=6, max_size=6), min_size=1,
                     max_size=20))
def test_random_npy_rays(fuzz_client, rays):
    client, urls = fuzz_client
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(rays, np.float32))
    response = client.post(urls["intersect"], content=buffer.getvalue(),
                           headers={"content-type": "application/x-npy"})
    assert response.status_code in (200, 422), response.text


@FUZZ
@given(body=st.binary(max_size=400), file_type=st.sampled_from(["obj", "ply", "stl", "off",
                                                                "glb"]))
def test_random_mesh_files(fuzz_client, body, file_type):
    client, _ = fuzz_client
    response = client.post(f"/v1/meshes?format={file_type}", content=body)
    assert response.status_code < 500, response.text


vector = st.lists(st.floats(-10, 10) | st.sampled_from([0.0, 1e30]), min_size=3, max_size=3)


@FUZZ
@given(rays=st.lists(st.tuples(vector, vector), max_size=4),
       query=st.sampled_from(["closest", "any", "all", "count"]), tmin=st.floats(-1, 5),
       tmax=st.none() | st.floats(-1, 5),
       fields=st.lists(st.sampled_from(["uv", "normal", "point"]), unique=True))
def test_random_ray_batches(fuzz_client, rays, query, tmin, tmax, fields):
    """Well-formed requests of any size, bounds and query: answered, or refused as invalid."""
    client, urls = fuzz_client
    body = {"origins": [origin for origin, _ in rays],
            "directions": [direction for _, direction in rays], "query": query, "tmin": tmin,
            "tmax": tmax, "fields": fields if query == "closest" else []}
    response = post_json(client, urls["intersect"], body)
    assert response.status_code in (200, 422), response.text
