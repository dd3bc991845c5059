"""Fuzzing from the OpenAPI document with schemathesis (issue 7): every operation, with the API
key configured and sent, answered without a server error and as documented (status, content
type, body schema, headers).  Bounded here; ``make fuzz`` runs longer (RAYCORE_FUZZ_EXAMPLES)."""

import dataclasses
import os
import zlib

import jsonschema_rs
import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    status_code_conformance,
)

from service.app import create_app
from service.store import Store

from .data import SETTINGS, SPEC

EXAMPLES = int(os.environ.get("RAYCORE_FUZZ_EXAMPLES", "25"))
KEY = "fuzz-key"

APP = create_app(dataclasses.replace(SETTINGS, api_key=KEY))
DOCUMENT = APP.openapi()
schema = schemathesis.openapi.from_asgi("/openapi.json", APP)


def documented_body(ctx, response, case):
    """A JSON answer conforms to the schema documented for its status.

    In place of schemathesis's response_schema_conformance, which (4.x) rewrites the
    ``prefixItems`` of tuples inside ``anyOf`` into a draft-4 ``items`` list and then fails to
    build a 2020-12 validator from it.
    """
    if not response.headers.get("content-type", [""])[0].startswith("application/json"):
        return None
    operation = DOCUMENT["paths"][case.operation.path].get(case.method.lower(), {})
    documented = operation.get("responses", {}).get(str(response.status_code))
    media = (documented or {}).get("content", {}).get("application/json")
    if media is None or "schema" not in media:
        return None
    validator = jsonschema_rs.Draft202012Validator(
        {**media["schema"], "components": DOCUMENT["components"]})
    errors = [error.message for error in validator.iter_errors(response.json())]
    assert not errors, f"{case.method} {case.path} {response.status_code}: {errors[:3]}"
    return True


# not ignored_auth: it takes the key set below for a generated one (tests/service/test_auth.py
# checks the key); not positive_data_acceptance: a body schema of "binary" cannot say what a
# valid mesh file or .npy array is
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance,
          response_headers_conformance, documented_body]


@schemathesis.serializer("application/x-npy", "model/obj", "model/stl", "model/ply",
                         "model/off", "model/gltf-binary")
def _binary(ctx, value):
    """Bodies documented as binary strings: bytes as they are, anything else as its text."""
    if value is None:
        return None
    return value if isinstance(value, bytes) else str(value).encode()


@pytest.fixture(scope="module")
def scene():
    """A built scene, so that queries and renders reach the geometry, not only a 404."""
    with TestClient(APP) as client:
        response = client.post("/v1/scenes", json=SPEC, headers={"x-api-key": KEY})
        assert response.status_code in (200, 201), response.text
        yield client, response.json()["id"]


@schema.parametrize()
@settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
def test_operation(scene, case):
    client, scene_id = scene
    # most queries and renders at the built scene, some at whatever id was generated (a 404)
    if case.path.endswith(("/intersect", "/render")) and zlib.crc32(repr(case.body).encode()) % 5:
        case.path_parameters["scene_id"] = scene_id
    if case.operation.security or case.method in ("POST", "DELETE"):
        case.headers = {**(case.headers or {}), "X-API-Key": KEY}
    case.call_and_validate(session=client, checks=CHECKS)


WORKFLOW_APP = create_app(dataclasses.replace(SETTINGS, api_key=KEY))


class Workflows(schemathesis.openapi.from_asgi("/openapi.json", WORKFLOW_APP).as_state_machine()):
    """Sequences that follow the documented links: upload a mesh, build scenes of it, describe,
    query, render and delete them, each answer checked as above."""

    def setup(self):
        # each scenario from an empty store: the same draws give the same answers (201, not a
        # 200 for what an earlier scenario stored), as Hypothesis needs to replay and shrink
        runtime = WORKFLOW_APP.state.runtime
        runtime.store = Store(runtime.settings.store_bytes)

    def get_call_kwargs(self, case):
        return {"headers": {"X-API-Key": KEY}}

    def validate_response(self, response, case, additional_checks=None, **kwargs):
        case.validate_response(response, checks=CHECKS)


TestWorkflows = Workflows.TestCase
TestWorkflows.settings = settings(max_examples=max(EXAMPLES // 5, 3), stateful_step_count=6,
                                  deadline=None, derandomize=True,
                                  suppress_health_check=list(HealthCheck))
