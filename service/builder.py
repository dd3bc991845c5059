"""From validated client input to stored geometry: uploaded mesh files and scene specs.

The library's ``ValueError``s become :class:`~service.errors.ClientError`s here, prefixed with
where in the input the problem lies.
"""

import gc
import io
import time
from dataclasses import dataclass

import numpy as np

from raycore import Scene
from raycore.mesh import load_trimesh
from raycore.render import DEFAULT_COLOR
from service.errors import ClientError, LimitExceeded, NotFound
from service.schemas import Bounds, MeshInfo, SceneInfo, SceneSpec
from service.store import ENTRY_OVERHEAD, content_id

#: Memory a scene holds per object beyond its trees (the Scene's tables, an analytic shape's
#: parameters): 530-1010 bytes, traced by tracemalloc over scenes of 5,000-20,000 planes, boxes
#: or spheres; charged nothing, a scene of 100,000 planes was held at 32 KiB and took 57 MiB.
OBJECT_BYTES = 1280
#: File types trimesh reads for uploads.
MESH_FORMATS = ("obj", "ply", "stl", "off", "glb")


@dataclass(frozen=True)
class MeshEntry:
    """An uploaded mesh: (V, 3) float64 vertices, (F, 3) int64 faces, and what the API says."""

    vertices: np.ndarray
    faces: np.ndarray
    info: MeshInfo

    @property
    def nbytes(self):
        return self.vertices.nbytes + self.faces.nbytes + ENTRY_OVERHEAD


@dataclass(frozen=True)
class SceneEntry:
    """A built scene, the (G, 3) linear RGB colour of each geometry id, and what the API says."""

    scene: Scene
    colors: np.ndarray
    info: SceneInfo


#: Mesh files of this many bytes or more are followed by a full garbage collection: trimesh's
#: objects hold reference cycles, which only a full collection frees, and none ran between
#: uploads: three 130 MB OBJ bodies (refused, 413) left the process 3.2 -> 8.5 GB (in-process,
#: three parses: 259 -> 1558 MB, 449 after a collection).
COLLECT_AFTER_BYTES = 1 << 20


def parse_mesh(data, file_type, max_triangles):
    """Read a mesh file's bytes; a multi-part file (e.g. a glTF scene) is flattened into one mesh.

    Raises
    ------
    ClientError
        When the file cannot be read, holds no triangles or non-finite vertices.
    LimitExceeded
        When it has more than ``max_triangles`` faces.
    """
    try:
        return _parsed_mesh(data, file_type, max_triangles)
    finally:
        if len(data) >= COLLECT_AFTER_BYTES:
            gc.collect()


def _parsed_mesh(data, file_type, max_triangles):
    import trimesh

    if file_type not in MESH_FORMATS:
        raise ClientError(f"format must be one of {MESH_FORMATS}, got {file_type!r}")
    try:
        loaded = load_trimesh(io.BytesIO(data), file_type)
    except ValueError as error:
        raise ClientError(str(error)) from error
    if isinstance(loaded, trimesh.Scene):
        # count before flattening: a small file can place one mesh at a million nodes
        placed = sum(len(getattr(loaded.geometry.get(name), "faces", ())) for name in
                     (loaded.graph[node][1] for node in loaded.graph.nodes_geometry))
        if placed > max_triangles:
            raise LimitExceeded(f"the mesh file places {placed} triangles; the limit is "
                                f"{max_triangles}")
        for name, part in loaded.geometry.items():
            _check_faces(part.vertices, part.faces, f"part {name!r}: ")
        mesh = loaded.to_mesh()
    else:
        mesh = loaded
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    if len(faces) > max_triangles:
        raise LimitExceeded(f"the mesh has {len(faces)} triangles; the limit is {max_triangles}")
    _check_faces(vertices, faces)
    if not np.all(np.isfinite(vertices)):
        raise ClientError("the mesh's vertices must be finite (no NaN or inf)")
    # STL stores a triangle soup: merge equal vertices before asking whether edges are shared
    closed = bool(trimesh.Trimesh(vertices, faces, process=True).is_watertight)
    used = vertices[faces.ravel()]
    info = MeshInfo(id=content_id(vertices.tobytes(), faces.tobytes()), vertices=len(vertices),
                    faces=len(faces), closed=closed,
                    bounds=Bounds(lo=used.min(axis=0).tolist(), hi=used.max(axis=0).tolist()))
    return MeshEntry(vertices, faces, info)


def _check_faces(vertices, faces, where=""):
    """ClientError unless every face index names a vertex (files can hold any integer)."""
    faces = np.asarray(faces)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ClientError(f"{where}the mesh's faces must index its {len(vertices)} vertices, got "
                          f"indices in [{faces.min()}, {faces.max()}]")


def scene_id(spec):
    """Content hash of a scene spec (uploaded meshes enter through their content ids)."""
    return content_id(spec.model_dump_json().encode())


