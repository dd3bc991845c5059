"""Request and response models of the HTTP API (pydantic v2), with the examples OpenAPI shows.

Shapes mirror the arguments of ``raycore.Scene.add_*``.  Every rule that JSON Schema can state is
stated here, so that the OpenAPI document says it (numbers are strict: no booleans or strings;
coordinates are bounded; radii are positive); the library checks what it cannot (e.g. that a
box's ``lo`` is below its ``hi``), and those rules are listed in the operations' descriptions.

3-vectors are arrays of three numbers rather than tuples: a tuple's ``prefixItems`` inside
``anyOf`` is rewritten into a draft-4 ``items`` list by schemathesis 4.x, which then cannot
validate answers against it.
"""

from datetime import datetime
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from raycore.camera import MAX_SAMPLES
from raycore.sensors import LIDAR_PRESETS

#: Bound of every coordinate and length a request gives (Embree's range, 1.844e18): squares and
#: products of such numbers still fit float32, so that no valid request overflows a kernel.
COORDINATE_LIMIT = 1.844e18
Coordinate = Annotated[float, Field(ge=-COORDINATE_LIMIT, le=COORDINATE_LIMIT)]
Vec3 = Annotated[list[Coordinate], Field(min_length=3, max_length=3)]
Face = Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=3, max_length=3)]
Radius = Annotated[float, Field(gt=0, le=COORDINATE_LIMIT)]
#: 3-vectors in answers: unbounded (they come from the scene's arithmetic).
Point = Annotated[list[float], Field(min_length=3, max_length=3)]
Row = Annotated[list[Coordinate], Field(min_length=4, max_length=4)]
#: For the lists a body may make long (rays, vertices, faces, objects): their validation stops
#: at the first bad item.  A body of a million bad rays took 27 s to refuse, holding the GIL, and
#: so every other request, while pydantic wrote a million errors into a 422 of some 200 MB; one
#: error says what is wrong as well.
FAIL_FAST = Field(fail_fast=True)
AFFINE_ROW = [0.0, 0.0, 0.0, 1.0]


def _affine(rows):
    if len(rows) == 4 and rows[3] != AFFINE_ROW:
        raise ValueError(f"the last row of a 4x4 transform must be {AFFINE_ROW}")
    return rows


def _affine_schema(schema):
    # the first three rows as any row, a fourth one only [0, 0, 0, 1]
    schema["prefixItems"] = [schema["items"]] * 3 + [{"const": AFFINE_ROW}]


Matrix = Annotated[list[Row], AfterValidator(_affine), Field(
    min_length=3, max_length=4, json_schema_extra=_affine_schema,
    description="Affine transform, row-major: 3x4, or 4x4 whose last row is [0, 0, 0, 1]; it "
                "must be invertible")]
DType = Literal["float32", "float64"]
TriangleTest = Literal["watertight", "moller", "geometric"]
QueryKind = Literal["closest", "any", "all", "count"]
SurfaceField = Literal["uv", "normal", "point", "shading_normal"]
Unit = Annotated[float, Field(ge=0, le=1)]
Byte = Annotated[int, Field(ge=0, le=255)]

IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
EXAMPLE_MESH_ID = "9f2c1e5d7a3b4c6d8e0f1a2b3c4d5e6f"
EXAMPLE_SCENE_ID = "0c5b7e2a9d1f4e3b8a6c2d0e1f3a5b7c"


