"""The CPU raycore's kernels are compiled for: a micro-architecture level, x86-64-v4 or v3.

Numba compiles for the exact CPU it runs on, and keys its on-disk cache on that CPU's name and
feature list (``CPUCodegen.magic_tuple``): a kernel compiled on one machine is never loaded on
another, even one that runs the same instructions, nor on the same machine under another
hypervisor that hides a feature.  raycore asks Numba for a micro-architecture level instead, the
best of :data:`LEVELS` that the machine runs: x86-64-v4 (AVX-512 F, BW, CD, DQ and VL: Intel's
server CPUs since Skylake-SP, AMD's since Zen 4) or x86-64-v3 (AVX2, FMA, BMI: every x86-64 CPU
since Intel's Haswell and AMD's Zen).  Kernels compiled once for a level load on every machine
of that level: a wheel carries them for each level its build machine runs
(``release/ship_kernels.py``), and so does a container image (``raycore warmup
--every-level``).

The kernels' vectors are 256 bits wide (eight float32 boxes a node, four float64 triangles a
block), which AVX2 holds whole.  AVX-512's instructions on those vectors, and its 32 vector
registers rather than 16, still make them faster: on a 2-core AMD EPYC (Zen 5), kernels
compiled for x86-64-v4 took 0.88-0.98 of the time of those compiled for x86-64-v3 (random rays
0.88-0.93, framed-camera rays 0.88-0.98; intersect and occluded, float32 and float64,
stanford-bunny, nefertiti and teapot; best of three alternating processes), as fast as those
compiled for the machine's own CPU.  On the AMD EPYC whose hypervisor hides AVX-512, kernels
compiled for x86-64-v3 traced float32 random and framed-camera rays as fast as those compiled
for the host (ratios 0.98-1.02, one thread, four alternating processes, stanford-bunny,
nefertiti and fandisk).

The choice is Numba's, for the whole process: made through the environment, so that a later
reload of Numba's configuration (the compiler reloads it whenever a ``NUMBA_*`` variable
changes) and child processes keep it.  It is left alone when the user set ``NUMBA_CPU_NAME`` or
``NUMBA_CPU_FEATURES`` (to one of the levels, for instance, as ``raycore warmup --every-level``
does for each), when Numba already compiles for a CPU (a function was jitted before raycore
was imported), and on CPUs below the levels or not x86-64: there Numba compiles for the host,
as it does by default.
"""

import os
import platform
from typing import NamedTuple

from llvmlite import binding as llvm
from numba import config
from numba.core.registry import cpu_target


class Level(NamedTuple):
    """A micro-architecture level: its name and features as LLVM knows them (spelled out:
    Numba reads an empty list as "this machine's", and ``raycore info`` reports the vector
    sets from this list)."""

    name: str
    features: str


_V3_FEATURES = ("+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+cx16,+cx8,+f16c,+fma,+fxsr,+lzcnt,+mmx,"
                "+movbe,+popcnt,+sahf,+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3,+xsave")
#: The levels raycore compiles for, best first.
LEVELS = (Level("x86-64-v4", _V3_FEATURES + ",+avx512bw,+avx512cd,+avx512dq,+avx512f,+avx512vl"),
          Level("x86-64-v3", _V3_FEATURES))


def runnable_levels():
    """The :data:`LEVELS` this machine runs, best first (none off x86-64)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return []
    host = llvm.get_host_cpu_features()
    return [level for level in LEVELS
            if all(host.get(feature[1:], False) for feature in level.features.split(","))]


def compiled_features():
    """Names of the CPU features the kernels are compiled with, as LLVM spells them
    (``avx2``, ``avx512vl``, ...): ``NUMBA_CPU_FEATURES``'s (a level's, where raycore chose
    one), else this machine's, which Numba then compiles for."""
    if config.CPU_FEATURES is not None:  # e.g. "+avx2,+fma,-avx512f"
        return {f[1:] for f in config.CPU_FEATURES.split(",") if f.startswith("+")}
    return {name for name, on in llvm.get_host_cpu_features().items() if on}


#: Numba's settings of the CPU it compiles for.
CPU_SETTINGS = ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")


def level_settings(level):
    """The environment (:data:`CPU_SETTINGS`) that makes Numba compile for ``level``."""
    return dict(zip(CPU_SETTINGS, level, strict=True))


def chosen_level():
    """The level this process should compile for: the best this machine runs, or None when
    the user or Numba chose already (see the module docstring), or it runs none."""
    if any(name in os.environ for name in CPU_SETTINGS):
        return None
    if "_toplevel_target_context" in cpu_target.__dict__:  # Numba's codegen is set up already
        return None
    levels = runnable_levels()
    return levels[0] if levels else None


def choose_target():
    """Compile for :func:`chosen_level`, if any.

    Called once, by ``import raycore``, before any kernel is declared (declaring one sets up
    Numba's codegen for a CPU) and before the threading layer is chosen (reloading Numba's
    configuration resets settings made outside the environment).
    """
    level = chosen_level()
    if level is not None:
        os.environ.update(level_settings(level))
        config.reload_config()
