"""HTTP semantics (issue 14): Allow names every method of a path, HEAD and OPTIONS answer;
listings of the store; a Content-Type naming a mesh format wins over ?format=."""

from .data import SPEC

OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def test_allow_head_and_options(client, scene_id):
    path = f"/v1/scenes/{scene_id}"
    options = client.options(path)
    assert options.status_code == 204
    assert options.headers["allow"] == "DELETE, GET, HEAD, OPTIONS"
    refused = client.patch(path)
    assert refused.status_code == 405 and refused.headers["allow"] == options.headers["allow"]
    assert "PATCH" in refused.json()["detail"]
    head, get = client.head(path), client.get(path)
    assert head.status_code == 200 and head.content == b""
    assert head.headers["content-length"] == get.headers["content-length"]
    assert client.options("/nothing").status_code == 404


def test_listings_are_paginated_by_id(client):
    ids = sorted(client.post("/v1/scenes", json={"objects": [
        {"type": "sphere", "center": [0, 0, index], "radius": 1}]}).json()["id"]
        for index in range(3))
    first = client.get("/v1/scenes?limit=2").json()
    assert [item["id"] for item in first["items"]] == ids[:2]
    assert first["total"] == 3 and first["next_offset"] == 2
    last = client.get("/v1/scenes?limit=2&offset=2").json()
    assert [item["id"] for item in last["items"]] == ids[2:] and last["next_offset"] is None
    assert all(item["bytes"] > 0 and item["last_used"] for item in last["items"])
    assert client.get("/v1/scenes?limit=0").status_code == 422
    mesh = client.post("/v1/meshes", content=OBJ, headers={"content-type": "model/obj"}).json()
    assert [item["id"] for item in client.get("/v1/meshes").json()["items"]] == [mesh["id"]]


def test_content_type_wins_over_the_format_parameter(client):
    named = client.post("/v1/meshes?format=stl", content=OBJ,
                        headers={"content-type": "model/obj"})
    assert named.status_code == 201, named.text
    generic = client.post("/v1/meshes?format=obj", content=OBJ,
                          headers={"content-type": "application/octet-stream"})
    assert generic.status_code == 200 and generic.json()["id"] == named.json()["id"]
    unknown = client.post("/v1/meshes", content=OBJ,
                          headers={"content-type": "application/octet-stream"})
    assert unknown.status_code == 415 and "format" in unknown.json()["detail"]


def test_strict_numbers(client, scene_id):
    render = {"camera": {"type": "perspective", "position": [0, 0, -4], "look_at": [0, 0, 0],
                         "width": 8, "height": 8}, "background": [0, 0, False]}
    assert client.post(f"/v1/scenes/{scene_id}/render", json=render).status_code == 422
    sphere = {**SPEC["objects"][0], "radius": "1"}
    assert client.post("/v1/scenes", json={"objects": [sphere]}).status_code == 422


def test_a_repeated_single_valued_parameter_is_refused(client, scene_id):
    # FastAPI would read the last value; the document declares one (schemathesis's ST201)
    refused = client.get("/v1/scenes?offset=x&offset=0")
    assert refused.status_code == 422
    assert "offset" in refused.json()["detail"] and "2 times" in refused.json()["detail"]
    assert client.get("/v1/meshes?limit=1&limit=2").status_code == 422
    rays = {"origins": [[0, 0, -5]], "directions": [[0, 0, 1]]}
    url = f"/v1/scenes/{scene_id}/intersect"
    assert client.post(f"{url}?tmax=1&tmax=9", json=rays).status_code == 422
    # fields is a list: repeating it is how a URL lists several
    listed = client.post(f"{url}?fields=normal&fields=point", json=rays)
    assert listed.status_code == 200, listed.text
    assert {"normal", "point"} <= set(listed.json())
    assert client.get("/v1/scenes?limit=2&offset=0").status_code == 200
