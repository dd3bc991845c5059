"""One line on stderr when raycore's kernels start compiling in this process.

Numba compiles a kernel at its first call with new argument types, unless its on-disk cache
holds it; the first calls after installing raycore (or on a new kind of CPU) therefore wait
while it compiles.  Numba broadcasts a ``numba:compile`` event only when it compiles, not when
it loads a kernel from its cache, so a warm cache shows nothing.  The line goes to stderr, which
Python shows by default, as do notebooks (where logging's INFO level is hidden).
"""

import sys

from numba.core import event

MESSAGE = ("raycore: compiling kernels for this CPU, once (about half a minute for a first "
           "answer; later runs load them from Numba's cache, and `raycore warmup` compiles "
           "them all ahead of use)")


class CompileNotice(event.Listener):
    """Prints :data:`MESSAGE` at the first compilation of a raycore kernel, then nothing.

    Attributes
    ----------
    compiled : list of str
        Each function compiled in this process since ``import raycore`` (``module.qualname``),
        in order: raycore's kernels, and what Numba compiles for them outside raycore's modules
        (such as a structref's constructor called from Python, which Numba does not cache).
    """

    def __init__(self, stream=None):
        self.stream = stream
        self.shown = False
        self.compiled = []

    def on_start(self, ev):
        # Numba compiles under its global compiler lock: no two threads get here at once.
        # Functions Numba makes itself (overload implementations) may have no module.
        function = ev.data["dispatcher"].py_func
        module = function.__module__ or ""
        self.compiled.append(f"{module}.{function.__qualname__}")
        if module.startswith("raycore.") and not self.shown:
            self.shown = True
            print(MESSAGE, file=self.stream or sys.stderr, flush=True)

    def on_end(self, ev):
        pass


#: The process's notice, listening from ``import raycore`` on.
NOTICE = CompileNotice()


def announce_compiles():
    """Listen for raycore's compilations in this process (once, at import)."""
    event.register("numba:compile", NOTICE)
