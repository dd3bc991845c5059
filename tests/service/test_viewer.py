"""The viewer page and the API docs in headless Chromium against a real ``raycore serve``, with
no network but the service's: what the page shows is checked on its screenshots and against
the service's own answers."""

import io
import json

import httpx
import numpy as np
import pytest
import trimesh
from PIL import Image

from raycore.camera import perspective_rays
from service.process import running_service

from .browser import chromium

KEY = "viewer-test-key"


@pytest.fixture(scope="module")
def server():
    with running_service() as url:
        yield url


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    with chromium(tmp_path_factory.mktemp("chromium")) as open_page:
        yield open_page


@pytest.fixture
def viewer(server, browser):
    """The viewer page, opened at ``/``, once it shows its first full frame."""
    tab = browser(server)
    tab.page.goto(f"{server}/")
    _wait_frame(tab, 0)
    yield tab
    tab.page.close()
    assert tab.refused == [] and tab.errors == []


def _frame(tab):
    return int(tab.page.get_by_test_id("view").get_attribute("data-frame") or 0)


def _wait_frame(tab, after, **expected):
    """Wait for a full frame later than frame ``after`` whose data attributes (``data-*``) are
    ``expected``; return its number."""
    conditions = " && ".join([f"Number(v.dataset.frame || 0) > {after}",
                              "v.dataset.kind === 'full'",
                              *(f"v.dataset.{name} === {json.dumps(value)}"
                                for name, value in expected.items())])
    tab.page.wait_for_function(f"() => {{ const v = document.querySelector("
                               f"'[data-testid=view]'); return {conditions}; }}")
    return _frame(tab)


def _screenshot(tab):
    """The picture element as the browser shows it: (H, W, 3) uint8."""
    png = tab.page.get_by_test_id("view").screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def _camera(tab):
    return json.loads(tab.page.get_by_test_id("view").get_attribute("data-camera"))


def _render(server, scene, camera, shading="lambert", samples=4):
    answer = httpx.post(f"{server}/v1/scenes/{scene}/render", timeout=120, json={
        "camera": camera, "shading": shading, "samples": samples})
    assert answer.status_code == 200, answer.text
    return np.asarray(Image.open(io.BytesIO(answer.content)).convert("RGB")).astype(int)


def test_root_leads_to_the_viewer_showing_the_demo(viewer, server):
    page = viewer.page
    assert page.url == f"{server}/viewer"
    assert page.get_by_test_id("scene").input_value() == "demo"
    shown = _screenshot(viewer)
    camera = _camera(viewer)
    assert shown.shape == (camera["height"], camera["width"], 3)
    # the picture is the service's render of the camera the page states, as it looks on screen
    expected = _render(server, "demo", camera)
    assert np.abs(shown - expected).mean() < 1.0
    # and it shows a lit scene: many colours, neither black nor blown out
    assert len(np.unique(shown.reshape(-1, 3), axis=0)) > 1000
    assert 40 < shown.mean() < 200
    assert all(url.startswith(server) for url in viewer.requested
               if not url.startswith(("data:", "blob:")))


def test_a_drag_changes_the_picture(viewer):
    page = viewer.page
    before, camera, frame = _screenshot(viewer), _camera(viewer), _frame(viewer)
    box = page.get_by_test_id("view").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    for step in range(1, 11):
        page.mouse.move(x + 12 * step, y + 3 * step)
    page.mouse.up()
    _wait_frame(viewer, frame)
    assert _camera(viewer)["position"] != camera["position"]
    after = _screenshot(viewer)
    assert np.abs(after - before).mean() > 5


def test_a_click_picks_what_intersect_answers_for_that_pixel(viewer, server):
    page = viewer.page
    camera = _camera(viewer)
    box = page.get_by_test_id("view").bounding_box()
    # the middle of the demo: the red sphere
    page.mouse.click(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.55)
    readout = page.get_by_test_id("pick")
    page.wait_for_function("() => document.querySelector('[data-testid=pick]').dataset.geomId "
                           "!== undefined")
    x, y = int(readout.get_attribute("data-x")), int(readout.get_attribute("data-y"))
    assert abs(x - camera["width"] * 0.5) <= 1 and abs(y - camera["height"] * 0.55) <= 1
    # the pixel's ray as the library makes it, cast through the intersect endpoint
    origins, directions = perspective_rays(camera["position"], camera["look_at"], camera["up"],
                                           camera["fov"], camera["width"], camera["height"])
    ray = y * camera["width"] + x
    answer = httpx.post(f"{server}/v1/scenes/demo/intersect", json={
        "origins": origins[ray:ray + 1].tolist(), "directions": directions[ray:ray + 1].tolist(),
        "fields": ["normal", "point"]}).json()
    assert answer["geom_id"][0] >= 0
    assert int(readout.get_attribute("data-geom-id")) == answer["geom_id"][0]
    assert int(readout.get_attribute("data-prim-id")) == answer["prim_id"][0]
    assert float(readout.get_attribute("data-t")) == pytest.approx(answer["t"][0], rel=1e-5)
    text = readout.inner_text()
    for value in (f"{answer['t'][0]:.6g}"[:5], str(answer["geom_id"][0]),
                  f"{answer['normal'][0][0]:.4f}", f"{answer['point'][0][1]:.4f}"):
        assert value in text
    assert page.get_by_test_id("marker").is_visible()


