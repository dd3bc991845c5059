"""POST /v1/scenes/{id}/intersect: HTTP answers equal Scene's, in JSON and in .npy."""

import io
from dataclasses import replace

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service.app import create_app

from .data import SETTINGS, rays, scene_in_process

NPY = {"content-type": "application/x-npy", "accept": "application/x-npy"}


def npy_bytes(array, **save):
    stream = io.BytesIO()
    np.save(stream, array, **save)
    return stream.getvalue()


def load_npy(content):
    return np.load(io.BytesIO(content), allow_pickle=False)


def json_t(values):
    return np.array([np.inf if v is None else v for v in values], np.float32)


@pytest.fixture(scope="module")
def expected():
    """In-process answers for the test rays, and a check that the data is interesting."""
    scene = scene_in_process()
    origins, directions = rays()
    hits = scene.intersect(origins, directions, fields=("uv", "normal", "point"))
    assert 0 < hits.hit.mean() < 1 and len(np.unique(hits.geom_id)) == 9  # 8 objects and misses
    counts = scene.count(origins, directions)
    assert counts.max() >= 2
    return {"closest": hits, "any": scene.occluded(origins, directions, 0.0, 4.0),
            "all": scene.intersect_all(origins, directions), "count": counts}


def test_closest_in_json_equals_scene(client, scene_id, expected):
    origins, directions = rays()
    response = client.post(f"/v1/scenes/{scene_id}/intersect", json={
        "origins": origins.tolist(), "directions": directions.tolist(),
        "fields": ["uv", "normal", "point"]})
    assert response.status_code == 200, response.text
    answer, hits = response.json(), expected["closest"]
    np.testing.assert_array_equal(json_t(answer["t"]), hits.t)
    np.testing.assert_array_equal(answer["geom_id"], hits.geom_id)
    np.testing.assert_array_equal(answer["prim_id"], hits.prim_id)
    for name in ("uv", "normal", "point"):
        values = getattr(hits, name)
        assert [row is None for row in answer[name]] == (~hits.hit).tolist()
        np.testing.assert_array_equal(
            np.array([row for row in answer[name] if row is not None], np.float32),
            values[hits.hit])


def test_other_queries_in_json_equal_scene(client, scene_id, expected):
    origins, directions = rays()
    base = {"origins": origins.tolist(), "directions": directions.tolist()}
    url = f"/v1/scenes/{scene_id}/intersect"
    occluded = client.post(url, json={**base, "query": "any", "tmax": 4.0}).json()
    np.testing.assert_array_equal(occluded["occluded"], expected["any"])
    counted = client.post(url, json={**base, "query": "count"}).json()
    np.testing.assert_array_equal(counted["count"], expected["count"])
    every, hits = client.post(url, json={**base, "query": "all"}).json(), expected["all"]
    np.testing.assert_array_equal(every["counts"], hits.counts)
    np.testing.assert_array_equal(every["ray_index"], hits.ray_index)
    np.testing.assert_array_equal(np.array(every["t"], np.float32), hits.t)
    np.testing.assert_array_equal(every["geom_id"], hits.geom_id)
    np.testing.assert_array_equal(every["prim_id"], hits.prim_id)


