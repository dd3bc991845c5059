"""Request and response models of the HTTP API (pydantic v2), with the examples OpenAPI shows.

Shapes mirror the arguments of ``raycore.Scene.add_*``; geometry is checked here only as far as
JSON types go (finite numbers, 3-vectors) and the library checks the rest.
"""

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

Vec3 = tuple[float, float, float]
Matrix = Annotated[list[list[float]], Field(
    description="4x4 affine transform, row-major (last row 0, 0, 0, 1); a 3x4 is accepted too")]
DType = Literal["float32", "float64"]
TriangleTest = Literal["watertight", "moller", "geometric"]
QueryKind = Literal["closest", "any", "all", "count"]
SurfaceField = Literal["uv", "normal", "point"]
Unit = Annotated[float, Field(ge=0, le=1)]
Byte = Annotated[int, Field(ge=0, le=255)]

IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
EXAMPLE_MESH_ID = "9f2c1e5d7a3b4c6d8e0f1a2b3c4d5e6f"
EXAMPLE_SCENE_ID = "0c5b7e2a9d1f4e3b8a6c2d0e1f3a5b7c"


class Strict(BaseModel):
    """Unknown keys and non-finite numbers are errors, not silently dropped or passed on."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class Error(BaseModel):
    """What was wrong with a request."""

    detail: str = Field(description="A sentence naming the offending part of the request")
    errors: list[dict] | None = Field(
        None, description="For malformed bodies: each problem's location, message and type")

    model_config = ConfigDict(json_schema_extra={"examples": [
        {"detail": "objects.0.sphere.radius: Input should be a valid number"}]})


# ---------------------------------------------------------------------- meshes


class Bounds(BaseModel):
    lo: Vec3
    hi: Vec3


class MeshInfo(BaseModel):
    """An uploaded mesh: reference it from scenes by ``id``."""

    id: str = Field(description="Content hash of the vertices and faces")
    vertices: int
    faces: int
    bounds: Bounds
    closed: bool = Field(description="Whether the mesh is watertight (every edge shared twice)")

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "id": EXAMPLE_MESH_ID, "vertices": 642, "faces": 1280,
        "bounds": {"lo": [-1.0, -1.0, -1.0], "hi": [1.0, 1.0, 1.0]}, "closed": True}]})


# ---------------------------------------------------------------------- scenes


class Material(Strict):
    color: tuple[Unit, Unit, Unit] = Field(description="Linear RGB in [0, 1], used by lambert "
                                                        "renders")


class Shape(Strict):
    material: Material | None = None


class Sphere(Shape):
    type: Literal["sphere"]
    center: Vec3
    radius: float


class Plane(Shape):
    type: Literal["plane"]
    point: Vec3
    normal: Vec3


class Disk(Shape):
    type: Literal["disk"]
    center: Vec3
    normal: Vec3
    radius: float


class Box(Shape):
    type: Literal["box"]
    lo: Vec3
    hi: Vec3
    transform: Matrix | None = None


class Cylinder(Shape):
    type: Literal["cylinder"]
    p0: Vec3
    p1: Vec3
    radius: float


class Cone(Shape):
    type: Literal["cone"]
    base_center: Vec3
    apex: Vec3
    radius: float


class MeshObject(Shape):
    """A triangle mesh: an uploaded mesh's id, or inline vertices and faces."""

    type: Literal["mesh"]
    mesh: str | None = Field(None, description="Id from POST /v1/meshes")
    vertices: list[Vec3] | None = None
    faces: list[tuple[int, int, int]] | None = None

    @model_validator(mode="after")
    def _one_source(self):
        inline = self.vertices is not None or self.faces is not None
        if (self.mesh is not None) == inline:
            raise ValueError("give either mesh (an uploaded mesh id) or vertices and faces")
        if inline and (self.vertices is None or self.faces is None):
            raise ValueError("inline meshes need both vertices and faces")
        return self


class Instance(Shape):
    """Another placement of a mesh; it shares the mesh's triangles and BVH."""

    type: Literal["instance"]
    mesh: str | Annotated[int, Field(ge=0)] = Field(
        description="An uploaded mesh's id, or the index of a mesh object in this scene's objects")
    transform: Matrix


SceneObject = Annotated[Sphere | Plane | Disk | Box | Cylinder | Cone | MeshObject | Instance,
                        Field(discriminator="type")]


