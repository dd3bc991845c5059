"""Scenes: create from JSON, list, describe, delete; intersect ray batches; render PNGs.

Two routers: ``router`` (reading, queries, renders) is always open; ``guarded`` (builds,
deletions) changes the store, and the app includes it behind the API key when one is configured.
"""

import time
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from service import codecs
from service.answers import encode_columns, lidar_answer, render_data, render_image, run_query
from service.bodies import read_body
from service.builder import build_scene, scene_id
from service.demo import DEMO_CAMERA
from service.errors import ClientError, LimitExceeded, UnsupportedMedia
from service.listing import Limit, Offset, page
from service.runtime import Runtime, runtime
from service.schemas import (
    SCENE_LINKS,
    IntersectRequest,
    IntersectResponse,
    Listing,
    RenderRequest,
    SceneInfo,
    SceneSpec,
    UrlOptions,
    error_responses,
)
from service.sensors import bounded, sensor_rays

router = APIRouter(prefix="/v1/scenes", tags=["scenes"])
guarded = APIRouter(prefix="/v1/scenes", tags=["scenes"])
State = Annotated[Runtime, Depends(runtime)]

_BINARY = {"type": "string", "format": "binary"}
_NPY_RAYS = ("<.npy bytes: float32 or float64 array of shape (N, 6) or (N, 8), each row origin, "
             "direction[, tmin, tmax]>")
_NPY_HITS = ("<.npy bytes: structured array, one row per ray (per hit for query=all); closest: "
             "t, geom_id (int32), prim_id (int32) and the asked fields; or, for a LiDAR's "
             "point_cloud, an (M, 3) float array of its hit points>")
_PLY_POINTS = "<binary PLY bytes: the hit points of a LiDAR's point_cloud, as vertices>"
_SENSOR_EXAMPLES = {
    "rays": {"summary": "Rays given one by one",
             "value": {"origins": [[0, 1, -5], [0, 10, -5]],
                       "directions": [[0, 0, 1], [0, 0, 1]], "fields": ["normal"]}},
    "lidar": {"summary": "A 16-channel LiDAR 1.8 units above the ground, y up",
              "value": {"rays": {"type": "lidar", "preset": "velodyne-vlp16",
                                 "position": [0, 1.8, -6], "forward": [0, 0, 1],
                                 "up": [0, 1, 0]}}},
    "camera": {"summary": "Perspective camera rays, as the render endpoint's camera makes them",
               "value": {"rays": {"type": "perspective", "position": [7, 5, -9],
                                  "look_at": [0, 1, 0], "width": 64, "height": 48},
                         "fields": ["normal"]}},
    "visibility": {"summary": "Is each target visible from the source?",
                   "value": {"query": "any", "rays": {
                       "type": "points", "sources": [[0, 5, -8]],
                       "targets": [[0, 1, 0], [3, 0.5, 2]]}}},
}


_BUILD_RULES = (
    "Rules that the schema does not state, answered with 422: a box's lo is below its hi on "
    "every axis; transforms are invertible; plane and disk normals, cylinder axes (p1 - p0) and "
    "cone axes (apex - base_center) are not zero; a mesh object gives either mesh or both "
    "vertices and faces, and its faces index its vertices; an instance's mesh index names an "
    "earlier mesh object; a float32 scene's numbers fit float32.  A mesh id that names no "
    "uploaded mesh is answered 404.  The whole scene stores at most the configured numbers of "
    "triangles and of planes (413).")


@guarded.post("", status_code=201, response_model=SceneInfo, summary="Build a scene",
              description=_BUILD_RULES,
              responses={201: {"links": SCENE_LINKS},
                         200: {"model": SceneInfo, "description": "Built already",
                               "links": SCENE_LINKS},
                         **error_responses(400, 404, 408, 413, 422)})
async def create_scene(spec: SceneSpec, response: Response, state: State):
    def build():
        key = scene_id(spec)
        existing = state.find("scene", key)
        if existing is not None:
            return existing, False
        entry, held = build_scene(spec, lambda mesh: state.find("mesh", mesh),
                                  state.settings.max_triangles, state.settings.max_planes)
        return state.keep("scene", key, entry, held)

    entry, created = await state.compute(build)
    if not created:
        response.status_code = 200
    return entry.info


@router.get("", response_model=Listing, summary="List the stored scenes",
            description="The demo scene is listed under its content id.",
            responses=error_responses(422))
