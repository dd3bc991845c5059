"""``raycore warmup`` compiles what the public calls reach: the service, driven with every kind of
request (docker/check_warm_cache.py), reaches no kernel signature beyond it."""

import subprocess
import sys
from pathlib import Path

import pytest

from raycore._compile_notice import NOTICE
from raycore.cli import main
from tests.commands.conftest import refused

CHECK = Path(__file__).resolve().parents[1] / "docker" / "check_warm_cache.py"


def test_the_service_needs_no_kernel_that_warmup_leaves_out():
    # a fresh interpreter: only what the warm-up and the requests load counts
    run = subprocess.run([sys.executable, str(CHECK), "--after-warmup"], capture_output=True,
                         text=True, timeout=1800)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert "reached no kernel signature beyond the warm-up's" in run.stdout


def test_cli_warmup_one_dtype(capsys):
    main(["warmup", "--dtype", "float32"])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("raycore warmup: float32 kernels ready in ")
    assert lines[-1].startswith("raycore warmup: done in ") and len(lines) == 2


def test_cli_warmup_refuses_an_unknown_dtype(capsys):
    with pytest.raises(SystemExit):
        main(["warmup", "--dtype", "float16"])
    assert "invalid choice: 'float16'" in capsys.readouterr().err


def test_cli_warmup_expect_cached_fails_naming_a_compiled_kernel(monkeypatch, capsys):
    # what a fresh process that found a kernel missing from the cache would have recorded
    monkeypatch.setattr(NOTICE, "compiled", ["raycore.bvh.traverse.trace_range"])
    status, err = refused(["warmup", "--dtype", "float32", "--expect-cached"], capsys)
    assert status == 1
    assert err == ("raycore warmup: 1 functions were compiled, not loaded from the cache, the "
                   "first raycore.bvh.traverse.trace_range")
    monkeypatch.setattr(NOTICE, "compiled", [])
    main(["warmup", "--dtype", "float32", "--expect-cached"])
    assert capsys.readouterr().out.splitlines()[-1].startswith("raycore warmup: done in ")
