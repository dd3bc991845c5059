"""Fixtures: an app with small limits and no demo scene, and a scene in it."""

import pytest
from fastapi.testclient import TestClient

from service.app import create_app

from .data import SETTINGS, SPEC


@pytest.fixture
def client():
    with TestClient(create_app(SETTINGS)) as test_client:
        yield test_client


@pytest.fixture
def scene_id(client):
    response = client.post("/v1/scenes", json=SPEC)
    assert response.status_code == 201, response.text
    return response.json()["id"]
