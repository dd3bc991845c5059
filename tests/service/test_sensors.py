"""The intersect endpoint's ``"rays"``: sensors described in JSON give the rays that
raycore.sensors gives in process, and the same hits; their ray counts are bounded by the limit."""

import io

import httpx
import numpy as np
import pytest
import trimesh

from raycore import sensors
from service.process import running_service

from .data import SETTINGS, SPEC, scene_in_process

LIDAR = {"type": "lidar", "position": [0.1, 0.2, 0.3], "forward": [0.0, 0.0, 1.0],
         "up": [0.0, 1.0, 0.0], "vertical_fov": [-40.0, 30.0], "channels": 24,
         "horizontal_resolution": 5.0, "max_range": 6.0}
#: LIDAR as raycore.sensors.lidar's keyword arguments (the position goes first)
LIDAR_ARGUMENTS = {name: value for name, value in LIDAR.items()
                   if name not in ("type", "position")}


def _lidar_in_process(dtype="float32"):
    return sensors.lidar(LIDAR["position"], **LIDAR_ARGUMENTS, dtype=dtype)


def _npy(response):
    assert response.status_code == 200, response.text
    return np.load(io.BytesIO(response.content), allow_pickle=False)


def test_lidar_answers_hits_ranges_and_points_as_in_process(client, scene_id):
    answer = client.post(f"/v1/scenes/{scene_id}/intersect", json={"rays": LIDAR})
    assert answer.status_code == 200, answer.text
    got = answer.json()
    rays = _lidar_in_process()
    hits = scene_in_process().intersect(*rays, fields=("point",))
    # misses within the range as well as hits on several objects
    assert len(set(hits.geom_id.tolist())) >= 4 and 0.2 < hits.hit.mean() < 0.9
    t = np.array([np.inf if value is None else value for value in got["t"]])
    np.testing.assert_array_equal(t, hits.t)
    np.testing.assert_array_equal(got["geom_id"], hits.geom_id)
    np.testing.assert_array_equal(got["prim_id"], hits.prim_id)
    # a return's range is its distance from the sensor, and its point lies there
    ranges = np.array([np.nan if value is None else value for value in got["range"]])
    points = np.array([[np.nan] * 3 if value is None else value for value in got["point"]])
    hit = hits.hit
    np.testing.assert_array_equal(np.isfinite(ranges), hit)
    assert np.all(ranges[hit] <= 6.0)
    np.testing.assert_allclose(np.linalg.norm(points[hit] - [0.1, 0.2, 0.3], axis=1),
                               ranges[hit], rtol=1e-5)


def test_lidar_point_cloud_as_json(client, scene_id):
    answer = client.post(f"/v1/scenes/{scene_id}/intersect",
                         json={"rays": {**LIDAR, "point_cloud": True}})
    assert answer.status_code == 200, answer.text
    hits = scene_in_process().intersect(*_lidar_in_process(), fields=("point",))
    np.testing.assert_allclose(answer.json()["points"], hits.point[hits.hit], rtol=1e-6)


def test_body_bounds_narrow_a_sensors_range(client, scene_id):
    answer = client.post(f"/v1/scenes/{scene_id}/intersect",
                         json={"rays": LIDAR, "tmin": 2.5, "tmax": 10.0})
    rays = _lidar_in_process()
    hits = scene_in_process().intersect(rays.origins, rays.directions, 2.5, 6.0)
    assert np.isfinite(hits.t).sum() > 10
    got = np.array([np.inf if value is None else value for value in answer.json()["t"]])
    np.testing.assert_array_equal(got, hits.t)


