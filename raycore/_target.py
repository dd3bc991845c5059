"""The CPU raycore's kernels are compiled for: x86-64-v3 wherever the machine runs it.

Numba compiles for the exact CPU it runs on, and keys its on-disk cache on that CPU's name and
feature list (``CPUCodegen.magic_tuple``): a kernel compiled on one machine is never loaded on
another, even one that runs the same instructions, nor on the same machine under another
hypervisor that hides a feature.  raycore asks Numba for a micro-architecture level instead,
x86-64-v3 (AVX2, FMA, BMI: every x86-64 CPU since Intel's Haswell and AMD's Zen), so that
kernels compiled once load on every such machine: a wheel carries them
(``release/ship_kernels.py``), and a container image built on one machine runs on the others
without compiling.

The kernels' vectors are 256 bits wide (eight float32 boxes a node, four float64 triangles a
block), which AVX2 holds whole.  On the AMD EPYC with AVX2 (a Zen 4 whose AVX-512 the hypervisor
hides), kernels compiled for x86-64-v3 traced float32 random and framed-camera rays as fast as
those compiled for the host (ratios 0.98-1.02, one thread, four alternating processes,
stanford-bunny, nefertiti and fandisk).  On a CPU with AVX-512 the level gives that up; set
``NUMBA_CPU_NAME`` to the machine's own name (``host_cpu`` in ``raycore info``) to compile for
it instead, at the cost of compiling on first use.

The choice is Numba's, for the whole process: made through the environment, so that a later
reload of Numba's configuration (the compiler reloads it whenever a ``NUMBA_*`` variable
changes) and child processes keep it.  It is left alone when the user set ``NUMBA_CPU_NAME`` or
``NUMBA_CPU_FEATURES``, when Numba already compiles for a CPU (a function was jitted before
raycore was imported), and on CPUs below the level or not x86-64: there Numba compiles for the
host, as it does by default.
"""

import os
import platform

from llvmlite import binding as llvm
from numba import config
from numba.core.registry import cpu_target

#: The level's name, as LLVM knows it.
PORTABLE_CPU = "x86-64-v3"
#: Its features, spelled out (LLVM takes them from the name too): Numba reads an empty list as
#: "this machine's", and ``raycore info`` reports the vector sets from this list.
PORTABLE_FEATURES = ("+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+cx16,+cx8,+f16c,+fma,+fxsr,+lzcnt,"
                     "+mmx,+movbe,+popcnt,+sahf,+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3,+xsave")


def host_runs_portable_code():
    """Whether this machine runs code compiled for :data:`PORTABLE_CPU`."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    host = llvm.get_host_cpu_features()
    return all(host.get(feature[1:], False) for feature in PORTABLE_FEATURES.split(","))


def portable_target_applies():
    """Whether this process may compile raycore's kernels for :data:`PORTABLE_CPU` (see the
    module docstring for when it may not)."""
    if "NUMBA_CPU_NAME" in os.environ or "NUMBA_CPU_FEATURES" in os.environ:
        return False
    if "_toplevel_target_context" in cpu_target.__dict__:  # Numba's codegen is set up already
        return False
    return host_runs_portable_code()


def choose_target():
    """Compile for :data:`PORTABLE_CPU` if :func:`portable_target_applies`.

    Called once, by ``import raycore``, before any kernel is declared (declaring one sets up
    Numba's codegen for a CPU) and before the threading layer is chosen (reloading Numba's
    configuration resets settings made outside the environment).
    """
    if portable_target_applies():
        os.environ["NUMBA_CPU_NAME"] = PORTABLE_CPU
        os.environ["NUMBA_CPU_FEATURES"] = PORTABLE_FEATURES
        config.reload_config()