def test_per_ray_bounds_in_json(client, scene_id):
    origins, directions = rays()
    tmin, tmax = np.full(len(origins), 0.5), [None if i % 2 else 3.0 for i in range(len(origins))]
    response = client.post(f"/v1/scenes/{scene_id}/intersect", json={
        "origins": origins.tolist(), "directions": directions.tolist(), "tmin": tmin.tolist(),
        "tmax": tmax})
    want = scene_in_process().intersect(origins, directions, tmin,
                                        [np.inf if v is None else v for v in tmax])
    np.testing.assert_array_equal(json_t(response.json()["t"]), want.t)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_closest_in_npy_equals_scene(client, scene_id, expected, dtype):
    origins, directions = rays()
    body = npy_bytes(np.hstack([origins, directions]).astype(dtype))
    response = client.post(f"/v1/scenes/{scene_id}/intersect?fields=normal&fields=uv",
                           content=body, headers=NPY)
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "application/x-npy"
    table, hits = load_npy(response.content), expected["closest"]
    if dtype == np.float64:  # the scene rounds rays to float32 itself
        hits = scene_in_process().intersect(origins, directions, fields=("normal", "uv"))
    assert table.dtype.names == ("t", "geom_id", "prim_id", "uv", "normal")
    np.testing.assert_array_equal(table["t"], hits.t)
    np.testing.assert_array_equal(table["geom_id"], hits.geom_id)
    np.testing.assert_array_equal(table["prim_id"], hits.prim_id)
    np.testing.assert_array_equal(table["normal"], hits.normal)
    np.testing.assert_array_equal(table["uv"], hits.uv)


def test_npy_rays_with_their_own_bounds_and_other_queries(client, scene_id, expected):
    origins, directions = rays()
    bounds = np.column_stack([np.zeros(len(origins)), np.full(len(origins), 4.0)])
    body = npy_bytes(np.hstack([origins, directions, bounds]).astype(np.float32))
    url = f"/v1/scenes/{scene_id}/intersect"
    occluded = load_npy(client.post(f"{url}?query=any", content=body, headers=NPY).content)
    np.testing.assert_array_equal(occluded["occluded"], expected["any"])
    six = npy_bytes(np.hstack([origins, directions]))
    every = load_npy(client.post(f"{url}?query=all", content=six, headers=NPY).content)
    assert every.dtype.names == ("ray_index", "t", "geom_id", "prim_id")
    np.testing.assert_array_equal(every["t"], expected["all"].t)
    np.testing.assert_array_equal(every["ray_index"], expected["all"].ray_index)
    counted = load_npy(client.post(f"{url}?query=count", content=six, headers=NPY).content)
    np.testing.assert_array_equal(counted["count"], expected["count"])
    bounded = load_npy(client.post(f"{url}?query=any&tmax=4", content=six, headers=NPY).content)
    np.testing.assert_array_equal(bounded["occluded"], expected["any"])


def test_npy_in_json_out_and_fortran_order(client, scene_id, expected):
    origins, directions = rays()
    body = npy_bytes(np.asfortranarray(np.hstack([origins, directions])))
    response = client.post(f"/v1/scenes/{scene_id}/intersect", content=body,
                           headers={"content-type": "application/x-npy"})
    assert response.headers["content-type"] == "application/json"
    np.testing.assert_array_equal(json_t(response.json()["t"]), expected["closest"].t)


# ---------------------------------------------------------------------- refusals


def post_npy(client, scene_id, body, query=""):
    return client.post(f"/v1/scenes/{scene_id}/intersect{query}", content=body, headers=NPY)


GOOD = np.hstack(rays(10)).astype(np.float32)


@pytest.mark.parametrize(("body", "status", "words"), [
    (npy_bytes(np.array([{"a": 1}], dtype=object), allow_pickle=True), 400, "dtype"),
    (npy_bytes(GOOD)[:-4], 400, "body holds"),
    (npy_bytes(GOOD) + b"\0" * 4, 400, "body holds"),
    (b"\x93NUMPY\x01\x00\x10\x00{'descr': 'O'}  \n", 400, "not a valid .npy"),
    (b"not numpy at all", 400, "not a valid .npy"),
    # regression: numpy's header parser raised tokenize.TokenError (a 500) on unbalanced brackets
    (b"\x93NUMPY\x01\x00\x10\x00{'shape': (1,  \n", 400, "not a valid .npy"),
    (npy_bytes(GOOD.astype(np.int32)), 400, "float32 or float64"),
    (npy_bytes(GOOD.astype(np.float16)), 400, "float32 or float64"),
    (npy_bytes(np.zeros(10, dtype=[("x", "<f4")])), 400, "float32 or float64"),
    (npy_bytes(GOOD[:, :5]), 422, "(N, 6) or (N, 8)"),
    (npy_bytes(GOOD.reshape(2, 5, 6)), 422, "(N, 6) or (N, 8)"),
    (npy_bytes(np.where(np.arange(6) == 4, np.nan, GOOD)), 422, "directions"),
    (npy_bytes(np.where(np.arange(6) == 0, np.inf, GOOD)), 422, "origins"),
    (npy_bytes(np.where(np.arange(6) >= 3, 0.0, GOOD)), 422, "non-zero"),
    (npy_bytes(np.zeros((SETTINGS.max_rays + 1, 6), np.float32)), 413, "limit"),
])
def test_bad_npy_bodies_are_refused_with_a_reason(client, scene_id, body, status, words):
    response = post_npy(client, scene_id, body)
    assert response.status_code == status, response.text
    assert words in response.json()["detail"]