def build_scene(spec: SceneSpec, find_mesh, max_triangles, max_planes):
    """Build (the BVHs of) a scene from its spec.

    Parameters
    ----------
    spec : SceneSpec
    find_mesh : callable
        Uploaded mesh id -> MeshEntry, or None when unknown.
    max_triangles, max_planes : int

    Returns
    -------
    SceneEntry, int
        The scene and the bytes it holds.

    Raises
    ------
    ClientError
        Naming the object whose parameters the library refuses, or the unknown mesh it names.
    LimitExceeded
        When the scene would store more than ``max_triangles`` triangles, or has more than
        ``max_planes`` planes.
    """
    start = time.perf_counter()
    planes = sum(obj.type == "plane" for obj in spec.objects)
    if planes > max_planes:
        raise LimitExceeded(f"the scene has {planes} planes; the limit is {max_planes} (every "
                            "ray tests every plane)")
    for index, obj in enumerate(spec.objects):
        if obj.type == "mesh" and obj.faces is not None and len(obj.faces) > max_triangles:
            # the document's maxItems: invalid, where only the whole scene's count is too large
            raise ClientError(f"objects[{index}].faces: {len(obj.faces)} triangles; the limit is "
                              f"{max_triangles}")
    uploads = _uploaded_meshes(spec, find_mesh)
    triangles = sum(len(mesh.faces) for mesh in uploads.values()) + sum(
        len(obj.faces) for obj in spec.objects if obj.type == "mesh" and obj.mesh is None)
    if triangles > max_triangles:
        raise LimitExceeded(f"the scene stores {triangles} triangles; the limit is {max_triangles}")

    scene = Scene(dtype=spec.dtype)
    prototypes = {}  # uploaded mesh id -> geometry id of the scene's copy of it
    mesh_of_object = {}  # index of a mesh object -> geometry id holding its triangles
    geom_ids, colors = [], {}
    for index, obj in enumerate(spec.objects):
        try:
            geom = _add(scene, obj, uploads, prototypes, mesh_of_object)
        except ValueError as error:
            raise ClientError(f"objects[{index}] ({obj.type}): {error}") from error
        if obj.type == "mesh":
            mesh_of_object[index] = geom if obj.mesh is None else prototypes[obj.mesh]
        geom_ids.append(geom)
        if obj.material is not None:
            colors[geom] = obj.material.color
    scene.build()

    palette = np.tile(np.asarray(DEFAULT_COLOR), (len(scene), 1))
    for geom, color in colors.items():
        palette[geom] = color
    lo, hi = scene.bounds
    bounded = bool(np.all(lo <= hi))
    held = ENTRY_OVERHEAD + OBJECT_BYTES * len(spec.objects) + scene.stats()["bytes"] + sum(
        m.nbytes for m in uploads.values()) + sum(
        24 * (len(obj.vertices) + len(obj.faces))
        for obj in spec.objects if obj.type == "mesh" and obj.mesh is None)
    info = SceneInfo(id=scene_id(spec), dtype=spec.dtype, objects=len(spec.objects),
                     triangles=scene.triangle_count, geom_ids=geom_ids,
                     bounds=Bounds(lo=lo.tolist(), hi=hi.tolist()) if bounded else None,
                     build_seconds=time.perf_counter() - start, bytes=held)
    return SceneEntry(scene, palette, info), held


def _uploaded_meshes(spec, find_mesh):
    """Uploaded meshes the spec names, by id; ClientError for an unknown one."""
    uploads = {}
    for index, obj in enumerate(spec.objects):
        name = obj.mesh if obj.type in ("mesh", "instance") else None
        if isinstance(name, str) and name not in uploads:
            entry = find_mesh(name)
            if entry is None:
                raise NotFound(f"objects[{index}].mesh: no mesh {name!r} (upload it with "
                                  "POST /v1/meshes)")
            uploads[name] = entry
    return uploads


def _add(scene, obj, uploads, prototypes, mesh_of_object):
    """Add one object to ``scene``; return its geometry id."""
    if obj.type == "mesh":
        if obj.mesh is None:
            return scene.add_mesh(obj.vertices, obj.faces)
        if obj.mesh in prototypes:  # another placement of the same upload: share it
            return scene.add_instance(prototypes[obj.mesh], np.eye(4))
        prototypes[obj.mesh] = scene.add_mesh(uploads[obj.mesh].vertices, uploads[obj.mesh].faces)
        return prototypes[obj.mesh]
    if obj.type == "instance":
        if isinstance(obj.mesh, int):
            if obj.mesh not in mesh_of_object:
                raise ValueError(f"mesh must be the index of an earlier mesh object, got "
                                 f"{obj.mesh}")
            return scene.add_instance(mesh_of_object[obj.mesh], obj.transform)
        if obj.mesh not in prototypes:  # placed only through instances: not visible itself
            upload = uploads[obj.mesh]
            prototypes[obj.mesh] = scene.add_mesh(upload.vertices, upload.faces, visible=False)
        return scene.add_instance(prototypes[obj.mesh], obj.transform)
    if obj.type == "box":
        return scene.add_box(obj.lo, obj.hi, obj.transform)
    parameters = obj.model_dump(exclude={"type", "material"})
    return getattr(scene, f"add_{obj.type}")(**parameters)
