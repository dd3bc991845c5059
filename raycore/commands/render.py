"""``raycore render INPUT -o OUT.png``: a PNG of a mesh file or a scene JSON.

The image is the service's render (``POST /v1/scenes/{id}/render``) of the same camera; where
no camera is given, :func:`raycore.camera.frame_box` frames the whole scene from a
three-quarter view.
"""

from pathlib import Path

from raycore.commands import CommandError, needs_service_extra, positive_int, write_file
from raycore.commands.progress import Progress
from raycore.commands.scenes import add_scene_arguments, load_scene

#: The service's camera fields, by the options that give them (for messages).
_OPTIONS = {"position": "--position", "look_at": "--look-at", "up": "--up", "fov": "--fov",
            "width": "--width", "height": "--height", "samples": "--samples"}


def add_parser(commands):
    """Add ``render`` to the ``raycore`` subcommands."""
    parser = commands.add_parser(
        "render", help="render a mesh file or a scene JSON to a PNG",
        description="Render a mesh file (obj, ply, stl, off, glb) or a scene JSON in the "
                    "service's format (mesh objects name files relative to it) to a PNG. "
                    "Without a camera, the whole scene is framed from a three-quarter view.")
    add_scene_arguments(parser)
    parser.add_argument("-o", "--output", required=True, metavar="OUT.png",
                        help="PNG file to write")
    parser.add_argument("--width", type=positive_int, default=512, help="pixels (default 512)")
    parser.add_argument("--height", type=positive_int, default=512, help="pixels (default 512)")
    parser.add_argument("--camera", choices=["perspective", "orthographic"],
                        default="perspective")
    vector = {"nargs": 3, "type": float, "metavar": ("X", "Y", "Z")}
    parser.add_argument("--position", **vector,
                        help="camera position (default: a three-quarter view framing the scene)")
    parser.add_argument("--look-at", **vector, help="point looked at (default: the scene's "
                        "centre)")
    parser.add_argument("--up", **vector, default=[0.0, 1.0, 0.0],
                        help="up direction (default 0 1 0)")
    parser.add_argument("--fov", type=float, default=45.0,
                        help="vertical field of view in degrees, perspective (default 45)")
    parser.add_argument("--shading", choices=["lambert", "normal", "depth", "id"],
                        default="lambert")
    parser.add_argument("--samples", type=positive_int, default=4,
                        help="rays per pixel, averaged (anti-aliasing; default 4)")
    parser.add_argument("--flat", action="store_true",
                        help="shade meshes with their face normals, not smooth")
    parser.set_defaults(run=run)


def run(args):
    """Load, frame, render and write the PNG."""
    needs_service_extra("render")
    from pydantic import ValidationError

    from raycore.camera import frame_box
    from service.answers import render_image
    from service.codecs import png
    from service.errors import ClientError, validation_detail
    from service.schemas import RenderRequest

    with Progress() as progress:
        scene, colors = load_scene(args.input, args.dtype, progress)
        lo, hi = scene.bounds
        try:
            position, look_at, view_height = frame_box(
                lo, hi, args.width, args.height, fov=args.fov, position=args.position,
                look_at=args.look_at, up=args.up)
        except ValueError as error:
            raise CommandError(_named(str(error))) from error
        camera = {"type": args.camera, "position": position.tolist(),
                  "look_at": look_at.tolist(), "up": list(args.up), "width": args.width,
                  "height": args.height}
        camera.update({"fov": args.fov} if args.camera == "perspective"
                      else {"view_height": view_height})
        try:
            # the service's checks of a render request, and its render
            spec = RenderRequest(camera=camera, shading=args.shading, samples=args.samples,
                                 smooth=not args.flat)
        except ValidationError as error:
            problems = [{**problem, "loc": problem["loc"][-1:]} for problem in error.errors()]
            raise CommandError(_named(validation_detail(problems))) from error
        with progress.stage(f"rendering {args.width}x{args.height}"):
            try:
                image = png(render_image(scene, colors, spec))
            except ClientError as error:
                raise CommandError(_named(str(error))) from error
    write_file(Path(args.output), image)


def _named(message):
    """``message`` with the camera's field names replaced by the options that give them."""
    for field, option in _OPTIONS.items():
        if message.startswith(f"{field} ") or message.startswith(f"{field}:"):
            return option + message[len(field):]
    return message
