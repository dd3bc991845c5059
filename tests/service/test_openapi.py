"""The committed OpenAPI document matches the app, and documents everything with examples."""

import json
from pathlib import Path

import pytest
from openapi_spec_validator import validate

from raycore.cli import main
from service.app import create_app
from service.config import Settings

COMMITTED = Path(__file__).resolve().parents[2] / "openapi" / "openapi.json"


@pytest.fixture(scope="module")
def document():
    return create_app(Settings(demo=False)).openapi()


def test_committed_document_matches_the_app(document):
    committed = json.loads(COMMITTED.read_text())
    assert committed == document, "openapi/openapi.json is stale: run `make openapi`"


def test_committed_document_is_valid_openapi():
    # raises OpenAPIValidationError, naming what is wrong (the served documents: see
    # test_schemathesis.py, which validates them in both configurations)
    validate(json.loads(COMMITTED.read_text()))


def test_cli_writes_the_document(tmp_path, document):
    main(["openapi", "--output", str(tmp_path / "openapi.json")])
    assert json.loads((tmp_path / "openapi.json").read_text()) == document


def _has_example(media, document):
    if "example" in media or "examples" in media:
        return True
    schema = media.get("schema", {})
    if "$ref" in schema:
        schema = document["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    return "examples" in schema or "example" in schema


def test_every_request_and_response_has_an_example(document):
    operations = [(path, method, operation) for path, item in document["paths"].items()
                  for method, operation in item.items()]
    assert len(operations) == 12
    missing = []
    for path, method, operation in operations:
        bodies = {"request": operation.get("requestBody", {})}
        bodies.update(operation["responses"])
        for name, body in bodies.items():
            for media_type, media in body.get("content", {}).items():
                if not _has_example(media, document):
                    missing.append(f"{method.upper()} {path} {name} {media_type}")
        if method in ("post", "get", "delete"):
            assert "summary" in operation, f"{method} {path}"
    assert not missing


def test_error_responses_use_the_error_body(document):
    for item in document["paths"].values():
        for operation in item.values():
            for status, response in operation["responses"].items():
                if status.startswith("4"):
                    schema = response["content"]["application/json"]["schema"]
                    assert schema == {"$ref": "#/components/schemas/Error"}, status
