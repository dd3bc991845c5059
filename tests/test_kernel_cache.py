"""Cached kernels are dropped when raycore's sources change (raycore._cache), in raycore's own
folder and in another one that asks for it (the test suite's, tests/conftest.py)."""

from raycore._cache import STAMP_NAME, drop_stale_kernels, sources_digest


def _cached_kernel(folder):
    cache = folder / "module" / "__pycache__"
    cache.mkdir(parents=True, exist_ok=True)
    index = cache / "module.kernel-1.py311.nbi"
    index.write_bytes(b"index")
    return index


def test_kernels_compiled_from_other_sources_are_dropped(tmp_path):
    stamp = tmp_path / "__pycache__" / STAMP_NAME
    stamp.parent.mkdir()
    stamp.write_text("the digest of older sources")
    index = _cached_kernel(tmp_path)
    drop_stale_kernels(tmp_path)
    assert not index.exists()
    assert stamp.read_text() == sources_digest()


def test_kernels_compiled_from_these_sources_are_kept(tmp_path):
    drop_stale_kernels(tmp_path)  # a folder never stamped: its cache, if any, is dropped
    index = _cached_kernel(tmp_path)
    drop_stale_kernels(tmp_path)
    assert index.exists()
