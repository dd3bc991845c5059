"""Scenes: create from JSON, list, describe, delete; intersect ray batches; render PNGs.

Two routers: ``router`` (reading, queries, renders) is always open; ``guarded`` (builds,
deletions) changes the store, and the app includes it behind the API key when one is configured.
"""

from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from service import codecs
from service.answers import render_image, run_query
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

router = APIRouter(prefix="/v1/scenes", tags=["scenes"])
guarded = APIRouter(prefix="/v1/scenes", tags=["scenes"])
State = Annotated[Runtime, Depends(runtime)]

_BINARY = {"type": "string", "format": "binary"}
_NPY_RAYS = ("<.npy bytes: float32 or float64 array of shape (N, 6) or (N, 8), each row origin, "
             "direction[, tmin, tmax]>")
_NPY_HITS = ("<.npy bytes: structured array, one row per ray (per hit for query=all); closest: "
             "t, geom_id (int32), prim_id (int32) and the asked fields>")


_BUILD_RULES = (
    "Rules that the schema does not state, answered with 422: a box's lo is below its hi on "
    "every axis; transforms are invertible; plane and disk normals, cylinder axes (p1 - p0) and "
    "cone axes (apex - base_center) are not zero; a mesh object gives either mesh or both "
    "vertices and faces, and its faces index its vertices; an instance's mesh index names an "
    "earlier mesh object; a float32 scene's numbers fit float32.  A mesh id that names no "
    "uploaded mesh is answered 404.  The whole scene stores at most the configured number of "
    "triangles (413).")


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
                                  state.settings.max_triangles)
        return state.keep("scene", key, entry, held)

    entry, created = await state.compute(build)
    if not created:
        response.status_code = 200
    return entry.info


@router.get("", response_model=Listing, summary="List the stored scenes",
            description="The demo scene is listed under its content id.",
            responses=error_responses(422))
async def list_scenes(state: State, limit: Limit = 100, offset: Offset = 0):
    return page(state.listing("scene"), limit, offset)


@router.get("/{scene_id}", response_model=SceneInfo, summary="Describe a scene",
            description="`demo` names the built-in demo scene.",
            responses=error_responses(404, 422))
async def get_scene(scene_id: str, state: State):
    return (await state.get("scene", scene_id)).info


@guarded.delete("/{scene_id}", status_code=204, summary="Forget a scene",
                responses=error_responses(404, 422))
async def delete_scene(scene_id: str, state: State):
    state.delete("scene", scene_id)


_INTERSECT = (
    "Rays as JSON, or as .npy (`Content-Type: application/x-npy`). Query options may be given "
    "as URL parameters with either body; where a JSON body gives an option too, the body's "
    "wins, and (N, 8) .npy rays' own tmin and tmax columns win over the URL's. The answer is "
    "JSON, or .npy when the Accept header asks for application/x-npy.\n\n"
    "Rules that the schema does not state, answered with 422: origins and directions are as "
    "many, and so are per-ray tmin and tmax; no direction is zero; fields only go with "
    "query=closest; a .npy body is a float32 or float64 array of shape (N, 6) or (N, 8) "
    "without NaN, and its origins and directions finite (400 when it is not an .npy file).")


@router.post(
    "/{scene_id}/intersect", response_model=IntersectResponse, summary="Cast a batch of rays",
    description=_INTERSECT,
    openapi_extra={
        "requestBody": {"required": True, "content": {
            "application/json": {"schema": {"$ref": "#/components/schemas/IntersectRequest"}},
            codecs.NPY: {"schema": _BINARY, "example": _NPY_RAYS}}},
        "responses": {"200": {"content": {codecs.NPY: {"schema": _BINARY,
                                                       "example": _NPY_HITS}}}}},
    responses=error_responses(400, 404, 408, 413, 415, 422))
async def intersect(scene_id: str, request: Request, state: State,
                    options: Annotated[UrlOptions, Query()]):
    entry = await state.get("scene", scene_id)
    media_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media_type not in ("application/json", codecs.NPY):
        raise UnsupportedMedia("Content-Type must be application/json or application/x-npy, "
                               f"got {media_type or 'none'}")
    body = await (read_body(request) if media_type == codecs.NPY else request.body())
    as_npy = codecs.accepts_npy(request.headers.get("accept", ""))
    in_url = set(request.query_params) & set(UrlOptions.model_fields)
    max_rays = state.settings.max_rays

    def answer():
        if media_type == codecs.NPY:
            rays, query = codecs.rays_from_npy(codecs.read_npy(body), options.tmin,
                                               options.tmax), options
        else:
            query = _with_url_options(_parse_json(IntersectRequest, body), options, in_url)
            if max(len(query.origins), len(query.directions)) > max_rays:
                # a maxItems of the document's schema: refused as invalid, not as too large
                raise ClientError(f"body.origins: {len(query.origins)} rays in one request; "
                                  f"the limit is {max_rays}")
            rays = codecs.rays_from_json(query)
        if len(rays[0]) > max_rays:
            raise LimitExceeded(f"{len(rays[0])} rays in one request; the limit is {max_rays}")
        columns = codecs.result_columns(query.query, run_query(entry.scene, rays, query))
        return codecs.columns_to_npy(columns) if as_npy else codecs.columns_to_json(columns)

    content = await state.compute(answer)
    return Response(content, media_type=codecs.NPY if as_npy else "application/json")


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
    "Rules that the schema does not state: width x height is at most the configured pixel "
    "limit (413); look_at differs from position, up is not parallel to the view direction, and "
    "light_direction is not zero (422).")


@router.post(
    "/{scene_id}/render", response_class=Response, summary="Render a PNG image",
    description=_RENDER,
    openapi_extra={"requestBody": {"content": {"application/json": {"examples": {
        "demo": {"summary": "The demo scene, lit, with shadows",
                 "value": {"camera": DEMO_CAMERA, "shading": "lambert"}}}}}}},
    responses={200: {"description": "The image", "content": {
        "image/png": {"schema": _BINARY, "example": "<PNG bytes>"}}},
        **error_responses(400, 404, 408, 413, 422)})
async def render_scene(scene_id: str, spec: RenderRequest, state: State):
    entry = await state.get("scene", scene_id)
    camera = spec.camera
    pixels, limit = camera.width * camera.height, state.settings.max_render_pixels
    for side in ("width", "height"):  # the document's maxima: invalid, not too large
        if getattr(camera, side) > limit:
            raise ClientError(f"body.camera.{side}: at most {limit}, the pixel limit")
    if pixels > limit:
        raise LimitExceeded(f"{camera.width}x{camera.height} is {pixels} pixels; the limit is "
                            f"{limit}")

    def draw():
        return codecs.png(render_image(entry.scene, entry.colors, spec))

    return Response(await state.compute(draw), media_type="image/png")
