"""Schemathesis against a real ``raycore serve`` (uvicorn on 127.0.0.1), as a user would run it
from the repository root (issue 14): ``schemathesis run <served /openapi.json> --checks all``,
with the repository's schemathesis.toml and hooks, once with no API key configured and once
with one configured and sent.  ``--checks all`` runs every check the installed schemathesis has,
new ones included.  Bounded here (RAYCORE_FUZZ_EXAMPLES cases per operation and phase, 60 by
default, the configuration's); ``make fuzz`` runs it longer."""

import json
import os
import subprocess
import sys
import urllib.request
from collections import Counter
from pathlib import Path

import pytest
from openapi_spec_validator import validate

from service.process import running_service

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = int(os.environ.get("RAYCORE_FUZZ_EXAMPLES", "60"))
KEY = "schemathesis-key"
#: Limits small enough that generated requests reach them, and renders stay quick.
LIMITS = {"RAYCORE_MAX_RAYS": "5000", "RAYCORE_MAX_TRIANGLES": "20000",
          "RAYCORE_MAX_RENDER_PIXELS": "4096", "RAYCORE_STORE_BYTES": str(64 * 2**20)}


def schemathesis_run(url, report_dir, headers=()):
    """Run the schemathesis command from the repository root; its ndjson events, parsed."""
    command = [str(Path(sys.executable).with_name("schemathesis")), "run",
               f"{url}/openapi.json", "--checks", "all", "--max-examples", str(EXAMPLES),
               "--generation-database", "none", "--no-color", "--report", "ndjson",
               "--report-dir", str(report_dir)]
    for header in headers:
        command += ["--header", header]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=900)
    reports = list(Path(report_dir).glob("*.ndjson"))
    assert reports, done.stdout + done.stderr
    events = [json.loads(line) for line in reports[0].read_text().splitlines() if line]
    return done, events


def cases_per_operation(events):
    """Test cases sent to each operation ("METHOD /path"), over all phases, from the events."""
    counts = Counter()
    for event in events:
        recorder = event.get("ScenarioFinished", {}).get("recorder", {})
        for case in recorder.get("cases", {}).values():
            counts[f"{case['value']['method']} {case['value']['path']}"] += 1
    return counts


@pytest.fixture(scope="module")
def warm_kernels():
    """Every kernel compiled into Numba's cache before the service starts: `--checks all`
    includes a 10 s response time limit (ST112), and a request that compiled a kernel took 16-34
    s (2 of 20 runs, after a source change had emptied the cache)."""
    warmup = subprocess.run([str(Path(sys.executable).with_name("raycore")), "warmup"],
                            capture_output=True, text=True, timeout=1200)
    assert warmup.returncode == 0, warmup.stdout + warmup.stderr


@pytest.mark.parametrize("key", [None, KEY], ids=["no-key", "key"])
def test_schemathesis_finds_nothing(key, tmp_path, monkeypatch, warm_kernels):
    monkeypatch.delenv("RAYCORE_API_KEY", raising=False)  # the keyless run has none
    environment = {**LIMITS, **({"RAYCORE_API_KEY": key} if key else {})}
    with running_service(environment) as url:
        done, events = schemathesis_run(url, tmp_path, [f"X-API-Key: {key}"] if key else [])
        with urllib.request.urlopen(f"{url}/openapi.json") as answer:
            document = json.load(answer)
    output = done.stdout[-20000:] + done.stderr[-5000:]
    assert done.returncode == 0, output
    finished = [event["EngineFinished"] for event in events if "EngineFinished" in event]
    assert finished, output
    errors = [event for event in events if "NonFatalError" in event or "FatalError" in event]
    failed = [check["name"] for event in events
              for checks in event.get("ScenarioFinished", {}).get("recorder", {})
              .get("checks", {}).values() for check in checks if check["status"] == "failure"]
    assert not errors and not failed, output
    validate(document)  # the served document is valid OpenAPI (openapi-spec-validator)
    # the document describes this configuration: security exactly when a key is set
    assert ("securitySchemes" in document["components"]) == (key is not None)
    counts = cases_per_operation(events)
    # every operation is tested, and every one that takes an input at least EXAMPLES times (one
    # without, such as /healthz, has a single request to send)
    operations = {f"{method.upper()} {path}": "requestBody" in operation
                  or bool(operation.get("parameters"))
                  for path, item in document["paths"].items() for method, operation in item.items()}
    short = {operation: counts[operation] for operation, varied in operations.items()
             if counts[operation] < (EXAMPLES if varied else 1)}
    assert not short, short
