"""Progress of a command's long work, on stderr.

Shown only on a terminal, and only once the command has worked for about a second, so that
quick runs print nothing; when stderr is not a terminal (a pipe, a file, CI's log) nothing is
printed at all.  The display is rich's (in the ``service`` extra), imported only when shown.
"""

import sys
import threading
from contextlib import contextmanager

#: Seconds of work before the display appears.
DELAY = 1.0


def _ignore(amount=1):
    pass


class Progress:
    """Stages of one command's work: a bar where the stage knows its total, else a spinner.

    Use as a context manager around the whole command, and :meth:`stage` around each part.

    Parameters
    ----------
    stream : file, optional
        Where the display goes; stderr by default.
    terminal : bool, optional
        Whether ``stream`` is a terminal; asked of the stream by default.
    delay : float
        Seconds after entering before the display appears.
    """

    def __init__(self, stream=None, *, terminal=None, delay=DELAY):
        self.stream = sys.stderr if stream is None else stream
        self.enabled = self.stream.isatty() if terminal is None else terminal
        self.delay = delay
        self._display = None
        self._shown = False
        self._timer = None
        # the timer thread shows the display while the command's thread adds and ends stages
        self._lock = threading.Lock()

    def __enter__(self):
        if self.enabled:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                Progress,
                SpinnerColumn,
                TaskProgressColumn,
                TextColumn,
                TimeElapsedColumn,
            )

            self._display = Progress(
                SpinnerColumn(), TextColumn("{task.description}"), BarColumn(),
                TaskProgressColumn(), TimeElapsedColumn(),
                console=Console(file=self.stream, force_terminal=True), transient=True,
                # what the command prints (e.g. the benchmark's lines) goes above the display
                redirect_stdout=True, redirect_stderr=False)
            self._timer = threading.Timer(self.delay, self._show)
            self._timer.daemon = True
            self._timer.start()
        return self

    def __exit__(self, *exc):
        if self._timer is not None:
            self._timer.cancel()
        with self._lock:
            if self._shown:
                self._display.stop()
            self._shown = False
            self._display = None

    def _show(self):
        with self._lock:
            if self._display is not None and not self._shown:
                self._display.start()
                self._shown = True

    @contextmanager
    def stage(self, description, total=None):
        """Show ``description`` while the block runs; yield ``advance(amount=1)``.

        Parameters
        ----------
        description : str
        total : int, optional
            Units of the stage (rays, meshes); a spinner when not given.
        """
        if self._display is None:
            yield _ignore
            return
        task = self._display.add_task(description, total=total)
        try:
            yield lambda amount=1: self._display.advance(task, amount)
        finally:
            self._display.remove_task(task)