def test_pickled_npy_is_never_loaded(client, scene_id):
    # a header whose descr would need unpickling, followed by a pickle payload
    payload = b"cos\nsystem\n(S'touch /tmp/raycore-pwned'\ntR."
    header = b"{'descr': '|O', 'fortran_order': False, 'shape': (1,), }"
    header += b" " * (63 - len(header) % 64) + b"\n"
    body = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + payload
    response = post_npy(client, scene_id, body)
    assert response.status_code == 400 and "dtype" in response.json()["detail"]


def test_n8_rays_own_bounds_win_over_the_url(client, scene_id):
    body = npy_bytes(np.hstack([GOOD, np.zeros((10, 1)), np.ones((10, 1))]))
    plain = post_npy(client, scene_id, body, "")
    with_url = post_npy(client, scene_id, body, "?tmin=0.5&tmax=3")
    assert plain.status_code == with_url.status_code == 200, with_url.text
    assert plain.content == with_url.content


@pytest.mark.parametrize(("query", "status"), [
    ("?query=nearest", 422), ("?fields=colour", 422), ("?tmin=nan", 422), ("?bogus=1", 422),
    ("?query=any&fields=normal", 422), ("?triangle_test=fast", 422),
])
def test_bad_url_options(client, scene_id, query, status):
    response = post_npy(client, scene_id, npy_bytes(GOOD), query)
    assert response.status_code == status, response.text
    assert response.json()["detail"]


ORIGINS = [[0.0, 0.0, 0.0]]
DIRECTIONS = [[0.0, 0.0, 1.0]]


@pytest.mark.parametrize(("body", "words"), [
    ({"origins": [[0.0, 0.0]], "directions": DIRECTIONS}, "origins.0"),
    ({"origins": ORIGINS, "directions": [[0, 0, 1], [0, 0, 1]]}, "directions"),
    ({"origins": ORIGINS, "directions": [[0.0, 0.0, 0.0]]}, "non-zero"),
    ({"origins": ORIGINS}, "origins and directions go together"),
    ({"origins": ORIGINS, "directions": DIRECTIONS, "query": "nearest"}, "query"),
    ({"origins": ORIGINS, "directions": DIRECTIONS, "tmin": [0.0, 1.0]}, "tmin"),
    ({"origins": ORIGINS, "directions": DIRECTIONS, "colour": 1}, "colour"),
    ({"origins": "everything", "directions": DIRECTIONS}, "origins"),
    ({"origins": ORIGINS, "directions": DIRECTIONS, "fields": ["normal"], "query": "count"},
     "fields apply"),
])
def test_bad_json_rays_are_refused_with_a_reason(client, scene_id, body, words):
    response = client.post(f"/v1/scenes/{scene_id}/intersect", json=body)
    assert response.status_code == 422, response.text
    assert words in response.json()["detail"]