def list_scenes(state: State, limit: Limit = 100, offset: Offset = 0):
    # run in a worker thread, off the event loop, as list_meshes
    return page(state.listing("scene"), limit, offset)


@router.get("/{scene_id}", response_model=SceneInfo, summary="Describe a scene",
            description="`demo` names the built-in demo scene.",
            responses=error_responses(404, 422))
async def get_scene(scene_id: str, state: State):
    return (await state.get("scene", scene_id)).info


@guarded.delete("/{scene_id}", status_code=204, summary="Forget a scene",
                responses=error_responses(404, 422))
def delete_scene(scene_id: str, state: State):
    state.delete("scene", scene_id)


_INTERSECT = (
    "Rays as JSON, or as .npy (`Content-Type: application/x-npy`), or generated by the service "
    "from a sensor described in a JSON body's `rays` (perspective or orthographic camera, "
    "spinning LiDAR, or sight lines between points), exactly as `raycore.sensors` makes them in "
    "process. Query options may be given as URL parameters with either body; where a JSON body "
    "gives an option too, the body's wins, and (N, 8) .npy rays' own tmin and tmax columns win "
    "over the URL's; with `rays`, tmin and tmax narrow the sensor's own range. The answer is "
    "JSON, or .npy when the Accept header asks for application/x-npy. LiDAR rays' closest hits "
    "also give each return's `range` and hit `point`; with `point_cloud` the answer is the hit "
    "points alone, as an (M, 3) .npy array, a binary PLY (`Accept: model/ply`) or JSON "
    "`points`.\n\n"
    "Rules that the schema does not state, answered with 422: a JSON body gives either origins "
    "and directions, or rays; origins and directions are as many, and so are per-ray tmin and "
    "tmax (which go with origins and directions only); no direction is zero; fields and "
    "point_cloud only go with query=closest; a camera's look_at differs from its position and "
    "its up is not parallel to the view; a LiDAR gives either elevations or vertical_fov (lowest "
    "first) with channels, and either horizontal_resolution or columns, unless its preset "
    "does, its forward is not parallel to up and its max_range is above its min_range; points' "
    "sources and targets are as many or either is one point, and each target differs from its "
    "source; a .npy body is a float32 or float64 array of shape (N, 6) or (N, 8) without NaN, "
    "and its origins and directions finite (400 when it is not an .npy file). The rays that "
    "`rays` makes (a camera's width x height, a LiDAR's channels x columns) are at most the "
    "configured ray limit (413).")


@router.post(
    "/{scene_id}/intersect", response_model=IntersectResponse, summary="Cast a batch of rays",
    description=_INTERSECT,
    openapi_extra={
        "requestBody": {"required": True, "content": {
            "application/json": {"schema": {"$ref": "#/components/schemas/IntersectRequest"},
                                 "examples": _SENSOR_EXAMPLES},
            codecs.NPY: {"schema": _BINARY, "example": _NPY_RAYS}}},
        "responses": {"200": {"content": {codecs.NPY: {"schema": _BINARY,
                                                       "example": _NPY_HITS},
                                          codecs.PLY: {"schema": _BINARY,
                                                       "example": _PLY_POINTS}}}}},
    responses=error_responses(400, 404, 408, 413, 415, 422))
