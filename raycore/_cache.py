"""Keep Numba's on-disk kernel cache consistent with the sources.

Numba's cache (``cache=True``, stored in ``__pycache__`` beside each module) is keyed by the
decorated function's own file only (a hash of its contents in Numba 0.68, its modification time
before).  A kernel that inlines code from
another module (the traversal inlines every primitive) is therefore reloaded stale after that
other module changes.  At import, raycore hashes its sources and, when they differ from the ones
the cache was built from, drops its cached kernels so that they are compiled afresh.  The test
suite does the same for its own kernels, which inline raycore's (``tests/conftest.py``).
"""

import functools
import hashlib
from pathlib import Path

from numba import config
from numba.core.caching import _CacheLocator

PACKAGE = Path(__file__).resolve().parent
#: The digest of the sources that a folder's cached kernels were compiled from, beside them.
STAMP_NAME = "kernel-sources.sha256"


@functools.cache
def sources_digest():
    """SHA-256 of every module of the package, with its path (read once a process: raycore's
    import and the test suite's ``conftest`` both ask for it)."""
    digest = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        digest.update(str(path.relative_to(PACKAGE)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _kernel_folders(folder):
    """The folders where Numba keeps the kernels of the modules under ``folder``, that of
    ``folder``'s own modules first: each package's ``__pycache__``, or with ``NUMBA_CACHE_DIR``
    set, the package's folder there, named as Numba names it (an older raycore's kernels there
    would otherwise be loaded stale)."""
    packages = sorted({path.parent for path in folder.rglob("*.py")} - {folder})
    if not config.CACHE_DIR:
        return [folder / "__pycache__"] + [package / "__pycache__" for package in packages]
    return [Path(config.CACHE_DIR) / _CacheLocator.get_suitable_cache_subpath(
        str(package / "__init__.py")) for package in [folder, *packages]]


def drop_stale_kernels(folder=PACKAGE):
    """Delete the kernels cached for the modules under ``folder`` (raycore's by default) if
    they were compiled from other raycore sources than these."""
    digest = sources_digest()
    kernel_folders = _kernel_folders(folder)
    stamp = kernel_folders[0] / STAMP_NAME
    try:
        if stamp.read_text() == digest:
            return
    except OSError:
        pass
    try:
        for kernels in kernel_folders:
            for cached in kernels.glob("*.nb[ic]"):
                cached.unlink(missing_ok=True)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest)
    except OSError:
        # a read-only installation: Numba cannot write a cache there either
        pass
