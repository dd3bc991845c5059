"""POST, GET and DELETE /v1/meshes: every format, raw or multipart, content ids, refusals."""

import numpy as np
import pytest

from .data import SETTINGS, sphere_file

#: The Content-Type that names each format.
MEDIA = {"obj": "model/obj", "ply": "model/ply", "stl": "model/stl", "off": "model/off",
         "glb": "model/gltf-binary"}


@pytest.mark.parametrize("file_type", sorted(MEDIA))
def test_upload_each_format_as_raw_body(client, file_type):
    data, sphere = sphere_file(file_type)
    response = client.post("/v1/meshes", content=data,
                           headers={"content-type": MEDIA[file_type]})
    assert response.status_code == 201, response.text
    info = response.json()
    assert info["faces"] == len(sphere.faces)
    # STL stores every triangle's corners: closed all the same once they are merged
    assert info["vertices"] == (3 * len(sphere.faces) if file_type == "stl"
                                else len(sphere.vertices))
    assert info["closed"] is True
    np.testing.assert_allclose(info["bounds"]["lo"], sphere.bounds[0], atol=1e-6)
    np.testing.assert_allclose(info["bounds"]["hi"], sphere.bounds[1], atol=1e-6)
    assert client.get(f"/v1/meshes/{info['id']}").json() == info


def test_format_parameter_and_multipart(client):
    data, _ = sphere_file("obj")
    raw = client.post("/v1/meshes?format=obj", content=data,
                      headers={"content-type": "application/octet-stream"})
    assert raw.status_code == 201
    form = client.post("/v1/meshes", files={"file": ("sphere.obj", data, "text/plain")})
    # the same geometry: the same id, stored once
    assert form.status_code == 200 and form.json() == raw.json()
    named = client.post("/v1/meshes?format=obj",
                        files={"file": ("upload.bin", data, "application/octet-stream")})
    assert named.json()["id"] == raw.json()["id"]


def test_open_mesh_is_not_closed(client):
    obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    info = client.post("/v1/meshes?format=obj", content=obj).json()
    assert info["faces"] == 1 and info["closed"] is False


def test_delete(client):
    data, _ = sphere_file("off")
    mesh_id = client.post("/v1/meshes?format=off", content=data).json()["id"]
    assert client.delete(f"/v1/meshes/{mesh_id}").status_code == 204
    assert client.get(f"/v1/meshes/{mesh_id}").status_code == 404
    assert client.delete(f"/v1/meshes/{mesh_id}").status_code == 404


@pytest.mark.parametrize(("kwargs", "status", "words"), [
    ({"content": b"v 0 0 0\n", "headers": {"content-type": "application/octet-stream"}}, 415,
     "format"),
    ({"content": b"v 0 0 0\nv 1 0 0\n", "params": {"format": "obj"}}, 422, "no triangles"),
    ({"content": b"\x00\x01garbage", "params": {"format": "glb"}}, 422, "could not read"),
    ({"content": b"solid x\n", "params": {"format": "dae"}}, 422, "query.format: Input should be"),
    ({"files": {"other": ("a.obj", b"v 0 0 0\n", "text/plain")}}, 422, "'file' part"),
    ({"content": b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "params": {"format": "obj"}}, 422,
     "finite"),
])
def test_bad_uploads_are_refused_with_a_reason(client, kwargs, status, words):
    response = client.post("/v1/meshes", **kwargs)
    assert response.status_code == status, response.text
    assert words in response.json()["detail"]


def test_limits(client):
    data, _ = sphere_file("ply", subdivisions=6)  # 81920 triangles, binary: under 2 MiB
    response = client.post("/v1/meshes?format=ply", content=data)
    assert response.status_code == 413
    assert str(SETTINGS.max_body_bytes) in response.json()["detail"]
    data, _ = sphere_file("ply", subdivisions=5)  # 20480 triangles: over the triangle limit
    assert len(data) < SETTINGS.max_body_bytes
    response = client.post("/v1/meshes?format=ply", content=data)
    assert response.status_code == 413 and "triangles" in response.json()["detail"]


def test_body_limit_without_content_length(client):
    """A streamed (chunked) body is cut off as it grows past the limit."""
    chunk = b"v 0 0 0\n" * 8192

    def stream():
        for _ in range(SETTINGS.max_body_bytes // len(chunk) + 2):
            yield chunk

    response = client.post("/v1/meshes?format=obj", content=stream())
    assert response.status_code == 413 and "limit" in response.json()["detail"]