async def intersect(scene_id: str, request: Request, state: State,
                    options: Annotated[UrlOptions, Query()]):
    entry = await state.get("scene", scene_id)
    media_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media_type not in ("application/json", codecs.NPY):
        raise UnsupportedMedia("Content-Type must be application/json or application/x-npy, "
                               f"got {media_type or 'none'}")
    start = time.perf_counter()
    body = await (read_body(request) if media_type == codecs.NPY else request.body())
    received = time.perf_counter()
    accept = request.headers.get("accept", "")
    in_url = set(request.query_params) & set(UrlOptions.model_fields)
    max_rays, max_hits = state.settings.max_rays, state.settings.max_hits

    def answer():
        sensor = None
        if media_type == codecs.NPY:
            rays, query = codecs.rays_from_npy(codecs.read_npy(body), options.tmin,
                                               options.tmax), options
        else:
            query = _with_url_options(_parse_json(IntersectRequest, body), options, in_url)
            sensor = query.rays
            if sensor is not None:
                rays = bounded(sensor_rays(sensor, entry.scene.dtype, max_rays), query.tmin,
                               query.tmax)
            elif max(len(query.origins), len(query.directions)) > max_rays:
                # a maxItems of the document's schema: refused as invalid, not as too large
                raise ClientError(f"body.origins: {len(query.origins)} rays in one request; "
                                  f"the limit is {max_rays}")
            else:
                rays = codecs.rays_from_json(query)
        if len(rays[0]) > max_rays:
            raise LimitExceeded(f"{len(rays[0])} rays in one request; the limit is {max_rays}")
        if sensor is not None and sensor.type == "lidar":
            return lidar_answer(entry.scene, rays, query, sensor.point_cloud, accept, max_hits)
        columns = codecs.result_columns(query.query,
                                        run_query(entry.scene, rays, query, max_hits))
        return encode_columns(columns, accept)

    content, answer_type = await state.compute(answer)
    # where the service's time went: receiving the body, and the rays' work (with its wait for
    # a compute slot)
    timing = (f"body;dur={1000 * (received - start):.1f}, "
              f"compute;dur={1000 * (time.perf_counter() - received):.1f}")
    return Response(content, media_type=answer_type, headers={"server-timing": timing})


def _parse_json(model, body):
    """``model`` from JSON bytes; its errors answered as FastAPI answers a body's (422)."""
    try:
        return model.model_validate_json(body)
    except ValidationError as error:
        raise RequestValidationError(
            [{**problem, "loc": ("body", *problem["loc"])}
             for problem in error.errors(include_url=False)]) from error


def _with_url_options(request, options, in_url):
    """``request`` with the URL's options (the names in ``in_url``) where it gives none."""
    return request.model_copy(update={name: getattr(options, name)
                                      for name in in_url - request.model_fields_set})


_RENDER = (
    "An sRGB PNG: each pixel the mean, in linear light, of `samples` rays jittered within "
    "strata of it; meshes shaded smooth from their vertex normals unless `smooth` is false. "
    "With `Accept: application/x-npy`, depth, normal and id renders answer with their data "
    "instead, one ray per pixel centre, as .npy: depth an (H, W) array of t (inf for misses), "
    "normal (H, W, 3) unit normals as intersect's normal or shading_normal (NaN for misses), "
    "id (H, W) int32 geometry ids (-1 for misses); a lambert render asked for .npy is answered "
    "406.\n\n"
    "Rules that the schema does not state: width x height x samples is at most the configured "
    "pixel limit (413); look_at differs from position, up is not parallel to the view "
    "direction, and light_direction is not zero (422).")
_NPY_RENDER = ("<.npy bytes: depth (H, W) float, normal (H, W, 3) float in the scene's "
               "precision, or id (H, W) int32>")


@router.post(
    "/{scene_id}/render", response_class=Response, summary="Render a PNG image",
    description=_RENDER,
    openapi_extra={"requestBody": {"content": {"application/json": {"examples": {
        "demo": {"summary": "The demo scene, lit, with shadows",
                 "value": {"camera": DEMO_CAMERA, "shading": "lambert"}}}}}}},
    responses={200: {"description": "The image, or its data", "content": {
        "image/png": {"schema": _BINARY, "example": "<PNG bytes>"},
        codecs.NPY: {"schema": _BINARY, "example": _NPY_RENDER}}},
        **error_responses(400, 404, 406, 408, 413, 422)})
async def render_scene(scene_id: str, spec: RenderRequest, request: Request, state: State):
    entry = await state.get("scene", scene_id)
    camera = spec.camera
    pixels, limit = camera.width * camera.height, state.settings.max_render_pixels
    for side in ("width", "height"):  # the document's maxima: invalid, not too large
        if getattr(camera, side) > limit:
            raise ClientError(f"body.camera.{side}: at most {limit}, the pixel limit")
    if pixels * spec.samples > limit:
        raise LimitExceeded(f"{camera.width}x{camera.height} pixels x {spec.samples} samples "
                            f"is {pixels * spec.samples} rays; the limit is {limit}")
    data = codecs.accepts_npy(request.headers.get("accept", ""))

    def draw():
        if data:
            return render_data(entry.scene, spec), codecs.NPY
        return codecs.png(render_image(entry.scene, entry.colors, spec)), "image/png"

    content, media_type = await state.compute(draw)
    return Response(content, media_type=media_type)
