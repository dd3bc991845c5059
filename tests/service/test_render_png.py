"""POST /v1/scenes/{id}/render: PNGs that show the scene, and refusals."""

import io
import json

import numpy as np
import pytest
from PIL import Image

from .data import SETTINGS


def decode(response):
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "image/png"
    return np.asarray(Image.open(io.BytesIO(response.content)).convert("RGB"))


@pytest.fixture
def sphere_scene(client):
    spec = {"objects": [{"type": "sphere", "center": [0, 0, 0], "radius": 1}]}
    return client.post("/v1/scenes", json=spec).json()["id"]


@pytest.mark.parametrize("shading", ["depth", "normal", "lambert", "id"])
def test_sphere_silhouette_covers_its_projected_area(client, sphere_scene, shading):
    size, fov, distance = 100, 40.0, 4.0
    camera = {"type": "perspective", "position": [0, 0, -distance], "look_at": [0, 0, 0],
              "fov": fov, "width": size, "height": size}
    image = decode(client.post(f"/v1/scenes/{sphere_scene}/render",
                               json={"camera": camera, "shading": shading}))
    assert image.shape == (size, size, 3)
    covered = np.any(image != 0, axis=2)
    radius = np.tan(np.arcsin(1 / distance)) / np.tan(np.radians(fov) / 2) * size / 2
    assert covered.sum() == pytest.approx(np.pi * radius**2, rel=0.03)


def test_orthographic_view_and_background(client, sphere_scene):
    camera = {"type": "orthographic", "position": [0, 5, 0], "look_at": [0, 0, 0],
              "up": [0, 0, 1], "view_height": 4, "width": 64, "height": 32}
    image = decode(client.post(f"/v1/scenes/{sphere_scene}/render", json={
        "camera": camera, "shading": "depth", "background": [10, 20, 30]}))
    assert image.shape == (32, 64, 3)
    missed = np.all(image == [10, 20, 30], axis=2)
    # a unit sphere seen along an axis: a disk of radius 1 in a 4-unit view of 32 rows
    assert (~missed).sum() == pytest.approx(np.pi * 8**2, rel=0.05)


@pytest.mark.parametrize(("change", "status", "words"), [
    ({"width": 129, "height": 128}, 413, "pixels"),
    ({"look_at": [0, 0, -4]}, 422, "look_at"),
    ({"up": [0, 0, 1]}, 422, "up"),
    ({"fov": 180}, 422, "fov"),
    ({"width": 0}, 422, "width"),
    ({"type": "fisheye"}, 422, "fisheye"),
    ({"position": [0, 0, float("nan")]}, 422, "position"),
])
def test_bad_cameras(client, sphere_scene, change, status, words):
    camera = {"type": "perspective", "position": [0, 0, -4], "look_at": [0, 0, 0],
              "width": 32, "height": 32, **change}
    # NaN as JavaScript writes it: not JSON, and not a number the service accepts
    response = client.post(f"/v1/scenes/{sphere_scene}/render",
                           content=json.dumps({"camera": camera}),
                           headers={"content-type": "application/json"})
    assert response.status_code == status, response.text
    assert words in response.json()["detail"]
    assert SETTINGS.max_render_pixels < 129 * 128


@pytest.mark.parametrize(("change", "words"), [
    ({"shading": "phong"}, "shading"),
    ({"light_direction": [0, 0, 0]}, "light_direction"),
    ({"background": [0, 0, 256]}, "background"),
    ({"ambient": -0.1}, "ambient"),
])
def test_bad_shading_options(client, sphere_scene, change, words):
    camera = {"type": "perspective", "position": [0, 0, -4], "look_at": [0, 0, 0],
              "width": 8, "height": 8}
    response = client.post(f"/v1/scenes/{sphere_scene}/render", json={"camera": camera, **change})
    assert response.status_code == 422, response.text
    assert words in response.json()["detail"]
