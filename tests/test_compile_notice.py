"""The first kernel compilation in a process says so, once, on stderr; a warm cache says
nothing.  Each run is a fresh interpreter with its own Numba cache directory."""

import os
import subprocess
import sys

from raycore._compile_notice import MESSAGE

#: Offsets spawned ray origins (a small parallel kernel), and counts the functions Numba
#: compiled for it, as the notice itself learns of them.
SCRIPT = """
import numpy as np
from numba.core import event

import raycore

compiled = []


class Count(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__qualname__)

    def on_end(self, ev):
        pass


event.register("numba:compile", Count())
points = np.zeros((4, 3), np.float32)
normals = np.tile(np.float32([0, 0, 1]), (4, 1))
raycore.offset_ray_origin(points, normals, normals)
print(len(compiled))
"""


def run(cache_dir):
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=environment, capture_output=True,
                          text=True, timeout=600, check=True)
    return int(done.stdout.split()[-1]), done.stderr


def test_one_line_while_compiling_none_once_cached(tmp_path):
    compiled, stderr = run(tmp_path)
    assert compiled >= 2  # several functions compiled, one line said so
    assert stderr.count(MESSAGE) == 1, stderr
    compiled, stderr = run(tmp_path)
    assert compiled == 0
    assert MESSAGE not in stderr, stderr
