"""The wheel that carries raycore's compiled kernels (``make wheel``, release/ship_kernels.py).

Built by ``python -m build`` and installed with its service extra in a new virtual environment,
with its dependencies from the package index and no Numba cache on the machine for it, a first
answer loads every kernel it needs from the wheel and compiles none: with ``build()`` called
first, and when ``intersect`` builds the scene; and ``raycore serve`` serves the demo scene.
Every kernel in it is keyed on one of raycore's CPU levels, those this machine runs
(x86-64-v4, x86-64-v3), so that another machine of those levels loads it as this one does (only
one machine is at hand).  The wheel here carries the float32 kernels
(the script's and the demo's), compiled by this interpreter."""

import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import httpx
import numpy as np
import pytest

from raycore._compile_notice import MESSAGE
from raycore._target import LEVELS, runnable_levels
from service.process import service_process

SHIP = Path(__file__).resolve().parents[1] / "release" / "ship_kernels.py"

#: A 512-triangle grid in the z = 0 plane, ten rays straight down onto it from z = 5.
SCRIPT = """
import json, sys
import numpy as np
import raycore
from raycore._compile_notice import NOTICE

u, v = np.meshgrid(np.linspace(0, 1, 17), np.linspace(0, 1, 17))
vertices = np.column_stack([u.ravel(), v.ravel(), np.zeros(u.size)])
corner = (np.arange(16)[:, None] * 17 + np.arange(16)).ravel()
faces = np.concatenate([np.column_stack([corner, corner + 1, corner + 18]),
                        np.column_stack([corner, corner + 18, corner + 17])])
scene = raycore.Scene("float32")
scene.add_mesh(vertices, faces)
if sys.argv[1] == "build":
    scene.build()
origins = np.column_stack([np.linspace(0.05, 0.95, 10), np.full(10, 0.3), np.full(10, 5.0)])
hits = scene.intersect(origins.astype(np.float32), np.tile(np.float32([0, 0, -1]), (10, 1)))
print(json.dumps({"t": hits.t.tolist(), "geom_id": hits.geom_id.tolist(),
                  "compiled": NOTICE.compiled, "cpu": raycore.info()["cpu"],
                  "module": raycore.__file__}))
"""


@pytest.fixture(scope="module")
def wheel_environment(tmp_path_factory):
    if not runnable_levels():
        pytest.skip(f"this machine runs none of {LEVELS}, for which the wheel ships kernels")
    folder = tmp_path_factory.mktemp("wheel")
    run = subprocess.run([sys.executable, str(SHIP), "--dest", str(folder / "dist"), "--dtype",
                          "float32", "--install-into", str(folder / "venv")],
                         capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return folder / "venv"


@pytest.fixture(scope="module")
def wheel_file(wheel_environment):
    (wheel,) = (wheel_environment.parent / "dist").glob("raycore-*.whl")
    return wheel


def test_the_wheels_kernels_are_keyed_on_nothing_of_this_machine(wheel_file):
    # Numba loads a cached kernel where its index key's codegen part (target triple, CPU name,
    # CPU features) equals the running process's: here a level's, on any machine of it
    keys = []
    with zipfile.ZipFile(wheel_file) as wheel:
        for name in wheel.namelist():
            if name.endswith(".nbi"):
                with wheel.open(name) as index:
                    pickle.load(index)  # Numba's version
                    _, overloads = pickle.loads(index.read())
                keys += [key[1] for key in overloads]
    assert len(keys) > 50
    assert {codegen[1:] for codegen in keys} == set(runnable_levels())


@pytest.mark.parametrize("how", ["build", "intersect builds"])
def test_a_first_answer_from_the_wheel_compiles_nothing(wheel_environment, how, tmp_path):
    run = subprocess.run([str(wheel_environment / "bin" / "python"), "-c", SCRIPT, how],
                         cwd=tmp_path, env=_user_environment(), capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    answer = json.loads(run.stdout.splitlines()[-1])
    assert answer["module"].startswith(str(wheel_environment))  # the wheel, not the tree
    assert answer["cpu"] == runnable_levels()[0].name
    assert answer["compiled"] == [] and MESSAGE not in run.stderr, run.stderr[-3000:]
    assert np.all(np.array(answer["geom_id"]) == 0)
    np.testing.assert_array_equal(answer["t"], 5.0)  # z = 5 to z = 0: exact in float32


def test_the_wheel_serves_the_demo(wheel_environment):
    command = wheel_environment / "bin" / "raycore"
    with service_process(startup_seconds=120, command=command) as (_, url):
        camera = {"type": "perspective", "position": [7, 5, -9], "look_at": [0, 1, 0],
                  "width": 32, "height": 24}
        response = httpx.post(f"{url}/v1/scenes/demo/render", json={"camera": camera},
                              timeout=60)
    assert response.status_code == 200, response.text
    assert response.content.startswith(b"\x89PNG\r\n\x1a\n")


def _user_environment():
    """This environment without Numba's settings (this process's raycore set its CPU) and
    Python's path: what a user's shell would give the installed wheel."""
    return {key: value for key, value in os.environ.items()
            if not key.startswith(("NUMBA_", "PYTHON"))}
