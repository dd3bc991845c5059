"""Put raycore's compiled kernels into its wheel (``make wheel``).

Installed from a plain wheel, raycore compiles its kernels at their first use: half a minute
before a first answer, two minutes for ``raycore warmup``.  A wheel from this script carries
them, and a first answer after ``pip install`` loads them instead (README, "Install").

Numba keys a cached kernel on the Python version, Numba's version, the contents of the source
file, the argument types and the CPU it was compiled for (raycore's kernels are compiled for a
micro-architecture level, x86-64-v4 or x86-64-v3: :mod:`raycore._target`).  The kernels are
made here for every level this machine runs, and are therefore loaded on any machine of those
levels that runs the same Python and Numba versions; elsewhere Numba passes them over and
compiles at first use, as without them.

For each interpreter given (each with raycore's dependencies installed, as a project virtual
environment has them):

1. the wheel is unpacked into a temporary folder;
2. ``raycore warmup --every-level`` runs on the unpacked package in fresh processes, which
   write the kernels into the package's ``__pycache__`` folders (``NUMBA_CACHE_DIR`` and
   ``NUMBA_CPU_*`` removed from their environment, so that they land there, for each level);
3. ``raycore warmup --every-level --expect-cached`` runs in others, and fails if any kernel
   compiles rather than loads.

Then the wheel is packed again with the kernels (``wheel pack``, which writes its RECORD), in
place of the plain one.  Usage (``--install-into`` tries it as a user would: a new virtual
environment with the wheel and its service extra installed, the dependencies from the package
index)::

    python release/ship_kernels.py [--dest dist] [--dtype both] \\
        [--python .venv/bin/python .venv-py313/bin/python] [--install-into DIR]

Numba stamps a source file by its contents from version 0.68 on; earlier versions stamp its
modification time, which an installation does not keep, and would pass the kernels over.
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]

#: What the kernels of one folder are: Numba's index and data files, and raycore's stamp of
#: the sources they were compiled from (raycore._cache).
KERNEL_FILES = ("*.nbi", "*.nbc", "kernel-sources.sha256")
#: Settings left out of every step's environment: they would put the kernels elsewhere, compile
#: them for another CPU, or show pip another raycore (a checkout on PYTHONPATH, whose metadata
#: says raycore is installed already).
DROPPED_SETTINGS = ("NUMBA_CACHE_DIR", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "PYTHONPATH")


def _run(command, cwd, **settings):
    """Run ``command`` in ``cwd``, in this environment less DROPPED_SETTINGS, plus
    ``settings``."""
    env = {key: value for key, value in os.environ.items() if key not in DROPPED_SETTINGS}
    print("+", " ".join(map(str, command)), flush=True)
    subprocess.run(command, cwd=cwd, env={**env, **settings}, check=True)


def compile_into(package_root, python, dtype):
    """Compile raycore's kernels into the unpacked wheel at ``package_root`` with interpreter
    ``python``, then check that a fresh process loads every one of them."""
    # the interpreter must import the unpacked package (not an installed raycore) and run one
    # of raycore's levels
    check = _imports_raycore_from(repr(str(package_root))) + (
        "import raycore._target as target; "
        "assert target.runnable_levels(), 'this machine runs none of ' + str(target.LEVELS)")
    warmup = ["-m", "raycore.cli", "warmup", "--every-level", "--dtype", dtype]
    with tempfile.TemporaryDirectory() as elsewhere:  # not the repository: its raycore
        for command in (["-c", check], warmup, warmup + ["--expect-cached"]):
            _run([python, *command], elsewhere, PYTHONPATH=str(package_root))


def _imports_raycore_from(folder):
    """Python code that fails unless ``import raycore`` finds it in ``folder`` (an expression
    in that code)."""
    return f"import raycore; assert raycore.__file__.startswith({folder}), raycore.__file__; "


def kernel_files(package_root):
    """The kernel files under ``package_root/raycore``."""
    return sorted(path for pattern in KERNEL_FILES
                  for path in (package_root / "raycore").rglob(f"__pycache__/{pattern}"))


def ship_kernels(wheel, pythons, dtype="both"):
    """Replace ``wheel`` (a path) by the same wheel with raycore's kernels compiled by each of
    ``pythons``; returns the number of kernel files it carries."""
    wheel = Path(wheel).resolve()
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        _run([sys.executable, "-m", "wheel", "unpack", "--dest", scratch, wheel], scratch)
        (unpacked,) = [path for path in scratch.iterdir() if path.is_dir()]
        # keep the kernels only: the interpreters' bytecode is pip's to write on install
        pristine = {path for path in unpacked.rglob("*") if path.is_file()}
        for python in pythons:
            compile_into(unpacked, python, dtype)
        kernels = set(kernel_files(unpacked))
        for path in unpacked.rglob("*"):
            if path.is_file() and path not in pristine and path not in kernels:
                path.unlink()
        packed = scratch / "packed"
        packed.mkdir()
        _run([sys.executable, "-m", "wheel", "pack", "--dest-dir", packed, unpacked], scratch)
        (built,) = packed.iterdir()
        shutil.move(built, wheel)
    return len(kernels)


def build_wheel(dest):
    """Build raycore's plain wheel from the repository into the empty folder ``dest``
    (``python -m build``); returns its path."""
    # setuptools builds in the repository's build/, and keeps there what the sources dropped
    shutil.rmtree(REPOSITORY / "build", ignore_errors=True)
    _run([sys.executable, "-m", "build", "--wheel", "--outdir", dest, REPOSITORY], REPOSITORY)
    (wheel,) = Path(dest).glob("raycore-*.whl")
    return wheel


def install_into(folder, wheel):
    """A new virtual environment at ``folder`` with ``wheel`` installed with its service extra
    (``pip install "raycore[service]"``, from the wheel); returns its python."""
    _run([sys.executable, "-m", "venv", folder], None)
    python = os.path.join(folder, "bin", "python")
    _run([python, "-m", "pip", "install", "--quiet", f"{wheel}[service]"], None)
    with tempfile.TemporaryDirectory() as elsewhere:  # the installed raycore, not another
        _run([python, "-c", "import sys; " + _imports_raycore_from("sys.prefix")], elsewhere)
    return python


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dest", default="dist", help="folder for the wheel (emptied first)")
    parser.add_argument("--python", nargs="+", default=[sys.executable],
                        help="interpreters to compile with, one per Python version to serve "
                             "(default: this one)")
    parser.add_argument("--dtype", default="both", choices=["float32", "float64", "both"])
    parser.add_argument("--install-into", metavar="DIR",
                        help="then install the wheel, with its service extra, in a new virtual "
                             "environment at DIR")
    args = parser.parse_args(argv)
    shutil.rmtree(args.dest, ignore_errors=True)
    os.makedirs(args.dest)
    wheel = build_wheel(args.dest)
    # absolute, since each runs in a temporary folder; not resolved, which would leave a virtual
    # environment's python for the interpreter it links to
    count = ship_kernels(wheel, [os.path.abspath(python) for python in args.python], args.dtype)
    print(f"{wheel}: {count} kernel files added", flush=True)
    if args.install_into:
        install_into(args.install_into, wheel)


if __name__ == "__main__":
    main()