class SceneSpec(Strict):
    """A scene: its precision and its objects, in order."""

    dtype: DType = "float32"
    objects: list[SceneObject]

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "dtype": "float32",
        "objects": [
            {"type": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]},
            {"type": "sphere", "center": [0, 1, 0], "radius": 1,
             "material": {"color": [0.9, 0.2, 0.2]}},
            {"type": "box", "lo": [2, 0, -1], "hi": [4, 2, 1]},
            {"type": "mesh", "vertices": [[-1, 0, 3], [1, 0, 3], [0, 2, 3]], "faces": [[0, 1, 2]]},
            {"type": "instance", "mesh": 3, "transform": [
                [1, 0, 0, -3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
        ]}]})


class SceneInfo(BaseModel):
    """A built scene.  Hits report ``geom_id``: ``geom_ids[i]`` is the one of ``objects[i]``."""

    id: str = Field(description="Content hash of the scene JSON (with its meshes)")
    dtype: DType
    objects: int
    triangles: int = Field(description="Triangles stored (instances share their mesh's)")
    geom_ids: list[int]
    bounds: Bounds | None = Field(description="Bounds of the bounded objects; null if none")
    build_seconds: float
    bytes: int = Field(description="Memory held for queries")

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "id": EXAMPLE_SCENE_ID, "dtype": "float32", "objects": 5, "triangles": 1,
        "geom_ids": [0, 1, 2, 3, 4], "bounds": {"lo": [-4, -1, -1], "hi": [4, 2, 3]},
        "build_seconds": 0.0012, "bytes": 512}]})


# ---------------------------------------------------------------------- intersect


class QueryOptions(Strict):
    """How to query: as URL parameters for .npy bodies, in the body for JSON."""

    query: QueryKind = Field("closest", description=(
        "closest: the nearest hit; any: whether anything is hit (occlusion); all: every hit "
        "along each ray, sorted by t; count: the number of hits"))
    fields: list[SurfaceField] = Field(
        [], description="Surface data of closest hits to return besides t and the ids")
    triangle_test: TriangleTest = "watertight"


class NpyOptions(QueryOptions):
    """URL parameters of .npy ray batches; ``tmin``/``tmax`` only for rays of shape (N, 6),
    as (N, 8) rays carry their own."""

    tmin: float | None = Field(None, description="Default 0")
    tmax: float | None = Field(None, description="Default: no limit")


class IntersectRequest(QueryOptions):
    """A batch of rays as JSON; a hit lies at ``origin + t * direction``."""

    origins: list[Vec3]
    directions: list[Vec3] = Field(description="Need not be unit length; t is in their units")
    tmin: float | list[float] = 0.0
    tmax: float | list[float | None] | None = Field(None, description="null: no limit")

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "origins": [[0, 1, -5], [0, 10, -5]], "directions": [[0, 0, 1], [0, 0, 1]],
        "tmin": 0, "tmax": None, "query": "closest", "fields": ["normal"],
        "triangle_test": "watertight"}]})


class IntersectResponse(BaseModel):
    """Per query: ``closest`` gives t, geom_id, prim_id and the asked fields (t and fields null,
    ids -1 where missed); ``any`` gives occluded; ``count`` gives count; ``all`` gives counts and,
    per hit in ray order, ray_index, t, geom_id and prim_id."""

    t: list[float | None] | None = None
    geom_id: list[int] | None = None
    prim_id: list[int] | None = None
    uv: list[tuple[float, float] | None] | None = None
    normal: list[Vec3 | None] | None = None
    point: list[Vec3 | None] | None = None
    occluded: list[bool] | None = None
    count: list[int] | None = None
    counts: list[int] | None = None
    ray_index: list[int] | None = None

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "t": [4.0, None], "geom_id": [1, -1], "prim_id": [0, -1],
        "normal": [[0.0, 0.0, -1.0], None]}]})


# ---------------------------------------------------------------------- render


class CameraBase(Strict):
    position: Vec3
    look_at: Vec3
    up: Vec3 = (0.0, 1.0, 0.0)
    width: Annotated[int, Field(ge=1)] = 512
    height: Annotated[int, Field(ge=1)] = 512


class PerspectiveCamera(CameraBase):
    type: Literal["perspective"]
    fov: Annotated[float, Field(gt=0, lt=180, description="Vertical, in degrees")] = 45.0


class OrthographicCamera(CameraBase):
    type: Literal["orthographic"]
    view_height: Annotated[float, Field(gt=0, description="In scene units")]


