"""``raycore.info()`` and ``raycore info``: what the library runs on."""

import json
import os
import subprocess
import sys
from pathlib import Path

from llvmlite import binding as llvm

import raycore
from raycore._threading import tbb_library_path
from raycore.cli import main


def test_info_names_the_layer_threads_cpu_and_cache():
    report = raycore.info()
    assert report["threading_layer"] in ("tbb", "workqueue")
    assert report["thread_safe"] and report["fork_safe"]
    assert isinstance(report["threads"], int) and report["threads"] >= 1
    features = {name for name, on in llvm.get_host_cpu_features().items() if on}
    assert set(report["simd"]) <= features and "sse2" in report["simd"]  # every x86-64 has it
    assert Path(report["numba_cache_dir"]).is_dir()


def test_tbb_is_found_where_pip_puts_it():
    path = tbb_library_path()
    if path is None:  # no tbb wheel for this platform: workqueue, serialised
        assert raycore.info()["threading_layer"] == "workqueue"
    else:
        assert Path(path).name.startswith(("libtbb", "tbb12")) and Path(path).is_file()


def test_the_cpu_numba_is_told_to_compile_for():
    code = "import json, raycore; print(json.dumps(raycore.info()))"
    environment = {**os.environ, "NUMBA_CPU_NAME": "haswell",
                   "NUMBA_CPU_FEATURES": "+avx2,+fma,+sse4.2,-avx512f,+popcnt"}
    run = subprocess.run([sys.executable, "-c", code], env=environment, capture_output=True,
                         text=True, timeout=300, check=True)
    report = json.loads(run.stdout)
    assert report["cpu"] == "haswell" and report["simd"] == ["avx2", "fma", "sse4.2"]


def test_cli_info(capsys):
    main(["info"])
    lines = capsys.readouterr().out.splitlines()
    report = raycore.info()
    assert lines[0].split()[:3] == ["threading", "layer", report["threading_layer"]]
    assert "thread-safe, fork-safe" in lines[0]
    assert lines[1].split() == ["threads", str(report["threads"])]
    main(["info", "--json"])
    assert json.loads(capsys.readouterr().out) == report
