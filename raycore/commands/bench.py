"""``raycore bench``: the side-by-side benchmark, ``benchmarks/run.py`` (``make bench``'s first
part), with a progress bar over its meshes on a terminal.

``benchmarks/`` is not installed with the package: this runs from a source checkout (an
editable install finds it beside ``raycore/``) with the ``bench`` extra installed.
"""

import importlib.util
import sys
from pathlib import Path

from raycore.commands import CommandError, positive_int
from raycore.commands.progress import Progress

#: What ``benchmarks.run`` imports beyond the library: the ``bench`` extra.
NEEDS = ("open3d", "embreex", "trimesh", "matplotlib", "psutil")


def add_parser(commands):
    """Add ``bench`` to the ``raycore`` subcommands.

    Its options are ``benchmarks/run.py``'s (a test holds them equal): they are declared here
    because ``benchmarks`` cannot be imported where it is not installed, and ``--help`` must work
    there too.
    """
    parser = commands.add_parser(
        "bench", help="benchmark raycore against Open3D and embreex (source checkout, bench "
                      "extra)",
        description="benchmarks/run.py: raycore, Open3D and embreex on the same rays, each "
                    "library's own call timed; results in benchmarks/results/bench.md.")
    parser.add_argument("--quick", action="store_true", help="one small mesh, few rays: a "
                                                             "smoke run")
    parser.add_argument("--no-large", action="store_true",
                        help="skip the subdivided meshes of 1.6M and 6.4M triangles")
    parser.add_argument("--rounds", type=positive_int, help="interleaved rounds per ray set "
                                                            "(default 5)")
    parser.add_argument("--meshes", nargs="+", metavar="NAME", help="measure only these meshes")
    parser.add_argument("--out", metavar="DIR", help="folder for bench.json and bench.md")
    parser.set_defaults(run=run)


def run(args):
    """Check that the benchmark can run here, then run it."""
    bench = _benchmark_module()
    argv = ["--quick"] * args.quick + ["--no-large"] * args.no_large
    if args.rounds is not None:
        argv += ["--rounds", str(args.rounds)]
    if args.meshes:
        from benchmarks import meshes

        known = meshes.benchmark_meshes(large=True)
        unknown = [name for name in args.meshes if name not in known]
        if unknown:
            raise CommandError(f"--meshes: no mesh named {', '.join(unknown)} (there are "
                               f"{', '.join(known)})")
        argv += ["--meshes", *args.meshes]
    if args.out is not None:
        argv += ["--out", args.out]
    with Progress() as progress:
        bench.main(argv, progress=progress.stage)


def _benchmark_module():
    """``benchmarks.run``, from the checkout that holds this package; CommandError where there
    is none or the ``bench`` extra is missing."""
    root = Path(__file__).resolve().parents[2]
    if not (root / "benchmarks" / "run.py").is_file():
        raise CommandError("the benchmark (benchmarks/run.py) comes with a source checkout of "
                           "raycore, not with the package: run it there, after pip install -e "
                           "'.[service,bench]'")
    missing = [name for name in NEEDS if importlib.util.find_spec(name) is None]
    if missing:
        raise CommandError(f"the benchmark needs the bench extra ({', '.join(missing)} "
                           "missing): pip install -e '.[service,bench]' (or make bench)")
    # (its subprocesses find the checkout themselves: benchmarks.run.CHECKOUT)
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    from benchmarks import run as bench

    return bench
