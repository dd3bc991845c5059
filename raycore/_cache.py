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


def drop_stale_kernels(folder=PACKAGE):
    """Delete the kernels cached under ``folder`` (raycore's by default) if they were compiled
    from other raycore sources than these."""
    digest = sources_digest()
    stamp = folder / "__pycache__" / STAMP_NAME
    try:
        if stamp.read_text() == digest:
            return
    except OSError:
        pass
    try:
        for cached in folder.rglob("__pycache__/*.nb[ic]"):
            cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:
        # a read-only installation: Numba cannot write a cache there either
        pass