class RenderRequest(Strict):
    """A camera and a shading; answered with a PNG."""

    camera: Annotated[PerspectiveCamera | OrthographicCamera, Field(discriminator="type")]
    shading: Literal["depth", "normal", "lambert", "id"] = "lambert"
    light_direction: Vec3 = Field((0.4, 1.0, 0.6), description="Towards the light (lambert)")
    ambient: Unit = 0.15
    background: tuple[Byte, Byte, Byte] = Field((0, 0, 0), description="RGB of missed pixels")
    triangle_test: TriangleTest = "watertight"

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "camera": {"type": "perspective", "position": [6, 4, -8], "look_at": [0, 1, 0],
                   "up": [0, 1, 0], "fov": 45, "width": 512, "height": 384},
        "shading": "lambert", "light_direction": [0.4, 1.0, 0.6]}]})


# ---------------------------------------------------------------------- health


class Status(BaseModel):
    status: Literal["ok"]

    model_config = ConfigDict(json_schema_extra={"examples": [{"status": "ok"}]})


class Readiness(BaseModel):
    """Whether startup work is done, and what the kernels run on (no more: the probe is open)."""

    status: Literal["ready", "starting"]
    threading_layer: str = Field(
        description="Numba's threading layer: tbb (thread-safe and fork-safe), or workqueue "
                    "where TBB cannot load (one parallel kernel at a time)")
    threads: int = Field(description="Threads each query's parallel kernels run on")

    model_config = ConfigDict(json_schema_extra={"examples": [
        {"status": "ready", "threading_layer": "tbb", "threads": 2}]})


# ---------------------------------------------------------------------- error documentation

_ERROR_EXAMPLES = {
    400: ("The body cannot be decoded",
          {"detail": "the .npy header announces shape (1000, 8) of <f4 (32000 bytes), the body "
                     "holds 31996 bytes of data"}),
    401: ("The API key is missing or wrong (only when the service is configured with one)",
          {"detail": "this endpoint needs the API key: send it as X-API-Key or "
                     "Authorization: Bearer"}),
    404: ("No such scene or mesh",
          {"detail": f"no scene '{EXAMPLE_SCENE_ID}' (it may have been evicted: send it again)"}),
    408: ("The body did not all arrive in time (RAYCORE_BODY_SECONDS)",
          {"detail": "the body did not all arrive within 60 s, the limit"}),
    413: ("Over a configured limit",
          {"detail": "2500000 rays in one request; the limit is 2097152"}),
    415: ("Unreadable content type",
          {"detail": "Content-Type must be application/json or application/x-npy, got text/plain"}),
    422: ("Invalid request",
          {"detail": "body.objects.0.sphere.radius: Field required",
           "errors": [{"loc": ["body", "objects", 0, "sphere", "radius"], "msg": "Field required",
                       "type": "missing"}]}),
}


def error_responses(*statuses):
    """OpenAPI ``responses`` entries, with an example each, for the given error statuses."""
    return {status: {"model": Error, "description": _ERROR_EXAMPLES[status][0],
                     "content": {"application/json": {"example": _ERROR_EXAMPLES[status][1]}}}
            for status in statuses}


# ---------------------------------------------------------------------- links

#: OpenAPI links from what creates a mesh or scene to the operations that use its id (clients
#: and stateful fuzzers follow them).
MESH_LINKS = {
    "GetMesh": {"operationId": "get_mesh_v1_meshes__mesh_id__get",
                "parameters": {"mesh_id": "$response.body#/id"},
                "description": "Describe the mesh"},
    "DeleteMesh": {"operationId": "delete_mesh_v1_meshes__mesh_id__delete",
                   "parameters": {"mesh_id": "$response.body#/id"},
                   "description": "Forget the mesh"},
    "BuildSceneWithMesh": {"operationId": "create_scene_v1_scenes_post",
                           "requestBody": {"objects": [{"type": "mesh",
                                                        "mesh": "$response.body#/id"}]},
                           "description": "Build a scene of the mesh"},
}
SCENE_LINKS = {
    name: {"operationId": operation, "parameters": {"scene_id": "$response.body#/id"},
           "description": description}
    for name, operation, description in [
        ("GetScene", "get_scene_v1_scenes__scene_id__get", "Describe the scene"),
        ("DeleteScene", "delete_scene_v1_scenes__scene_id__delete", "Forget the scene"),
        ("Intersect", "intersect_v1_scenes__scene_id__intersect_post", "Cast rays at the scene"),
        ("Render", "render_scene_v1_scenes__scene_id__render_post", "Render the scene")]}