@pytest.mark.parametrize("text", [
    '{"origins": [[NaN, 0, 0]], "directions": [[0, 0, 1]]}',
    '{"origins": [[Infinity, 0, 0]], "directions": [[0, 0, 1]]}',
    '{"origins": [[1e999, 0, 0]], "directions": [[0, 0, 1]]}',
    '{"origins": [[0, 0, 0]], "directions": [[0, 0, 1]]',
    "",
])
def test_non_finite_and_malformed_json(client, scene_id, text):
    response = client.post(f"/v1/scenes/{scene_id}/intersect", content=text,
                           headers={"content-type": "application/json"})
    assert response.status_code == 422, response.text
    assert response.json()["detail"]


def test_json_body_with_url_options_and_unknown_media(client, scene_id):
    """URL options apply to JSON bodies too; where the body gives an option, the body's wins."""
    url = f"/v1/scenes/{scene_id}/intersect"
    body = {"origins": ORIGINS, "directions": DIRECTIONS}
    assert set(client.post(f"{url}?query=any", json=body).json()) == {"occluded"}
    answer = client.post(f"{url}?query=any&tmax=0.5", json={**body, "query": "count"}).json()
    assert answer == {"count": [0]}  # count from the body, tmax from the URL
    assert client.post(url, json={**body, "query": "count"}).json()["count"] != [0]
    response = client.post(url, content=b"1,2,3", headers={"content-type": "text/csv"})
    assert response.status_code == 415 and "text/csv" in response.json()["detail"]


def test_too_many_json_rays_and_unknown_scene(client, scene_id):
    many = [[0.0, 0.0, 1.0]] * (SETTINGS.max_rays + 1)
    response = client.post(f"/v1/scenes/{scene_id}/intersect",
                           json={"origins": many, "directions": many})
    assert response.status_code == 422 and "limit" in response.json()["detail"]  # maxItems
    response = client.post("/v1/scenes/ffff/intersect", json={"origins": ORIGINS,
                                                              "directions": DIRECTIONS})
    assert response.status_code == 404 and "ffff" in response.json()["detail"]


@pytest.mark.parametrize("query", ["closest", "any", "all", "count"])
def test_misses_and_empty_batches(client, query):
    """Regression: an ``all`` answer without hits was a 500 (empty columns in JSON)."""
    empty_scene = client.post("/v1/scenes", json={"objects": []}).json()["id"]
    url = f"/v1/scenes/{empty_scene}/intersect"
    missed = client.post(url, json={"origins": ORIGINS, "directions": DIRECTIONS, "query": query})
    assert missed.status_code == 200, missed.text
    assert missed.json() == {"closest": {"t": [None], "geom_id": [-1], "prim_id": [-1]},
                             "any": {"occluded": [False]}, "count": {"count": [0]},
                             "all": {"ray_index": [], "t": [], "geom_id": [], "prim_id": [],
                                     "counts": [0]}}[query]
    empty = client.post(url, json={"origins": [], "directions": [], "query": query})
    assert empty.status_code == 200, empty.text
    assert all(values == [] for values in empty.json().values())
    table = load_npy(post_npy(client, empty_scene, npy_bytes(np.zeros((0, 6))),
                              f"?query={query}").content)
    assert len(table) == 0


def test_all_hits_past_the_limit_are_refused_before_they_are_listed():
    # ten boxes in a row along z: each ray down the row crosses the scene 20 times; an answer
    # may list 100 crossings (2M rays through 1,000 quads had taken the service past 8 GB)
    boxes = [{"type": "box", "lo": [-1, -1, 3 * i], "hi": [1, 1, 3 * i + 1]} for i in range(10)]
    with TestClient(create_app(replace(SETTINGS, max_hits=100))) as client:
        scene_id = client.post("/v1/scenes", json={"objects": boxes}).json()["id"]
        url = f"/v1/scenes/{scene_id}/intersect"
        answers = {}
        for count in (5, 6):
            answers[count] = client.post(url, json={
                "origins": [[0.1 * i, 0, -5] for i in range(count)],
                "directions": [[0, 0, 1]] * count, "query": "all"})
        assert answers[5].status_code == 200 and len(answers[5].json()["t"]) == 100
        assert answers[6].status_code == 413
        assert "cross the scene 120 times" in answers[6].json()["detail"]
