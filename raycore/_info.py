"""What raycore runs on: :func:`info`, and ``raycore info`` on the command line."""

import numba
from llvmlite import binding as llvm
from numba import config
from numba.core.caching import FunctionCache

from raycore import _threading
from raycore._target import compiled_features

#: Feature names of vector instruction sets, as LLVM spells them (x86, Arm, POWER).
_SIMD_PREFIXES = ("sse", "ssse", "avx", "fma", "f16c", "neon", "sve", "altivec", "vsx")


def info():
    """Describe the threading layer, threads, CPU and kernel cache that raycore uses.

    Returns
    -------
    dict
        ``threading_layer`` : str
            Numba's layer: ``"tbb"``, or ``"workqueue"`` where TBB cannot load (one parallel
            kernel at a time), or ``"omp"`` only when chosen outside raycore.
        ``thread_safe``, ``fork_safe`` : bool
            Whether threads may query at once, and whether a forked child may query after its
            parent did.
        ``threads`` : int
            Threads each parallel kernel runs on (``NUMBA_NUM_THREADS``, or
            ``numba.set_num_threads`` in this thread).
        ``cpu`` : str
            The CPU the kernels are compiled for: ``NUMBA_CPU_NAME``, which raycore sets to
            the best level the machine runs, x86-64-v4 or x86-64-v3, where it can
            (:mod:`raycore._target`), else this machine's.
        ``host_cpu`` : str
            This machine's CPU, as LLVM names it.
        ``simd`` : list of str
            Its vector instruction sets, as LLVM names them (``avx2``, ``avx512f``, ...).
        ``numba_cache_dir`` : str
            Where Numba keeps the compiled kernels of raycore's top-level modules; those of its
            subpackages sit beside it (under ``NUMBA_CACHE_DIR``, or in each package's
            ``__pycache__``).
        ``numba`` : str
            Numba's version.
    """
    layer = _threading.threading_layer()
    thread_safe, fork_safe = _threading.SAFETY[layer]
    return {
        "threading_layer": layer,
        "thread_safe": thread_safe,
        "fork_safe": fork_safe,
        "threads": numba.get_num_threads(),
        "cpu": config.CPU_NAME or llvm.get_host_cpu_name(),
        "host_cpu": llvm.get_host_cpu_name(),
        "simd": simd_features(),
        "numba_cache_dir": FunctionCache(info).cache_path,
        "numba": numba.__version__,
    }


def simd_features():
    """Sorted names of the vector instruction sets the kernels are compiled with."""
    return sorted(name for name in compiled_features() if name.startswith(_SIMD_PREFIXES))
