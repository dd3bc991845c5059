"""The data directory across real ``raycore serve`` processes: kill -9 after and during an
upload, a restart, and two workers (``--workers 2``) answering fresh connections."""

import io
import socket
import threading
import time
from pathlib import Path
from urllib.parse import urlparse

import httpx
import numpy as np
import pytest

from service.process import service_process

from .data import rays

BUNNY = Path(__file__).resolve().parents[3] / "shared" / "meshes" / "stanford-bunny.obj"


@pytest.fixture(scope="module")
def bunny_bytes():
    if not BUNNY.exists():
        pytest.skip(f"{BUNNY} is not there (the shared/ folder beside the repository)")
    return BUNNY.read_bytes()


def environment(directory):
    return {"RAYCORE_DATA_DIR": str(directory), "RAYCORE_DEMO": "false"}


def upload(url, data):
    answer = httpx.post(f"{url}/v1/meshes", content=data, timeout=120,
                        headers={"content-type": "model/obj"})
    assert answer.status_code in (200, 201), answer.text
    return answer


def spec_of(mesh_id):
    return {"objects": [{"type": "mesh", "mesh": mesh_id},
                        {"type": "sphere", "center": [0.0, 0.1, 0.3], "radius": 0.2}]}


def npy_answer(url, scene_id, fresh=False):
    """The .npy answer to camera-like rays at the bunny (a fresh connection each call)."""
    origins, directions = rays(4000, seed=3)
    buffer = io.BytesIO()
    np.save(buffer, np.hstack([origins * 0.1 + [0.0, 0.1, -0.5], directions]))
    with httpx.Client(timeout=120) as client:
        answer = client.post(f"{url}/v1/scenes/{scene_id}/intersect", content=buffer.getvalue(),
                             headers={"content-type": "application/x-npy",
                                      "accept": "application/x-npy"})
    assert answer.status_code == 200, answer.text
    return answer.content


def test_kill_9_after_and_during_uploads_loses_nothing_acknowledged(tmp_path, bunny_bytes):
    with service_process(environment(tmp_path)) as (process, url):
        mesh = upload(url, bunny_bytes).json()
        created = httpx.post(f"{url}/v1/scenes", json=spec_of(mesh["id"]), timeout=120)
        assert created.status_code == 201
        scene_id = created.json()["id"]
        before = npy_answer(url, scene_id)
        hits = np.load(io.BytesIO(before))
        assert {-1, 0, 1} <= set(hits["geom_id"].tolist())
        # during an upload: half of a body (another mesh's) has arrived when the process dies
        other = bunny_bytes.replace(b"v ", b"v  ", 1)
        address = urlparse(url)
        with socket.create_connection((address.hostname, address.port)) as stream:
            stream.sendall(b"POST /v1/meshes HTTP/1.1\r\nHost: x\r\nContent-Type: model/obj\r\n"
                           + f"Content-Length: {len(other)}\r\n\r\n".encode()
                           + other[:len(other) // 2])
            time.sleep(0.2)
            process.kill()
            process.wait()
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == sorted(
        [f"{mesh['id']}.rcf", f"{scene_id}.rcf"])

    with service_process(environment(tmp_path)) as (process, url):
        assert npy_answer(url, scene_id) == before  # answers identically, nothing re-uploaded
        assert httpx.get(f"{url}/v1/meshes/{mesh['id']}").json() == mesh
        again = httpx.post(f"{url}/v1/scenes", json=spec_of(mesh["id"]), timeout=120)
        assert again.status_code == 200 and again.json() == created.json()
        # kill -9 while an upload is being parsed and stored: whatever the moment, the
        # restarted service answers 200 or 404 for it, never a 5xx, and takes it again
        sender = threading.Thread(target=lambda: _post_ignoring_errors(url, other))
        sender.start()
        time.sleep(0.5)
        process.kill()
        process.wait()
        sender.join()

    with service_process(environment(tmp_path)) as (_, url):
        listed = httpx.get(f"{url}/v1/meshes").json()
        for item in listed["items"]:
            assert httpx.get(f"{url}/v1/meshes/{item['id']}").status_code == 200
        assert upload(url, other).status_code in (200, 201)
        assert npy_answer(url, scene_id) == before


def _post_ignoring_errors(url, data):
    try:
        httpx.post(f"{url}/v1/meshes", content=data, timeout=120,
                   headers={"content-type": "model/obj"})
    except httpx.HTTPError:
        pass  # the service was killed under it


def test_two_workers_answer_every_fresh_connection(tmp_path, bunny_bytes):
    with service_process(environment(tmp_path), workers=2) as (_, url):
        mesh_id = upload(url, bunny_bytes).json()["id"]
        created = httpx.post(f"{url}/v1/scenes", json=spec_of(mesh_id), timeout=120)
        assert created.status_code == 201
        scene_id = created.json()["id"]
        first = npy_answer(url, scene_id)
        statuses = []
        for _ in range(30):
            with httpx.Client(timeout=120) as client:  # a new connection: either worker
                statuses.append(client.get(f"{url}/v1/scenes/{scene_id}").status_code)
            assert npy_answer(url, scene_id) == first
        assert statuses == [200] * 30
