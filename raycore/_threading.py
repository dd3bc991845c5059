"""Numba's threading layer, chosen when raycore is imported: thread-safe and fork-safe.

Numba runs parallel loops on one of three layers, picked once per process, before the first
parallel kernel is linked:

- ``tbb`` (oneTBB): thread-safe and fork-safe.  ``pip install tbb`` puts ``libtbb`` in the
  environment's ``lib/``, where the dynamic loader does not look, so Numba passes it over
  unless the library is already loaded: :func:`choose_layer` loads it by its path first.
- ``omp`` (GNU OpenMP on Linux): a child forked after a parallel call hangs at its first one,
  and ``fork`` is how ``multiprocessing`` (by default up to Python 3.13), gunicorn with preload
  and Celery's prefork pool make workers.  raycore never chooses it.
- ``workqueue``: fork-safe, but it aborts the process when two threads run parallel loops at
  once.  Where TBB cannot load (PyPI has no tbb wheel for Linux aarch64 or macOS arm64),
  raycore uses it and lets one parallel loop run at a time (:func:`_serialise_launches`), as it
  does where an older libtbb was loaded first under the same name (Open3D's wheel carries one),
  which Numba refuses: raycore then says so.

A layer named in ``NUMBA_THREADING_LAYER`` is the user's choice and is kept.
"""

import ctypes
import os
import sys
import warnings
from importlib import metadata

from numba import config
from numba.np.ufunc import parallel

#: What each layer is safe for, as (thread-safe, fork-safe).  Workqueue's thread safety is
#: raycore's lock around every parallel launch.
SAFETY = {"tbb": (True, True), "workqueue": (True, True), "omp": (True, False)}

_TBB_LIBRARY = {"linux": "libtbb.so.12", "darwin": "libtbb.12.dylib", "win32": "tbb12.dll"}

#: Kept alive for the process: the compiled launcher and the lock it takes.
_serialised = None


def tbb_library_path():
    """Path of the ``libtbb`` that the ``tbb`` distribution installed, or None.

    Found from the distribution's file list, so that a virtual environment, ``pip install
    --user`` and a system-wide installation all work.
    """
    name = _TBB_LIBRARY.get(sys.platform)
    try:
        files = metadata.distribution("tbb").files or []
    except metadata.PackageNotFoundError:
        return None
    for file in files:
        if file.name == name:
            path = file.locate()
            if os.path.exists(path):
                return os.fspath(path)
    return None


def _load_tbb():
    """Load libtbb by its path; True if it loaded.

    Numba then finds it: its version check opens ``libtbb.so.12`` by name, and its ``tbbpool``
    extension needs that name, and the loader answers both with a library already loaded under
    that name.
    """
    path = tbb_library_path()
    if path is None:
        return False
    try:
        ctypes.CDLL(path)
    except OSError:
        return False
    return True


def choose_layer():
    """Start Numba's threads on TBB, else on workqueue with serialised launches.

    Called once, by ``import raycore``.  A layer Numba already started (another library's
    parallel kernel ran first) or the one ``NUMBA_THREADING_LAYER`` names is kept; workqueue
    gets the lock in every case.

    Returns
    -------
    str
        The layer: ``"tbb"``, ``"workqueue"`` or (only when chosen outside raycore) ``"omp"``.
    """
    tbb_loaded = False
    if not parallel._is_initialized:
        chosen = config.THREADING_LAYER
        if chosen == "default":
            tbb_loaded = _load_tbb()
            _start("tbb" if tbb_loaded else "workqueue")
        else:
            if chosen in ("tbb", "safe", "threadsafe", "forksafe"):
                _load_tbb()
            parallel._launch_threads()
    layer = parallel.threading_layer()
    if layer == "workqueue":
        _serialise_launches()
        if tbb_loaded:
            # loaded, yet refused: the loader answers Numba's request for libtbb by name with
            # the library loaded under that name first, and Open3D's wheel carries an older one
            # (interface 12050; Numba asks for 12060, and its warning says only that TBB is off)
            warnings.warn(
                "raycore runs on Numba's workqueue threading layer, one parallel loop at a "
                "time: Numba refused the tbb package's libtbb, most likely because an older "
                "libtbb was loaded first (Open3D's wheel carries one). Import raycore before "
                "open3d to run on TBB.", RuntimeWarning, stacklevel=3)
    elif layer == "omp" and config.THREADING_LAYER != "omp":
        warnings.warn(
            "Numba runs on its OpenMP threading layer, started before raycore was imported: "
            "a process forked after a parallel call hangs at its first one. Import raycore "
            "first, or set NUMBA_THREADING_LAYER=tbb (pip install tbb).",
            RuntimeWarning, stacklevel=3)
    return layer


