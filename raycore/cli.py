"""The ``raycore`` command: ``raycore serve`` runs the HTTP service, ``raycore openapi`` writes
its OpenAPI document, ``raycore info`` says what the library runs on, ``raycore warmup``
compiles its kernels ahead of use; ``render``, ``cast`` and ``bench`` (:mod:`raycore.commands`)
work on files.

Whatever a user gets wrong (options, files, their contents) is answered with one line on stderr
and exit status 1 (2 for the command line's own syntax), never a traceback.
"""

import argparse
import json
import os
import re
import subprocess
import sys

from raycore.commands import CommandError, bench, cast, positive_int, render, user_error

#: Set to 1 to let unexpected errors through with their traceback (they are bugs: report them).
TRACEBACK_VARIABLE = "RAYCORE_TRACEBACK"


class _Parser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line (argparse prints the usage before them), and
    which takes negative numbers in any notation as values (``--look-at -1e3 0 0``): the argparse
    of Python 3.11.7, 3.12.1 and 3.13.0 takes only -1 and -1.5 so, and -1e3 for an option."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # a minus, then a digit, or a point and a digit
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _serve(args):
    import uvicorn

    # worker processes import the app by name and make their own; one process can take the app
    uvicorn.run("service.app:create_app", factory=True, host=args.host, port=args.port,
                log_level=args.log_level, workers=args.workers)


def _openapi(args):
    from service.app import create_app
    from service.config import Settings

    document = json.dumps(create_app(Settings(demo=False)).openapi(), indent=2) + "\n"
    if args.output == "-":
        sys.stdout.write(document)
    else:
        with open(args.output, "w", encoding="utf-8") as file:
            file.write(document)


def _info(args):
    import raycore

    report = raycore.info()
    if args.json:
        print(json.dumps(report, indent=2))
        return
    safety = [name for name, safe in (("thread-safe", report["thread_safe"]),
                                      ("fork-safe", report["fork_safe"])) if safe]
    print(f"threading layer   {report['threading_layer']} ({', '.join(safety) or 'unsafe'})")
    print(f"threads           {report['threads']}")
    print(f"cpu               {report['cpu']} (this machine: {report['host_cpu']})")
    print(f"simd              {' '.join(report['simd']) or 'none'}")
    print(f"numba cache       {report['numba_cache_dir']}")
    print(f"numba             {report['numba']}")


def _warmup(args):
    from raycore._compile_notice import NOTICE
    from raycore._target import runnable_levels
    from raycore._warmup import DTYPES, warm_up

    levels = runnable_levels() if args.every_level else []
    if levels:
        _warm_up_every_level(args, levels)
        return
    dtypes = DTYPES if args.dtype == "both" else (args.dtype,)
    seconds = warm_up(dtypes)
    print(f"raycore warmup: done in {seconds:.1f} s")
    if args.expect_cached and NOTICE.compiled:
        raise CommandError(f"{len(NOTICE.compiled)} functions were compiled, not loaded from "
                           f"the cache, the first {NOTICE.compiled[0]}")


def _warm_up_every_level(args, levels):
    """``raycore warmup`` for each of ``levels`` (:mod:`raycore._target`), in a process of its
    own: Numba compiles a whole process for one CPU."""
    from raycore._target import CPU_SETTINGS, level_settings

    environment = {key: value for key, value in os.environ.items() if key not in CPU_SETTINGS}
    for level in levels:
        print(f"raycore warmup: kernels for {level.name}", flush=True)
        command = [sys.executable, "-m", "raycore.cli", "warmup", "--dtype", args.dtype]
        if args.expect_cached:
            command.append("--expect-cached")
        if subprocess.run(command, env={**environment, **level_settings(level)}).returncode:
            raise CommandError(f"the warmup for {level.name} failed")


def build_parser():
    """The ``raycore`` command's parser, with every subcommand."""
    parser = _Parser(prog="raycore", description="Ray casting library and service")
    commands = parser.add_subparsers(dest="command", required=True)
    serve = commands.add_parser(
        "serve", help="serve the HTTP API (settings from RAYCORE_* environment variables)")
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8000)
    serve.add_argument("--log-level", default="info",
                       choices=["critical", "error", "warning", "info", "debug"])
    serve.add_argument("--workers", type=positive_int,
                       help="worker processes, each with its own store (default: 1, or "
                            "$WEB_CONCURRENCY); see the README's 'Scaling to several workers'")
    serve.set_defaults(run=_serve)
    openapi = commands.add_parser("openapi", help="write the HTTP API's OpenAPI document")
    openapi.add_argument("--output", default="-", help="file to write, or - for stdout")
    openapi.set_defaults(run=_openapi)
    info = commands.add_parser(
        "info", help="the threading layer, threads, CPU features and kernel cache in use")
    info.add_argument("--json", action="store_true", help="as JSON, as raycore.info() gives it")
    info.set_defaults(run=_info)
    warmup = commands.add_parser(
        "warmup", help="compile every kernel ahead of use, into Numba's cache")
    warmup.add_argument("--dtype", default="both", choices=["float32", "float64", "both"],
                        help="precision of the scenes to compile for (default: both)")
    warmup.add_argument("--expect-cached", action="store_true",
                        help="fail if any kernel has to be compiled rather than loaded from "
                             "the cache (checks a cache that was shipped or warmed before)")
    warmup.add_argument("--every-level", action="store_true",
                        help="for every CPU level this machine runs (x86-64-v4, x86-64-v3), "
                             "each in a process of its own, rather than for this process's: "
                             "for a cache that other machines will load")
    warmup.set_defaults(run=_warmup)
    for command in (render, cast, bench):
        command.add_parser(commands)
    return parser


def main(argv=None):
    """Parse ``argv`` (default: the command line) and run the subcommand."""
    args = build_parser().parse_args(argv)
    try:
        args.run(args)
    except Exception as error:  # noqa: BLE001 - the user sees one line, whatever failed
        sys.exit(_one_line(args.command, error))
    except KeyboardInterrupt:
        print(f"raycore {args.command}: interrupted", file=sys.stderr)
        sys.exit(130)  # the shell's status for a command ended by SIGINT


def _one_line(command, error):
    """The line that ``error`` is reported with (re-raised when it is a bug and
    :data:`TRACEBACK_VARIABLE` asks for its traceback)."""
    message = user_error(error)
    if message is None:
        if os.environ.get(TRACEBACK_VARIABLE) == "1":
            raise error
        message = (f"unexpected {type(error).__name__}: {error} (a bug: "
                   f"{TRACEBACK_VARIABLE}=1 shows where)")
    return f"raycore {command}: {' '.join(str(message).split())}"


if __name__ == "__main__":
    main()
