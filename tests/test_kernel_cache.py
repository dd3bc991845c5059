"""Cached kernels are dropped when raycore's sources change (raycore._cache), in raycore's own
folder and in another one that asks for it (the test suite's, tests/conftest.py), whether Numba
keeps them beside the sources or in ``NUMBA_CACHE_DIR``.  The kernels are real: a fresh
interpreter compiles and caches a function of each module of a package made here."""

import os
import subprocess
import sys

import pytest
from numba import config

from raycore._cache import STAMP_NAME, drop_stale_kernels, sources_digest

KERNEL = "import numba\n\n\n@numba.njit(cache=True)\ndef kernel(x):\n    return x + 1\n"


class Package:
    """A package of two modules with a kernel each, the second in a subpackage, and the folder
    where Numba caches their kernels (``cache_dir``, or the package's when None)."""

    def __init__(self, folder, cache_dir):
        self.folder, self.cache_dir = folder, cache_dir
        self.where = folder if cache_dir is None else cache_dir
        (folder / "sub").mkdir(parents=True)
        for module in (folder / "top.py", folder / "sub" / "deep.py"):
            module.write_text(KERNEL)

    def compile(self):
        environment = {key: value for key, value in os.environ.items()
                       if key != "NUMBA_CACHE_DIR"}
        if self.cache_dir is not None:
            environment["NUMBA_CACHE_DIR"] = str(self.cache_dir)
        code = "import top, sub.deep; top.kernel(1); sub.deep.kernel(1)"
        subprocess.run([sys.executable, "-c", code], cwd=self.folder, env=environment,
                       check=True, timeout=300)

    def kernel_files(self):
        return sorted(self.where.rglob("*.nb[ic]"))


@pytest.fixture(params=[None, "cache"], ids=["beside the sources", "NUMBA_CACHE_DIR"])
def package(request, tmp_path, monkeypatch):
    cache_dir = None if request.param is None else tmp_path / request.param
    monkeypatch.setattr(config, "CACHE_DIR", "" if cache_dir is None else str(cache_dir))
    return Package(tmp_path / "package", cache_dir)


def test_kernels_compiled_from_other_sources_are_dropped(package):
    package.compile()
    assert len(package.kernel_files()) == 4  # an index and its data, for each module
    drop_stale_kernels(package.folder)  # never stamped: they may come from any sources
    assert package.kernel_files() == []
    (stamp,) = package.where.rglob(STAMP_NAME)
    assert stamp.read_text() == sources_digest()


def test_kernels_compiled_from_these_sources_are_kept(package):
    drop_stale_kernels(package.folder)  # stamps the empty cache with these sources
    package.compile()
    drop_stale_kernels(package.folder)
    assert len(package.kernel_files()) == 4