class Strict(BaseModel):
    """Unknown keys and non-finite numbers are errors, not silently dropped or passed on."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class Error(BaseModel):
    """What was wrong with a request."""

    detail: str = Field(description="A sentence naming the offending part of the request")
    errors: list[dict] | None = Field(
        None, description="For malformed bodies: each problem's location, message and type")

    model_config = ConfigDict(json_schema_extra={"examples": [
        {"detail": "objects.0.sphere.radius: Input should be a valid number"}]})


# ---------------------------------------------------------------------- meshes


class Bounds(BaseModel):
    lo: Point
    hi: Point


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
    color: Annotated[list[Unit], Field(min_length=3, max_length=3)] = Field(
        description="Linear RGB in [0, 1], used by lambert renders")


class Shape(Strict):
    material: Material | None = None


class Sphere(Shape):
    type: Literal["sphere"]
    center: Vec3
    radius: Radius


class Plane(Shape):
    type: Literal["plane"]
    point: Vec3
    normal: Vec3


class Disk(Shape):
    type: Literal["disk"]
    center: Vec3
    normal: Vec3
    radius: Radius


class Box(Shape):
    type: Literal["box"]
    lo: Vec3
    hi: Vec3
    transform: Matrix = Field(default_factory=lambda: [row[:] for row in IDENTITY],
                              description="Affine transform of the box (default: none)")


class Cylinder(Shape):
    type: Literal["cylinder"]
    p0: Vec3
    p1: Vec3
    radius: Radius


class Cone(Shape):
    type: Literal["cone"]
    base_center: Vec3
    apex: Vec3
    radius: Radius


class MeshObject(Shape):
    """A triangle mesh: an uploaded mesh's id, or inline vertices and faces."""

    type: Literal["mesh"]
    mesh: str | None = Field(None, description="Id from POST /v1/meshes")
    vertices: Annotated[list[Vec3], Field(min_length=1), FAIL_FAST] | None = None
    faces: Annotated[list[Face], Field(min_length=1), FAIL_FAST] | None = Field(
        None, description="Indices into vertices, each below their count")

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
    objects: Annotated[list[SceneObject], FAIL_FAST]

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
    """How to query: as URL parameters, or in a JSON body (where the body's win)."""

    query: QueryKind = Field("closest", description=(
        "closest: the nearest hit; any: whether anything is hit (occlusion); all: every hit "
        "along each ray, sorted by t; count: the number of hits"))
    fields: Annotated[list[SurfaceField], Field(max_length=4)] = Field(
        [], description="Surface data of closest hits to return besides t and the ids (only "
                        "with query=closest): uv (barycentrics on triangles), normal (the unit "
                        "geometric normal), point, shading_normal (mesh vertex normals "
                        "interpolated with the barycentrics; the geometric normal elsewhere)")
    triangle_test: TriangleTest = "watertight"


class UrlOptions(QueryOptions):
    """Query options as URL parameters, for either body.  A JSON body's own options win over
    these, and so do the tmin and tmax columns of (N, 8) .npy rays."""

    tmin: float | None = Field(None, description="Default 0")
    tmax: float | None = Field(None, description="Default: no limit")

    model_config = ConfigDict(strict=False)  # URL parameters are text: "0.5" is a number here


class CameraBase(Strict):
    position: Vec3
    look_at: Vec3 = Field(description="Not equal to position")
    up: Vec3 = Field((0.0, 1.0, 0.0), description="Not parallel to look_at - position")
    width: Annotated[int, Field(ge=1)] = 512
    height: Annotated[int, Field(ge=1)] = 512


class PerspectiveCamera(CameraBase):
    type: Literal["perspective"]
    fov: Annotated[float, Field(gt=0, lt=180, description="Vertical, in degrees")] = 45.0


class OrthographicCamera(CameraBase):
    type: Literal["orthographic"]
    view_height: Annotated[float, Field(gt=0, le=COORDINATE_LIMIT, description="In scene units")]


class PerspectiveRays(PerspectiveCamera):
    """Pinhole camera rays, one per pixel in scanline order (raycore.sensors.perspective)."""


class OrthographicRays(OrthographicCamera):
    """Parallel camera rays, one per pixel in scanline order (raycore.sensors.orthographic)."""


Degrees = Annotated[float, Field(ge=-90, le=90)]
LidarPresetName = Literal[tuple(LIDAR_PRESETS)]


