"""The INPUT of ``raycore render`` and ``raycore cast``: a mesh file, or a scene JSON in the
service's format (``POST /v1/scenes``) whose mesh objects name files relative to the JSON,
read into a built :class:`raycore.Scene`."""

import sys
from pathlib import Path

from raycore.commands import CommandError

#: Triangles a scene may hold: the service's limit protects a shared server, a local file has
#: only the machine's memory to answer to.
UNLIMITED = sys.maxsize


def load_scene(path, dtype, progress):
    """Read and build the scene of a mesh file or a scene JSON.

    Parameters
    ----------
    path : str or Path
        A mesh file (obj, ply, stl, off, glb: trimesh reads them) or a ``.json`` scene.
    dtype : {"float32", "float64"} or None
        The scene's precision; None: the JSON's own (``dtype``), float32 for a mesh file.
    progress : raycore.commands.progress.Progress

    Returns
    -------
    scene : raycore.Scene
        Built.
    colors : ndarray, shape (G, 3), or None
        Linear RGB of each geometry id from the JSON's materials; None (grey) for a mesh file.

    Raises
    ------
    CommandError
        Naming the file and what is wrong with it.
    """
    from service.builder import MESH_FORMATS

    path = Path(path)
    check_file(path, str(path))
    suffix = path.suffix[1:].lower()
    if suffix == "json":
        return _load_json(path, dtype, progress)
    if suffix not in MESH_FORMATS:
        raise CommandError(f"{path}: not a mesh file ({', '.join(MESH_FORMATS)}) nor a scene "
                           "JSON (.json)")
    from raycore import Scene
    from raycore.mesh import load_trimesh

    with progress.stage(f"loading {path.name}"):
        try:
            # Scene.from_file's steps, whose errors name its argument; the command names the
            # file.  trimesh keeps a glTF's repeated geometry as instances of one stored mesh.
            scene = Scene.from_trimesh(load_trimesh(path), dtype=dtype or "float32")
        except ValueError as error:
            raise CommandError(f"{path}: {error}") from error
    with progress.stage(f"building the BVH of {scene.triangle_count:,} triangles"):
        scene.build()
    return scene, None


def add_scene_arguments(parser):
    """The arguments that :func:`load_scene` takes: ``INPUT`` (the first positional) and
    ``--dtype``."""
    parser.add_argument("input", metavar="INPUT", help="mesh file or scene .json")
    parser.add_argument("--dtype", choices=["float32", "float64"],
                        help="the scene's precision (default: the JSON's, else float32)")


def check_file(path, where):
    """CommandError unless ``path`` is an existing file (``where`` names it in the message)."""
    if not path.exists():
        raise CommandError(f"{where}: no such file")
    if not path.is_file():
        raise CommandError(f"{where}: not a file")


def _load_json(path, dtype, progress):
    """The scene of a scene JSON, built by the service's own builder."""
    from pydantic import ValidationError

    from service.builder import build_scene, parse_mesh
    from service.errors import ClientError, validation_detail
    from service.schemas import SceneSpec

    try:
        spec = SceneSpec.model_validate_json(path.read_bytes())
    except ValidationError as error:
        raise CommandError(f"{path}: {validation_detail(error.errors())}") from error
    if dtype is not None:
        spec = spec.model_copy(update={"dtype": dtype})
    # the files that mesh objects and instances name, read as the service reads an upload; the
    # builder then finds them by name as it finds uploads by id
    meshes = {}
    for index, obj in enumerate(spec.objects):
        name = obj.mesh if obj.type in ("mesh", "instance") else None
        if not isinstance(name, str) or name in meshes:
            continue
        file, where = path.parent / name, f"{path}: objects[{index}].mesh"
        check_file(file, f"{where}: {file}")
        with progress.stage(f"loading {file.name}"):
            try:
                meshes[name] = parse_mesh(file.read_bytes(), file.suffix[1:].lower(), UNLIMITED)
            except ClientError as error:
                raise CommandError(f"{where}: {file}: {error}") from error
    with progress.stage("building the scene"):
        try:
            entry, _ = build_scene(spec, meshes.get, UNLIMITED, UNLIMITED)
        except ClientError as error:
            raise CommandError(f"{path}: {error}") from error
    return entry.scene, entry.colors
