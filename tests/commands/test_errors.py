"""Bad input to the ``raycore`` command, run as a user runs it: one line on stderr, a non-zero
exit status, never a traceback; and nothing on stderr when all goes well and stderr is not a
terminal (no progress display)."""

import subprocess
import sys
from pathlib import Path

import numpy as np

from raycore._compile_notice import MESSAGE as COMPILE_NOTICE
from tests.commands.conftest import mesh_file

RAYCORE = str(Path(sys.executable).with_name("raycore"))


def _run_all(commands):
    """Run the commands at once (each pays for Python's and Numba's imports); their results."""
    processes = [subprocess.Popen([RAYCORE, *map(str, argv)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for argv in commands]
    results = []
    for process in processes:
        out, err = process.communicate(timeout=600)
        # a fresh cache compiles the kernels of the successful run, and says so
        lines = [line for line in err.splitlines() if line != COMPILE_NOTICE]
        results.append((process.returncode, out, lines))
    return results


def test_bad_input_is_one_line_and_good_input_is_quiet(tmp_path):
    suzanne = mesh_file("suzanne")
    (tmp_path / "garbage.obj").write_bytes(b"\x00\x01 not a mesh \xff" * 50)
    np.save(tmp_path / "rays5.npy", np.zeros((4, 5)))
    cases = {
        "missing file": (["render", tmp_path / "gone.obj", "-o", tmp_path / "x.png"],
                         f"raycore render: {tmp_path / 'gone.obj'}: no such file"),
        "unreadable mesh": (["render", tmp_path / "garbage.obj", "-o", tmp_path / "x.png"],
                            f"raycore render: {tmp_path / 'garbage.obj'}: "),
        "bad .npy shape": (["cast", suzanne, tmp_path / "rays5.npy", "-o", tmp_path / "h.npy"],
                           f"raycore cast: {tmp_path / 'rays5.npy'}: the .npy rays must have "
                           "shape (N, 6) or (N, 8), got (4, 5)"),
        "bad option value": (["render", suzanne, "-o", tmp_path / "x.png", "--camera",
                              "fisheye"], "raycore render: error: argument --camera: invalid "
                                          "choice: 'fisheye'"),
    }
    good = ["render", suzanne, "-o", tmp_path / "good.png", "--width", "40", "--height", "30"]
    *results, (good_code, good_out, good_err) = _run_all(
        [argv for argv, _ in cases.values()] + [good])
    for (name, (_, expected)), (code, out, err) in zip(cases.items(), results, strict=True):
        assert code != 0, name
        assert len(err) == 1, (name, err)
        assert err[0].startswith(expected), (name, err)
        assert "Traceback" not in err[0] and out == "", name
    assert code == 2  # argparse's status for the command line's own syntax
    assert (good_code, good_out, good_err) == (0, "", [])
    assert (tmp_path / "good.png").read_bytes().startswith(b"\x89PNG")