def _start(layer):
    """Start ``layer``, falling back to workqueue if it cannot load (never to OpenMP)."""
    default = config.THREADING_LAYER
    try:
        config.THREADING_LAYER = layer
        try:
            parallel._launch_threads()
        except ValueError:  # "No threading layer could be loaded"
            config.THREADING_LAYER = "workqueue"
            parallel._launch_threads()
    finally:
        config.THREADING_LAYER = default


def _serialise_launches():
    """Let one parallel loop run at a time on the workqueue layer.

    Numba's compiled kernels start their parallel loops through the symbol
    ``numba_parallel_for``, which they look up when they are linked (compiled or loaded from
    the cache).  It is pointed at a launcher that takes a mutex around workqueue's own, so that
    every parallel kernel of the process linked from now on, raycore's and others', waits for
    the one running rather than abort.  The mutex is native, not Python's: kernels launch with
    the GIL released.  A forked child gets a fresh one, as its holder may be a thread that did
    not survive the fork.

    Nested parallel launches, which workqueue refuses anyway, would wait for ever here
    instead; raycore's kernels do not nest.
    """
    global _serialised
    if _serialised is not None:
        return
    import llvmlite.binding as llvm
    from llvmlite import ir
    from numba.np.ufunc import workqueue

    mutex = _NativeMutex()
    address = ir.IntType(ctypes.sizeof(ctypes.c_void_p) * 8)
    byte_pointer = ir.IntType(8).as_pointer()
    # what Numba's kernels call: (function, args, dimensions, steps, data, inner dimensions,
    # array count, threads), see numba/np/ufunc/parallel.py build_gufunc_kernel
    launch_type = ir.FunctionType(ir.VoidType(), [byte_pointer] * 5 + [address] * 3)
    lock_type = ir.FunctionType(ir.VoidType(), [byte_pointer])
    module = ir.Module("raycore_serialised_parallel_for")
    launcher = ir.Function(module, launch_type, "raycore_serialised_parallel_for")
    builder = ir.IRBuilder(launcher.append_basic_block())

    def function(pointer, kind):
        return builder.inttoptr(ir.Constant(address, pointer), kind.as_pointer())

    mutex_pointer = builder.inttoptr(ir.Constant(address, mutex.address), byte_pointer)
    builder.call(function(mutex.lock, lock_type), [mutex_pointer])
    builder.call(function(workqueue.parallel_for, launch_type), launcher.args)
    builder.call(function(mutex.unlock, lock_type), [mutex_pointer])
    builder.ret_void()

    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    machine = llvm.Target.from_default_triple().create_target_machine()
    engine = llvm.create_mcjit_compiler(llvm.parse_assembly(str(module)), machine)
    engine.finalize_object()
    llvm.add_symbol("numba_parallel_for", engine.get_function_address(launcher.name))
    if sys.platform != "win32":
        os.register_at_fork(after_in_child=mutex.reset)
    _serialised = (engine, mutex)


def _address(function):
    return ctypes.cast(function, ctypes.c_void_p).value


class _NativeMutex:
    """A mutex that compiled code takes and releases: ``lock`` and ``unlock`` are the addresses
    of functions that take ``address``.  A pthread mutex, or a Windows slim reader/writer lock
    (which starts as zeros and needs no reset: Windows does not fork)."""

    def __init__(self):
        if sys.platform == "win32":
            kernel32 = ctypes.WinDLL("kernel32")
            self._memory = ctypes.c_void_p(0)  # SRWLOCK_INIT
            self.lock = _address(kernel32.AcquireSRWLockExclusive)
            self.unlock = _address(kernel32.ReleaseSRWLockExclusive)
        else:
            self._libc = ctypes.CDLL(None)
            self._memory = ctypes.create_string_buffer(128)  # larger than any pthread_mutex_t
            self.lock = _address(self._libc.pthread_mutex_lock)
            self.unlock = _address(self._libc.pthread_mutex_unlock)
            self.reset()
        self.address = ctypes.addressof(self._memory)

    def reset(self):
        """A fresh, unlocked mutex (in a forked child, whose holder may not have survived)."""
        ctypes.memset(self._memory, 0, ctypes.sizeof(self._memory))
        self._libc.pthread_mutex_init(self._memory, None)


def threading_layer():
    """The name of Numba's threading layer (``"tbb"``, ``"workqueue"`` or ``"omp"``)."""
    return parallel.threading_layer()
