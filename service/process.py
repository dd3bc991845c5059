"""Run ``raycore serve`` in a child process on a free loopback port (for tests and benchmarks)."""

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from contextlib import contextmanager
from pathlib import Path


class ServiceFailed(RuntimeError):
    """The child process exited, did not get ready in time, or did not stop cleanly."""


def free_port():
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextmanager
def running_service(environment=None, startup_seconds=600, workers=None):
    """Start the service, wait until /readyz answers 200, yield its base URL, then stop it.

    Parameters
    ----------
    environment : mapping, optional
        Extra environment variables (e.g. ``RAYCORE_MAX_RAYS``).
    startup_seconds : float
        How long to wait for readiness (a fresh process may compile stale kernel caches).
    workers : int, optional
        ``raycore serve --workers``.

    Raises
    ------
    ServiceFailed
        With the process's output, also when it does not stop cleanly.
    """
    with service_process(environment, startup_seconds, workers) as (_, url):
        yield url


@contextmanager
def service_process(environment=None, startup_seconds=600, workers=None, command=None):
    """:func:`running_service`, yielding ``(process, url)``: a test may kill the process
    (``kill -9``); one that is still running at the end is stopped with SIGINT and must exit
    cleanly.  ``command`` is the ``raycore`` command to run (default: the one installed beside
    this interpreter)."""
    port = free_port()
    command = [str(command or Path(sys.executable).with_name("raycore")), "serve", "--host",
               "127.0.0.1", "--port", str(port), "--log-level", "warning"]
    if workers is not None:
        command += ["--workers", str(workers)]
    with tempfile.TemporaryFile() as log:
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                   env={**os.environ, **(environment or {})})

        def failure(reason):
            log.seek(0)
            return ServiceFailed(f"{reason}; its output:\n{log.read().decode(errors='replace')}")

        url = f"http://127.0.0.1:{port}"
        killed = False
        try:
            deadline = time.monotonic() + startup_seconds
            while not _ready(url):
                if process.poll() is not None:
                    raise failure(f"the service exited with {process.returncode}")
                if time.monotonic() > deadline:
                    raise failure(f"the service was not ready after {startup_seconds} s")
                time.sleep(0.2)
            yield process, url
        finally:
            killed = process.poll() == -signal.SIGKILL
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
            try:
                returncode = process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                process.kill()
                returncode = process.wait()
        if returncode != 0 and not killed:
            raise failure(f"the service stopped with {returncode}")


def _ready(url):
    try:
        with urllib.request.urlopen(f"{url}/readyz", timeout=10) as response:
            return response.status == 200
    except urllib.error.HTTPError:  # 503: starting
        return False
    except OSError:  # not listening yet
        return False
