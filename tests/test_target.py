"""The CPU raycore's kernels are compiled for (raycore._target): the portable x86-64-v3 level
where the machine runs it, unless the user or an earlier use of Numba chose already.  Each case
is a fresh interpreter, without the NUMBA_CPU_* variables that this process's raycore set."""

import json
import os
import subprocess
import sys

from llvmlite import binding as llvm

from raycore._target import PORTABLE_CPU, host_runs_portable_code

REPORT = "import json, raycore; print(json.dumps(raycore.info()))"
#: A function jitted and called before raycore is imported: Numba then compiles for the host.
NUMBA_FIRST = """
import numba
numba.njit(lambda x: x + 1)(1)
""" + REPORT


def report(code, **settings):
    environment = {key: value for key, value in os.environ.items()
                   if key not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    run = subprocess.run([sys.executable, "-c", code], env={**environment, **settings},
                         capture_output=True, text=True, timeout=300, check=True)
    return json.loads(run.stdout.splitlines()[-1])


def test_the_portable_level_where_the_machine_runs_it():
    info = report(REPORT)
    assert info["host_cpu"] == llvm.get_host_cpu_name()
    if host_runs_portable_code():
        assert info["cpu"] == PORTABLE_CPU
        assert {"avx2", "fma", "sse4.2"} <= set(info["simd"])
        assert not any(name.startswith("avx512") for name in info["simd"])
    else:
        assert info["cpu"] == info["host_cpu"]


def test_numba_set_up_before_raycore_keeps_the_host():
    info = report(NUMBA_FIRST)
    assert info["cpu"] == info["host_cpu"]


def test_the_users_choice_is_kept():
    info = report(REPORT, NUMBA_CPU_NAME="haswell")
    assert info["cpu"] == "haswell"
