"""The API key (issue 7): with RAYCORE_API_KEY set, endpoints that change the store need it."""

import dataclasses

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.config import load_settings

from .data import SETTINGS, SPEC

KEY = "s3cret-key"
OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
RAY = {"origins": [[0, 0, 0]], "directions": [[0, 0, 1]]}


@pytest.fixture(scope="module")
def guarded():
    with TestClient(create_app(dataclasses.replace(SETTINGS, api_key=KEY))) as client:
        yield client


def mutations(client, headers):
    """Each mutating request with ``headers``: upload, build, and two deletions."""
    return [client.post("/v1/meshes?format=obj", content=OBJ, headers=headers),
            client.post("/v1/scenes", json=SPEC, headers=headers),
            client.delete("/v1/meshes/0123", headers=headers),
            client.delete("/v1/scenes/0123", headers=headers)]


@pytest.mark.parametrize("headers", [
    {}, {"x-api-key": "wrong"}, {"authorization": "Bearer wrong"}, {"authorization": KEY},
    {"authorization": f"Basic {KEY}"}, {"x-api-key": ""}, {"x-api-key": KEY + "x"},
    {"x-api-key": KEY[:-1]}, {"x-api-key": KEY, "authorization": "Bearer wrong"},
    {"x-api-key": "wrong", "authorization": f"Bearer {KEY}"},
])
def test_mutations_without_the_key_are_401(guarded, headers):
    for response in mutations(guarded, headers):
        assert response.status_code == 401, response.text
        assert "API key" in response.json()["detail"]
        assert response.headers["www-authenticate"] == "Bearer"


@pytest.mark.parametrize("headers", [{"x-api-key": KEY}, {"authorization": f"Bearer {KEY}"}])
def test_mutations_with_the_key(guarded, headers):
    upload, scene, *deletions = mutations(guarded, headers)
    assert upload.status_code in (200, 201) and scene.status_code in (200, 201), scene.text
    assert [response.status_code for response in deletions] == [404, 404]
    scene_id = scene.json()["id"]
    assert guarded.delete(f"/v1/scenes/{scene_id}", headers=headers).status_code == 204


def test_queries_need_no_key(guarded):
    scene_id = guarded.post("/v1/scenes", json=SPEC, headers={"x-api-key": KEY}).json()["id"]
    assert guarded.get(f"/v1/scenes/{scene_id}").status_code == 200
    assert guarded.post(f"/v1/scenes/{scene_id}/intersect", json=RAY).status_code == 200
    assert guarded.get("/healthz").status_code == 200


def test_no_key_configured_needs_none(client):
    assert client.post("/v1/meshes?format=obj", content=OBJ).status_code == 201


def test_key_from_the_environment_is_not_shown():
    settings = load_settings({"RAYCORE_API_KEY": f" {KEY}\n"})
    assert settings.api_key == KEY and KEY not in repr(settings)
    with pytest.raises(ValueError, match="RAYCORE_API_KEY"):
        load_settings({"RAYCORE_API_KEY": "  "})


def test_openapi_documents_no_key_when_none_is_configured():
    document = create_app(SETTINGS).openapi()
    assert "securitySchemes" not in document["components"]
    assert "API key" not in document["info"]["description"]
    for item in document["paths"].values():
        for operation in item.values():
            assert "security" not in operation and "401" not in operation["responses"]


def test_openapi_documents_the_key():
    document = create_app(dataclasses.replace(SETTINGS, api_key=KEY)).openapi()
    schemes = document["components"]["securitySchemes"]
    assert schemes["APIKeyHeader"]["name"] == "X-API-Key"
    assert schemes["HTTPBearer"]["scheme"] == "bearer"
    guarded = {(path, method) for path, item in document["paths"].items()
               for method, operation in item.items() if operation.get("security")}
    assert guarded == {("/v1/meshes", "post"), ("/v1/meshes/{mesh_id}", "delete"),
                       ("/v1/scenes", "post"), ("/v1/scenes/{scene_id}", "delete")}
    for path, method in guarded:
        assert "401" in document["paths"][path][method]["responses"]
