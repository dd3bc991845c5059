"""The data directory (RAYCORE_DATA_DIR) through the app: what was acknowledged is on disk and
found by a new app (a restart) or another one (a worker); corrupt files are 404, never 5xx; the
disk budget evicts the least recently used files."""

import dataclasses
import logging
import os
import shutil
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from raycore import arrayfile
from service.app import create_app

from .data import SETTINGS, SPEC, rays, sphere_file


def app_on(directory, **settings):
    return TestClient(create_app(dataclasses.replace(SETTINGS, data_dir=str(directory),
                                                     **settings)))


def files(directory):
    return sorted(p.relative_to(directory).as_posix() for p in directory.rglob("*")
                  if p.is_file())


def intersect(client, scene_id, count=300):
    origins, directions = rays(count)
    answer = client.post(f"/v1/scenes/{scene_id}/intersect", json={
        "origins": origins.tolist(), "directions": directions.tolist(), "fields": ["normal"]})
    assert answer.status_code == 200, answer.text
    return answer.json()


def uploaded_spec(client, subdivisions=2):
    data, _ = sphere_file("obj", subdivisions)
    mesh = client.post("/v1/meshes", content=data, headers={"content-type": "model/obj"})
    assert mesh.status_code in (200, 201), mesh.text
    return mesh.json()["id"], {**SPEC, "objects": [*SPEC["objects"], {
        "type": "instance", "mesh": mesh.json()["id"],
        "transform": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]]}]}


def test_acknowledged_entries_survive_a_new_app(tmp_path):
    with app_on(tmp_path) as first:
        mesh_id, spec = uploaded_spec(first)
        created = first.post("/v1/scenes", json=spec)
        assert created.status_code == 201
        scene_id = created.json()["id"]
        before = intersect(first, scene_id)
    assert files(tmp_path) == [f"meshes/{mesh_id}.rcf", f"scenes/{scene_id}.rcf"]
    with app_on(tmp_path) as second:  # a restart, or another worker
        assert second.get(f"/v1/scenes/{scene_id}").json() == created.json()
        assert intersect(second, scene_id) == before
        assert second.get(f"/v1/meshes/{mesh_id}").status_code == 200
        listed = second.get("/v1/scenes").json()
        assert [item["id"] for item in listed["items"]] == [scene_id]
        # known already: 200, not built again
        again = second.post("/v1/scenes", json=spec)
        assert again.status_code == 200 and again.json()["build_seconds"] == created.json()[
            "build_seconds"]
        assert second.post("/v1/meshes", content=sphere_file("obj")[0],
                           headers={"content-type": "model/obj"}).status_code == 200
        # a scene built in a new app from a mesh that only the directory holds
        other = {**spec, "dtype": "float64"}
        assert second.post("/v1/scenes", json=other).status_code == 201
        assert second.delete(f"/v1/scenes/{scene_id}").status_code == 204
    with app_on(tmp_path) as third:
        assert third.get(f"/v1/scenes/{scene_id}").status_code == 404
        assert third.get("/v1/scenes").json()["total"] == 1


def test_no_data_dir_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with TestClient(create_app(SETTINGS)) as client:
        assert client.post("/v1/scenes", json=SPEC).status_code == 201
    assert files(tmp_path) == []


