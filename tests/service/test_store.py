"""The scene and mesh store: least-recently-used eviction under a byte budget."""

from dataclasses import replace

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.errors import LimitExceeded
from service.store import Store, content_id

from .data import SETTINGS


def test_least_recently_used_goes_first():
    store = Store(budget=100)
    store.put("scene", "a", "A", 40)
    store.put("scene", "b", "B", 40)
    assert store.get("scene", "a") == "A"  # now b is the least recently used
    store.put("scene", "c", "C", 40)
    assert store.get("scene", "b") is None
    assert store.get("scene", "a") == "A" and store.get("scene", "c") == "C"
    assert store.nbytes == 80


def test_pinned_entries_stay_and_aliases_resolve():
    store = Store(budget=100)
    store.put("scene", "demo-hash", "D", 50, pinned=True)
    store.alias("scene", "demo", "demo-hash")
    store.put("scene", "x", "X", 50)
    store.put("scene", "y", "Y", 50)
    assert store.get("scene", "demo") == "D" and store.get("scene", "x") is None
    with pytest.raises(LimitExceeded, match="at most 50 bytes"):
        store.put("scene", "z", "Z", 51)


def test_kinds_are_separate_and_existing_values_are_kept():
    store = Store(budget=100)
    assert store.put("mesh", "k", "mesh", 10) == ("mesh", True)
    assert store.put("scene", "k", "scene", 10) == ("scene", True)
    assert store.put("mesh", "k", "other", 10) == ("mesh", False)
    assert store.delete("mesh", "k") and not store.delete("mesh", "k")
    assert store.get("scene", "k") == "scene" and store.nbytes == 10


def test_content_id_separates_parts():
    assert content_id(b"ab", b"c") != content_id(b"a", b"bc")
    assert content_id(b"ab", b"c") == content_id(b"ab", b"c")
    assert len(content_id(b"")) == 32


def test_the_service_evicts_old_scenes_under_its_budget():
    sphere = {"objects": [{"type": "mesh", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                           "faces": [[0, 1, 2]] * 3000}]}
    with TestClient(create_app(SETTINGS)) as client:
        size = client.post("/v1/scenes", json=sphere).json()["bytes"]
    with TestClient(create_app(replace(SETTINGS, store_bytes=int(2.5 * size)))) as client:
        ids = []
        for dtype in ("float32", "float64", "float32"):
            spec = {**sphere, "dtype": dtype}
            if len(ids) == 2:  # a third, different scene
                spec["objects"] = [{**sphere["objects"][0], "faces": [[0, 2, 1]] * 3000}]
            ids.append(client.post("/v1/scenes", json=spec).json()["id"])
        assert client.get(f"/v1/scenes/{ids[0]}").status_code == 404
        assert client.get(f"/v1/scenes/{ids[2]}").status_code == 200