class LidarRays(Strict):
    """One revolution of a spinning multi-channel LiDAR (raycore.sensors.lidar): a
    (channels, columns) range image, channel by channel in the order of the elevations.  Its
    rays are unit length and start at min_range and stop at max_range, so that t is the range."""

    type: Literal["lidar"]
    position: Vec3
    forward: Vec3 = Field((1.0, 0.0, 0.0), description=(
        "Direction of the first column (made perpendicular to up); not parallel to up"))
    up: Vec3 = Field((0.0, 0.0, 1.0), description="Spin axis; not zero. Columns turn from "
                                                  "forward towards up x forward")
    preset: LidarPresetName | None = Field(None, description=(
        "A common sensor, as an approximation from its data sheet (channels evenly spread over "
        "its vertical field of view, 10 Hz columns, ranges in metres); the fields given "
        "besides it win"))
    elevations: Annotated[list[Degrees], Field(min_length=1), FAIL_FAST] | None = Field(
        None, description="Each channel's elevation in degrees; or vertical_fov and channels")
    vertical_fov: Annotated[list[Degrees], Field(min_length=2, max_length=2)] | None = Field(
        None, description="[lowest, highest] elevation in degrees, channels evenly spread")
    channels: Annotated[int, Field(ge=1)] | None = None
    horizontal_resolution: Annotated[float, Field(gt=0, le=360)] | None = Field(
        None, description="Degrees between columns; or columns")
    columns: Annotated[int, Field(ge=1)] | None = Field(
        None, description="Rays per channel in one revolution")
    min_range: Annotated[float, Field(ge=0, le=COORDINATE_LIMIT)] | None = Field(
        None, description="Default 0 (or the preset's)")
    max_range: Annotated[float, Field(gt=0, le=COORDINATE_LIMIT)] | None = Field(
        None, description="Above min_range; default: no limit (or the preset's)")
    point_cloud: bool = Field(False, description=(
        "Answer with the hit points only, in ray order: (M, 3) .npy in the scene's precision "
        "(Accept: application/x-npy), binary PLY of float32 vertices (Accept: model/ply) or "
        "JSON points (query=closest only)"))


class PointRays(Strict):
    """Sight lines from sources to targets (raycore.sensors.points), for visibility: direction
    target - source, so that t = 1 at the target, where the rays stop."""

    type: Literal["points"]
    sources: Annotated[list[Vec3], Field(min_length=1), FAIL_FAST]
    targets: Annotated[list[Vec3], Field(min_length=1, description=(
        "As many as sources, or either holds one point; each differs from its source")),
        FAIL_FAST]


SensorSpec = Annotated[PerspectiveRays | OrthographicRays | LidarRays | PointRays,
                       Field(discriminator="type")]


class IntersectRequest(QueryOptions):
    """A batch of rays as JSON, given (``origins`` and ``directions``) or generated by a sensor
    (``rays``); a hit lies at ``origin + t * direction``."""

    origins: Annotated[list[Vec3], FAIL_FAST] | None = Field(
        None, description="As many as directions; not with rays")
    directions: Annotated[list[Vec3], FAIL_FAST] | None = Field(
        None, description="Need not be unit length (but not zero); t is in their units")
    rays: SensorSpec | None = Field(None, description=(
        "Rays generated by the service, as raycore.sensors makes them in process, in place of "
        "origins and directions"))
    tmin: float | Annotated[list[float], FAIL_FAST] = Field(
        0.0, description="One for all rays, or one per ray")
    tmax: float | Annotated[list[float | None], FAIL_FAST] | None = Field(
        None, description="One for all rays, or one per ray; null: no limit")

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "origins": [[0, 1, -5], [0, 10, -5]], "directions": [[0, 0, 1], [0, 0, 1]],
        "tmin": 0, "tmax": None, "query": "closest", "fields": ["normal"],
        "triangle_test": "watertight"}]})

    @model_validator(mode="after")
    def _one_source(self):
        given = self.origins is not None or self.directions is not None
        if given == (self.rays is not None):
            raise ValueError("give either origins and directions, or rays")
        if given and (self.origins is None or self.directions is None):
            raise ValueError("origins and directions go together")
        if self.rays is not None and (isinstance(self.tmin, list)
                                      or isinstance(self.tmax, list)):
            raise ValueError("per-ray tmin and tmax go with origins and directions; with rays, "
                             "give one for all rays")
        return self