def test_shading_and_samples_choosers(viewer, server):
    page = viewer.page
    frame = _frame(viewer)
    page.get_by_test_id("shading").select_option("normal")
    frame = _wait_frame(viewer, frame, shading="normal")
    expected = _render(server, "demo", _camera(viewer), "normal")
    assert np.abs(_screenshot(viewer) - expected).mean() < 1.0
    page.get_by_test_id("samples").select_option("1")
    _wait_frame(viewer, frame, samples="1")
    one = _render(server, "demo", _camera(viewer), "normal", samples=1)
    assert np.abs(_screenshot(viewer) - one).mean() < 1.0


def _mesh_file(tmp_path):
    path = tmp_path / "capsule.ply"
    trimesh.creation.capsule(height=1.0, radius=0.5).export(path)
    return path


def test_uploading_a_mesh_shows_it(viewer, server, tmp_path):
    page = viewer.page
    demo, frame = _screenshot(viewer), _frame(viewer)
    page.get_by_test_id("upload").set_input_files(str(_mesh_file(tmp_path)))
    frame = _wait_frame(viewer, frame)
    scene = page.get_by_test_id("view").get_attribute("data-scene")
    assert scene != "demo" and page.get_by_test_id("scene").input_value() == scene
    assert "capsule.ply" in page.get_by_test_id("scene").inner_text()
    shown = _screenshot(viewer)
    assert np.abs(shown - demo).mean() > 10
    assert np.abs(shown - _render(server, scene, _camera(viewer))).mean() < 1.0
    # one mesh, framed: the middle of the picture is the mesh (geometry 0)
    ids = httpx.post(f"{server}/v1/scenes/{scene}/render", headers={"Accept": "application/x-npy"},
                     json={"camera": _camera(viewer), "shading": "id"})
    ids = np.load(io.BytesIO(ids.content))
    assert ids[ids.shape[0] // 2, ids.shape[1] // 2] == 0 and (ids == -1).any()


def test_api_key_field_and_errors_as_the_service_words_them(browser, tmp_path):
    with running_service({"RAYCORE_API_KEY": KEY}) as server:
        tab = browser(server)
        page = tab.page
        page.goto(f"{server}/viewer")
        frame = _wait_frame(tab, 0)
        mesh = _mesh_file(tmp_path)
        refused = httpx.post(f"{server}/v1/meshes", files={"file": (mesh.name, mesh.read_bytes())})
        assert refused.status_code == 401
        page.get_by_test_id("upload").set_input_files(str(mesh))
        error = page.get_by_test_id("error")
        error.wait_for(state="visible")
        assert error.inner_text() == refused.json()["detail"]
        page.get_by_test_id("api-key").fill(KEY)
        page.get_by_test_id("upload").set_input_files(str(mesh))
        _wait_frame(tab, frame, kind="full")
        assert page.get_by_test_id("view").get_attribute("data-scene") != "demo"
        assert not error.is_visible()
        page.close()
        # 401s are the service's answers, logged by the browser as failed resources
        assert tab.refused == [] and all("401" in text for text in tab.errors)


def test_docs_render_offline(server, browser):
    tab = browser(server)
    page = tab.page
    page.goto(f"{server}/docs")
    page.locator(".swagger-ui .info .title").wait_for()
    assert "raycore" in page.locator(".swagger-ui .info .title").inner_text()
    page.locator(".opblock-summary-path", has_text="/v1/scenes/{scene_id}/render").first.wait_for()
    shot = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB")).astype(int)
    assert len(np.unique(shot.reshape(-1, 3), axis=0)) > 20  # styled, not a bare page
    assert tab.refused == [] and tab.errors == []
    assert any(url.endswith("swagger-ui-bundle.js") for url in tab.requested)
    assert all(url.startswith(server) for url in tab.requested
               if not url.startswith(("data:", "blob:")))
    page.close()
