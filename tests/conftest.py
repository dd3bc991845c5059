"""What the whole test suite shares: a cache of its kernels that follows raycore's sources.

A few test kernels are compiled with Numba's cache and inline raycore's code (the brute-force
reference inlines its triangle tests, the leaf-test comparison its vector test).  Numba keys
their cache on the test file alone, so after a change to raycore they would run the old code:
they are dropped when raycore's sources change, as raycore drops its own.
"""

from pathlib import Path

from raycore._cache import drop_stale_kernels

drop_stale_kernels(Path(__file__).resolve().parent)
