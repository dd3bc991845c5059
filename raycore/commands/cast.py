"""``raycore cast INPUT RAYS.npy -o HITS.npy``: a batch of rays from a file, answered into a file.

Rays and answers are the service's ``.npy`` (``POST /v1/scenes/{id}/intersect``): (N, 6) or
(N, 8) float32 or float64 rays in (origin, direction[, tmin, tmax]), a structured array out
(``t``, ``geom_id``, ``prim_id`` and the asked fields for closest hits; ``occluded``; ``count``;
``ray_index``, ``t``, ``geom_id``, ``prim_id`` per hit for all), read and written by the
service's own codecs.
"""

from pathlib import Path

import numpy as np

from raycore.commands import CommandError, needs_service_extra, write_file
from raycore.commands.progress import Progress
from raycore.commands.scenes import add_scene_arguments, check_file, load_scene
from raycore.hits import SURFACE_FIELDS

#: Rays per call: a batch goes through in chunks of this many, so that the progress bar moves.
#: Rays are independent, so the answers are those of one call; a chunk is large enough (about
#: 0.1-0.5 s of work) that the calls' own overhead does not show.
CHUNK = 2**20


def add_parser(commands):
    """Add ``cast`` to the ``raycore`` subcommands."""
    parser = commands.add_parser(
        "cast", help="cast a .npy batch of rays at a mesh file or a scene JSON",
        description="Cast (N, 6) or (N, 8) rays (origin, direction[, tmin, tmax]; float32 or "
                    "float64 .npy) at a mesh file or a scene JSON, and write the answers as "
                    "the service's structured .npy.")
    add_scene_arguments(parser)
    parser.add_argument("rays", metavar="RAYS.npy", help="(N, 6) or (N, 8) rays")
    parser.add_argument("-o", "--output", required=True, metavar="HITS.npy",
                        help=".npy file to write")
    parser.add_argument("--query", choices=["closest", "any", "all", "count"],
                        default="closest", help="closest hit (default), any hit (occlusion), "
                                                "all hits, or their count")
    parser.add_argument("--fields", type=_fields, default=[], metavar="F[,F...]",
                        help="surface data of closest hits: uv, normal, point")
    parser.add_argument("--triangle-test", choices=["watertight", "moller", "geometric"],
                        default="watertight")
    parser.set_defaults(run=run)


def _fields(text):
    import argparse

    fields = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in fields if name not in SURFACE_FIELDS]
    if unknown or not fields:
        raise argparse.ArgumentTypeError(
            f"must be among {', '.join(SURFACE_FIELDS)} (comma-separated), got {text!r}")
    return list(dict.fromkeys(fields))


def run(args):
    """Load the scene and the rays, answer the query, write the table."""
    needs_service_extra("cast")
    from service import codecs
    from service.errors import ClientError
    from service.schemas import QueryOptions

    options = QueryOptions(query=args.query, fields=args.fields,
                           triangle_test=args.triangle_test)
    if options.fields and options.query != "closest":
        raise CommandError(f"--fields apply to closest-hit queries, not --query {options.query}")
    rays_path = Path(args.rays)
    check_file(rays_path, str(rays_path))
    try:
        rays = codecs.rays_from_npy(codecs.read_npy(rays_path.read_bytes()), None, None)
    except ClientError as error:
        raise CommandError(f"{rays_path}: {error}") from error
    with Progress() as progress:
        scene, _ = load_scene(args.input, args.dtype, progress)
        try:
            columns = _answer(scene, rays, options, progress)
        except ClientError as error:
            raise CommandError(f"{rays_path}: {error}") from error
    write_file(Path(args.output), codecs.columns_to_npy(columns))


def _answer(scene, rays, options, progress):
    """The service's result columns of ``options.query`` for ``rays``, a chunk at a time."""
    from service.answers import run_query
    from service.codecs import result_columns

    count = len(rays[0])
    parts = []
    with progress.stage(f"casting {count:,} rays", total=count) as advance:
        for start in range(0, max(count, 1), CHUNK):
            chunk = slice(start, start + CHUNK)
            part = tuple(column[chunk] if np.ndim(column) else column for column in rays)
            columns = result_columns(options.query, run_query(scene, part, options))
            if options.query == "all":  # ray indices count from the chunk's first ray
                columns["ray_index"] = columns["ray_index"] + start
            parts.append(columns)
            advance(len(part[0]))
    if len(parts) == 1:
        return parts[0]
    return {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}