def corrupt(path, how):
    data = path.read_bytes()
    if how == "truncated":
        path.write_bytes(data[:len(data) // 2])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "flipped":
        path.write_bytes(data[:-100] + bytes([data[-100] ^ 0xFF]) + data[-99:])
    elif how == "garbage":
        path.write_bytes(os.urandom(len(data)))
    else:  # checksums that check out, around arrays of the wrong names
        meta, arrays = arrayfile.read(path)
        arrayfile.write(path, meta, {name.replace("faces", "facez").replace("colors", "colorz"):
                                     array.copy() for name, array in arrays.items()})


@pytest.mark.parametrize("how", ["truncated", "empty", "flipped", "garbage", "renamed"])
def test_corrupt_files_are_logged_removed_and_absent(tmp_path, caplog, how):
    with app_on(tmp_path) as first:
        mesh_id, spec = uploaded_spec(first)
        scene_id = first.post("/v1/scenes", json=spec).json()["id"]
    for path in tmp_path.rglob("*.rcf"):
        corrupt(path, how)
    with caplog.at_level(logging.WARNING, "raycore.service"), app_on(tmp_path) as second:
        assert second.get(f"/v1/scenes/{scene_id}").status_code == 404
        assert second.post(f"/v1/scenes/{scene_id}/intersect", json={
            "origins": [[0, 0, 0]], "directions": [[0, 0, 1]]}).status_code == 404
        assert second.get(f"/v1/meshes/{mesh_id}").status_code == 404
        assert second.post("/v1/scenes", json=spec).status_code == 404  # its mesh is gone
        assert files(tmp_path) == []
        assert sum("removing unreadable" in r.getMessage() for r in caplog.records) == 2
        # sent again, as after an eviction
        assert uploaded_spec(second)[0] == mesh_id
        assert second.post("/v1/scenes", json=spec).status_code == 201
        assert len(intersect(second, scene_id)["t"]) == 300


def test_a_data_directory_emptied_under_a_running_service(tmp_path):
    with app_on(tmp_path) as client:
        mesh_id, spec = uploaded_spec(client)
        for folder in ("meshes", "scenes"):
            shutil.rmtree(tmp_path / folder)
        assert client.get("/v1/meshes").json()["total"] == 1  # still in this worker's memory
        assert client.delete(f"/v1/meshes/{mesh_id}").status_code == 204
        assert client.get(f"/v1/meshes/{mesh_id}").status_code == 404
        assert uploaded_spec(client)[0] == mesh_id
        assert client.post("/v1/scenes", json=spec).status_code == 201
        assert len(files(tmp_path)) == 2


def test_ids_that_are_not_content_ids_never_reach_the_file_system(tmp_path):
    with app_on(tmp_path) as client:
        for name in ("..%2F..%2Fetc%2Fpasswd", "demo", "0" * 31, "g" * 32):
            assert client.get(f"/v1/scenes/{name}").status_code == 404
            assert client.delete(f"/v1/meshes/{name}").status_code == 404


def test_disk_budget_evicts_least_recently_used(tmp_path):
    with app_on(tmp_path) as client:
        ids = [uploaded_spec(client, subdivisions)[0] for subdivisions in (3, 4)]
        sizes = [p.stat().st_size for p in sorted(tmp_path.rglob("*.rcf"))]
    budget = sum(sizes) + 1000  # the third mesh's file (3.4 kB) does not fit beside them
    with app_on(tmp_path, data_bytes=budget) as client:
        time.sleep(0.02)  # file times have finite resolution
        assert client.get(f"/v1/meshes/{ids[0]}").status_code == 200  # now the most recent
        time.sleep(0.02)
        third = uploaded_spec(client, 1)[0]  # pushes the files over the budget
        kept = {p.stem for p in tmp_path.rglob("*.rcf")}
        assert kept == {ids[0], third}  # the one not used since went
        assert sum(p.stat().st_size for p in tmp_path.rglob("*.rcf")) <= budget
    with app_on(tmp_path, data_bytes=1000) as client:
        data, _ = sphere_file("obj", 2)  # not stored yet
        refused = client.post("/v1/meshes", content=data, headers={"content-type": "model/obj"})
        assert refused.status_code == 413 and "RAYCORE_DATA_BYTES" in refused.json()["detail"]


def test_scene_files_load_rather_than_build(tmp_path):
    """A scene read back answers as the one built, in both dtypes and every query."""
    with app_on(tmp_path) as first:
        _, spec = uploaded_spec(first)
        built = {}
        for dtype in ("float32", "float64"):
            scene_id = first.post("/v1/scenes", json={**spec, "dtype": dtype}).json()["id"]
            built[scene_id] = [first.post(f"/v1/scenes/{scene_id}/intersect", json={
                "origins": rays()[0].tolist(), "directions": rays()[1].tolist(),
                "query": query}).json() for query in ("closest", "any", "count", "all")]
    with app_on(tmp_path) as second:
        for scene_id, answers in built.items():
            got = [second.post(f"/v1/scenes/{scene_id}/intersect", json={
                "origins": rays()[0].tolist(), "directions": rays()[1].tolist(),
                "query": query}).json() for query in ("closest", "any", "count", "all")]
            assert got == answers
            assert np.sum(np.array(answers[2]["count"])) > 0
