"""The CPU raycore's kernels are compiled for (raycore._target): the best level the machine
runs, x86-64-v4 or x86-64-v3, unless the user or an earlier use of Numba chose already.  Each case
is a fresh interpreter, without the NUMBA_CPU_* variables that this process's raycore set."""

import json
import os
import subprocess
import sys

from llvmlite import binding as llvm

from raycore._target import LEVELS, runnable_levels

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


def test_the_best_level_the_machine_runs():
    info = report(REPORT)
    assert info["host_cpu"] == llvm.get_host_cpu_name()
    levels = runnable_levels()
    if not levels:
        assert info["cpu"] == info["host_cpu"]
        return
    assert info["cpu"] == levels[0].name
    assert {"avx2", "fma", "sse4.2"} <= set(info["simd"])
    # AVX-512 where the machine has it (x86-64-v4), none where it has not (x86-64-v3)
    avx512 = {name for name in info["simd"] if name.startswith("avx512")}
    if levels[0] == LEVELS[0]:
        assert avx512 == {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"}
    else:
        assert not avx512


def test_each_level_when_asked_for():
    for level in runnable_levels():
        info = report(REPORT, NUMBA_CPU_NAME=level.name, NUMBA_CPU_FEATURES=level.features)
        assert info["cpu"] == level.name
        assert {f"+{name}" for name in info["simd"]} <= set(level.features.split(","))


def test_numba_set_up_before_raycore_keeps_the_host():
    info = report(NUMBA_FIRST)
    assert info["cpu"] == info["host_cpu"]


def test_the_users_choice_is_kept():
    info = report(REPORT, NUMBA_CPU_NAME="haswell")
    assert info["cpu"] == "haswell"