def test_camera_rays_are_the_render_cameras(client, scene_id):
    camera = {"type": "perspective", "position": [0.0, 0.5, -2.0], "look_at": [0.0, 0.0, 4.0],
              "fov": 60.0, "width": 40, "height": 30}
    answer = client.post(f"/v1/scenes/{scene_id}/intersect",
                         json={"rays": camera, "fields": ["normal"]})
    assert answer.status_code == 200, answer.text
    rays = sensors.perspective([0.0, 0.5, -2.0], [0.0, 0.0, 4.0], fov=60.0, width=40,
                               height=30, dtype="float32")
    hits = scene_in_process().intersect(*rays, fields=("normal",))
    assert len(set(hits.geom_id.tolist())) >= 5
    got = answer.json()
    np.testing.assert_array_equal(got["geom_id"], hits.geom_id)
    np.testing.assert_array_equal([np.inf if t is None else t for t in got["t"]], hits.t)
    normals = [[np.nan] * 3 if n is None else n for n in got["normal"]]
    np.testing.assert_array_equal(normals, hits.normal)
    # the orthographic camera's view height is required, as the render's
    bad = client.post(f"/v1/scenes/{scene_id}/intersect",
                      json={"rays": {**camera, "type": "orthographic"}})
    assert bad.status_code == 422 and "view_height" in bad.json()["detail"]