class IntersectResponse(BaseModel):
    """Per query: ``closest`` gives t, geom_id, prim_id and the asked fields (t and fields null,
    ids -1 where missed); ``any`` gives occluded; ``count`` gives count; ``all`` gives counts and,
    per hit in ray order, ray_index, t, geom_id and prim_id."""

    t: list[float | None] | None = None
    geom_id: list[int] | None = None
    prim_id: list[int] | None = None
    uv: list[Annotated[list[float], Field(min_length=2, max_length=2)] | None] | None = None
    normal: list[Point | None] | None = None
    point: list[Point | None] | None = None
    shading_normal: list[Point | None] | None = None
    occluded: list[bool] | None = None
    count: list[int] | None = None
    counts: list[int] | None = None
    ray_index: list[int] | None = None
    range: list[float | None] | None = Field(None, description="LiDAR rays: each return's "
                                                               "distance from the sensor")
    points: list[Point] | None = Field(None, description="LiDAR rays with point_cloud: the "
                                                         "hit points, in ray order")

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "t": [4.0, None], "geom_id": [1, -1], "prim_id": [0, -1],
        "normal": [[0.0, 0.0, -1.0], None]}]})


# ---------------------------------------------------------------------- render


class RenderRequest(Strict):
    """A camera and a shading; answered with an sRGB PNG, or for depth, normal and id with the
    data as .npy when the Accept header asks for application/x-npy."""

    camera: Annotated[PerspectiveCamera | OrthographicCamera, Field(discriminator="type")]
    shading: Literal["depth", "normal", "lambert", "id"] = "lambert"
    samples: Annotated[int, Field(ge=1, le=MAX_SAMPLES)] = Field(1, description=(
        "Rays per pixel, each jittered within a stratum of the pixel, averaged in linear light "
        "(anti-aliasing); .npy answers trace one ray per pixel centre"))
    smooth: bool = Field(True, description=(
        "Shade meshes with their vertex normals interpolated across faces (normal, lambert; "
        "and the .npy normals); their face normals when false"))
    light_direction: Vec3 = Field((0.4, 1.0, 0.6),
                                  description="Towards the light (lambert); not zero")
    ambient: Unit = 0.15
    background: Annotated[list[Byte], Field(min_length=3, max_length=3)] = Field(
        (0, 0, 0), description="RGB of missed pixels")
    triangle_test: TriangleTest = "watertight"

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "camera": {"type": "perspective", "position": [6, 4, -8], "look_at": [0, 1, 0],
                   "up": [0, 1, 0], "fov": 45, "width": 512, "height": 384},
        "shading": "lambert", "samples": 4, "light_direction": [0.4, 1.0, 0.6]}]})


# ---------------------------------------------------------------------- listings


class Stored(BaseModel):
    """One stored mesh or scene."""

    id: str
    bytes: int = Field(description="Memory it holds, as charged to the store's budget")
    last_used: datetime = Field(description="When it was last stored, described or queried (UTC)")


class Listing(BaseModel):
    """A page of stored meshes or scenes, ordered by id (stable between pages)."""

    items: list[Stored]
    total: int = Field(description="How many there are in all")
    next_offset: int | None = Field(description="offset of the next page; null on the last")

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "items": [{"id": EXAMPLE_SCENE_ID, "bytes": 33568,
                   "last_used": "2025-01-01T12:00:00Z"}], "total": 1, "next_offset": None}]})


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
    406: ("No such answer type for this request",
          {"detail": "a lambert render is answered as image/png only; .npy answers are for "
                     "depth, normal and id"}),
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
