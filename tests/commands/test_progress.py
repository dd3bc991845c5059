"""The progress display: on a terminal once work has run a while, never elsewhere."""

import io
import time

from raycore.commands.progress import Progress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _wait_for(condition, seconds=30):
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)
    return condition()


def test_a_terminal_shows_stages_once_work_has_run_a_while():
    terminal = _Terminal()
    with Progress(terminal, delay=0) as progress:
        assert _wait_for(lambda: progress._shown)
        with progress.stage("casting 1,000 rays", total=1000) as advance:
            advance(500)
            assert _wait_for(lambda: "casting 1,000 rays" in terminal.getvalue())
            assert _wait_for(lambda: "50%" in terminal.getvalue())
        with progress.stage("building the BVH"):  # no total: a spinner
            assert _wait_for(lambda: "building the BVH" in terminal.getvalue())


def test_quick_work_shows_nothing_on_a_terminal():
    terminal = _Terminal()
    with Progress(terminal, delay=600) as progress:
        with progress.stage("loading", total=3) as advance:
            advance(3)
    assert terminal.getvalue() == ""


def test_not_a_terminal_shows_nothing():
    stream = io.StringIO()
    with Progress(stream, delay=0) as progress:
        assert not progress.enabled
        with progress.stage("casting", total=10) as advance:
            advance(10)
    assert stream.getvalue() == ""