def test_sight_lines_between_points(client, scene_id):
    # from the origin: the sphere's centre (0, 0, 3) hides (0, 0, 5); (0, 0, 2) lies before it
    answer = client.post(f"/v1/scenes/{scene_id}/intersect", json={
        "query": "any", "rays": {"type": "points", "sources": [[0.0, 0.0, 0.0]],
                                 "targets": [[0.0, 0.0, 5.0], [0.0, 0.0, 2.0]]}})
    assert answer.status_code == 200, answer.text
    assert answer.json()["occluded"] == [True, False]
    closest = client.post(f"/v1/scenes/{scene_id}/intersect", json={
        "rays": {"type": "points", "sources": [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
                 "targets": [[0.0, 0.0, 5.0], [0.0, 0.0, 5.0]]}}).json()
    # t is the fraction of the way: the sphere's near side at z = 2.5
    np.testing.assert_allclose(closest["t"], [2.5 / 5, 1.5 / 4], rtol=1e-6)


@pytest.mark.parametrize("rays, status, words", [
    # the schema's maxima: one field over the ray limit
    ({**LIDAR, "horizontal_resolution": None, "columns": SETTINGS.max_rays + 1}, 422,
     "columns"),
    ({"type": "perspective", "position": [0, 0, 0], "look_at": [0, 0, 1], "width": 10**12,
      "height": 1}, 422, "width"),
    # a product over it, refused before any ray is made
    ({**LIDAR, "channels": 1000, "horizontal_resolution": None, "columns": 1000}, 413,
     "1000 channels x 1000 columns"),
    ({**LIDAR, "vertical_fov": None, "channels": None, "elevations": [0.0] * 5000}, 413,
     "5000 channels x 72 columns"),
    ({"type": "lidar", "position": [0, 0, 0], "preset": "ouster-os1-128"}, 413, "limit"),
    ({"type": "orthographic", "position": [0, 0, 0], "look_at": [0, 0, 1], "view_height": 1.0,
      "width": 5000, "height": 5000}, 413, "5000x5000"),
    ({**LIDAR, "horizontal_resolution": 0.01}, 422, "horizontal_resolution"),
    ({"type": "points", "sources": [[0, 0, 0]], "targets": [[0, 0, 1]] * 5001}, 422,
     "targets"),
    # what the library refuses
    ({**LIDAR, "forward": [0.0, 2.0, 0.0]}, 422, "forward"),
    ({**LIDAR, "max_range": 1.0, "min_range": 2.0}, 422, "max_range"),
    ({**LIDAR, "horizontal_resolution": None}, 422, "horizontal_resolution or columns"),
    ({**LIDAR, "vertical_fov": [10.0, -10.0]}, 422, "vertical_fov"),
    ({**LIDAR, "vertical_fov": [-91.0, 10.0]}, 422, "vertical_fov"),
    ({**LIDAR, "horizontal_resolution": 0.0}, 422, "horizontal_resolution"),
    ({**LIDAR, "channels": 2.0}, 422, "channels"),
    ({**LIDAR, "point_cloud": 1}, 422, "point_cloud"),
    ({**LIDAR, "preset": "hdl"}, 422, "preset"),
    ({"type": "points", "sources": [[0, 0, 0], [1, 1, 1]], "targets": [[0, 0, 1]] * 3}, 422,
     "as many"),
    ({"type": "points", "sources": [[0, 0, 0]], "targets": [[0, 0, 0]]}, 422, "differ"),
    ({"type": "sonar", "position": [0, 0, 0]}, 422, "sonar"),
])
def test_bad_sensors_are_refused_and_the_service_keeps_serving(client, scene_id, rays, status,
                                                               words):
    answer = client.post(f"/v1/scenes/{scene_id}/intersect", json={"rays": rays})
    assert answer.status_code == status, answer.text
    assert words in answer.json()["detail"]
    assert client.post(f"/v1/scenes/{scene_id}/intersect",
                       json={"rays": LIDAR}).status_code == 200


@pytest.mark.parametrize("body, words", [
    ({"rays": LIDAR, "origins": [[0, 0, 0]], "directions": [[0, 0, 1]]}, "either"),
    ({}, "either"),
    ({"rays": LIDAR, "tmax": [1.0] * 1728}, "per-ray"),
    ({"rays": {**LIDAR, "point_cloud": True}, "query": "count"}, "point_cloud"),
    ({"rays": LIDAR, "query": "any", "fields": ["normal"]}, "fields"),
])
def test_rays_rules_the_schema_cannot_state(client, scene_id, body, words):
    answer = client.post(f"/v1/scenes/{scene_id}/intersect", json=body)
    assert answer.status_code == 422, answer.text
    assert words in answer.json()["detail"]


@pytest.fixture(scope="module")
def server():
    with running_service({"RAYCORE_DEMO": "false", "RAYCORE_MAX_RAYS": "300000"}) as url:
        spec = {**SPEC, "dtype": "float64"}
        created = httpx.post(f"{url}/v1/scenes", json=spec)
        assert created.status_code == 201, created.text
        yield f"{url}/v1/scenes/{created.json()['id']}/intersect"


def test_http_lidar_preset_hits_equal_in_process_exactly(server):
    """Over a real uvicorn, .npy answers: a preset's rays made by the service, traced there,
    equal the same preset's rays made and traced in process, bit for bit."""
    request = {"rays": {"type": "lidar", "position": [0.0, 0.0, 0.0], "forward": [0, 0, 1],
                        "up": [0, 1, 0], "preset": "ouster-os1-128"}, "fields": ["normal"]}
    table = _npy(httpx.post(server, json=request, headers={"accept": "application/x-npy"},
                            timeout=120))
    rays = sensors.lidar([0.0, 0.0, 0.0], [0, 0, 1], [0, 1, 0], preset="ouster-os1-128")
    hits = scene_in_process("float64").intersect(*rays, fields=("normal", "point"))
    assert len(table) == 128 * 1024 and 0.2 < hits.hit.mean() < 1
    for name in ("t", "geom_id", "prim_id", "normal", "point"):
        np.testing.assert_array_equal(table[name], getattr(hits, name), err_msg=name)
    np.testing.assert_array_equal(table["range"], hits.t)


@pytest.mark.parametrize("accept", ["application/x-npy", "model/ply"])
def test_http_point_cloud_files(server, accept):
    request = {"rays": {**LIDAR, "point_cloud": True}}
    answer = httpx.post(server, json=request, headers={"accept": accept}, timeout=120)
    assert answer.status_code == 200, answer.text
    assert answer.headers["content-type"] == accept
    hits = scene_in_process("float64").intersect(*_lidar_in_process("float64"),
                                                 fields=("point",))
    if accept == "model/ply":
        cloud = trimesh.load(io.BytesIO(answer.content), file_type="ply")
        assert isinstance(cloud, trimesh.PointCloud)
        # trimesh writes PLY vertices as float32
        points, expected = cloud.vertices, hits.point[hits.hit].astype(np.float32)
    else:
        points, expected = _npy(answer), hits.point[hits.hit]
    assert points.shape == (hits.hit.sum(), 3) and len(points) > 100
    np.testing.assert_array_equal(points, expected)
