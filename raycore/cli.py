"""The ``raycore`` command: ``raycore serve`` runs the HTTP service, ``raycore openapi`` writes
its OpenAPI document, ``raycore info`` says what the library runs on, ``raycore warmup``
compiles its kernels ahead of use."""

import argparse
import json
import sys


def _serve(args):
    import uvicorn

    from service.app import create_app

    uvicorn.run(create_app(), host=args.host, port=args.port, log_level=args.log_level)


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
    print(f"cpu               {report['cpu']}")
    print(f"simd              {' '.join(report['simd']) or 'none'}")
    print(f"numba cache       {report['numba_cache_dir']}")
    print(f"numba             {report['numba']}")


def _warmup(args):
    from raycore._warmup import DTYPES, warm_up

    dtypes = DTYPES if args.dtype == "both" else (args.dtype,)
    seconds = warm_up(dtypes)
    print(f"raycore warmup: done in {seconds:.1f} s")


def main(argv=None):
    """Parse ``argv`` (default: the command line) and run the subcommand."""
    parser = argparse.ArgumentParser(prog="raycore", description="Ray casting library and service")
    commands = parser.add_subparsers(dest="command", required=True)
    serve = commands.add_parser(
        "serve", help="serve the HTTP API (settings from RAYCORE_* environment variables)")
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8000)
    serve.add_argument("--log-level", default="info",
                       choices=["critical", "error", "warning", "info", "debug"])
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
    warmup.set_defaults(run=_warmup)
    args = parser.parse_args(argv)
    args.run(args)


if __name__ == "__main__":
    main()
