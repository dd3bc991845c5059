"""Scenes: create from JSON, describe, delete; intersect ray batches; render PNGs."""

from typing import Annotated

import numpy as np
from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from raycore.camera import orthographic_rays, perspective_rays
from raycore.render import render
from service import codecs
from service.auth import require_api_key
from service.bodies import read_body
from service.builder import build_scene, scene_id
from service.demo import DEMO_CAMERA
from service.errors import ClientError, LimitExceeded, UnsupportedMedia
from service.runtime import Runtime, runtime
from service.schemas import (
    SCENE_LINKS,
    IntersectRequest,
    IntersectResponse,
    NpyOptions,
    RenderRequest,
    SceneInfo,
    SceneSpec,
    error_responses,
)

router = APIRouter(prefix="/v1/scenes", tags=["scenes"])
State = Annotated[Runtime, Depends(runtime)]

_BINARY = {"type": "string", "format": "binary"}
_NPY_RAYS = ("<.npy bytes: float32 or float64 array of shape (N, 6) or (N, 8), each row origin, "
             "direction[, tmin, tmax]>")
_NPY_HITS = ("<.npy bytes: structured array, one row per ray (per hit for query=all); closest: "
             "t, geom_id (int32), prim_id (int32) and the asked fields>")


@router.post("", status_code=201, response_model=SceneInfo, summary="Build a scene",
             dependencies=[Depends(require_api_key)],
             responses={201: {"links": SCENE_LINKS},
                        200: {"model": SceneInfo, "description": "Built already",
                              "links": SCENE_LINKS},
                        **error_responses(400, 401, 408, 413, 422)})
async def create_scene(spec: SceneSpec, response: Response, state: State):
    def build():
        key = scene_id(spec)
        existing = state.store.get("scene", key)
        if existing is not None:
            return existing, False
        entry, held = build_scene(spec, lambda mesh: state.store.get("mesh", mesh),
                                  state.settings.max_triangles)
        return state.store.put("scene", key, entry, held)

    entry, created = await state.compute(build)
    if not created:
        response.status_code = 200
    return entry.info


@router.get("/{scene_id}", response_model=SceneInfo, summary="Describe a scene",
            description="`demo` names the built-in demo scene.",
            responses=error_responses(404, 422))
async def get_scene(scene_id: str, state: State):
    return (await state.get("scene", scene_id)).info


@router.delete("/{scene_id}", status_code=204, summary="Forget a scene",
               dependencies=[Depends(require_api_key)], responses=error_responses(401, 404, 422))
async def delete_scene(scene_id: str, state: State):
    state.delete("scene", scene_id)


@router.post(
    "/{scene_id}/intersect", response_model=IntersectResponse, summary="Cast a batch of rays",
    description=(
        "Rays as JSON (query options in the body), or as .npy (`Content-Type: "
        "application/x-npy`, query options as URL parameters). The answer is JSON, or .npy when "
        "the Accept header asks for application/x-npy."),
    openapi_extra={
        "requestBody": {"required": True, "content": {
            "application/json": {"schema": IntersectRequest.model_json_schema()},
            codecs.NPY: {"schema": _BINARY, "example": _NPY_RAYS}}},
        "responses": {"200": {"content": {codecs.NPY: {"schema": _BINARY,
                                                       "example": _NPY_HITS}}}}},
    responses=error_responses(400, 404, 408, 413, 415, 422))
async def intersect(scene_id: str, request: Request, state: State,
                    options: Annotated[NpyOptions, Query()]):
    entry = await state.get("scene", scene_id)
    media_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media_type not in ("application/json", codecs.NPY):
        raise UnsupportedMedia("Content-Type must be application/json or application/x-npy, "
                               f"got {media_type or 'none'}")
    if media_type == "application/json" and request.query_params:
        raise ClientError("with a JSON body, query options go in the body, not the URL")
    body = await (read_body(request) if media_type == codecs.NPY else request.body())
    as_npy = codecs.accepts_npy(request.headers.get("accept", ""))
    max_rays = state.settings.max_rays

    def answer():
        if media_type == codecs.NPY:
            rays, query = codecs.rays_from_npy(codecs.read_npy(body), options.tmin,
                                               options.tmax), options
        else:
            try:
                query = IntersectRequest.model_validate_json(body)
            except ValidationError as error:
                raise RequestValidationError(
                    [{**problem, "loc": ("body", *problem["loc"])}
                     for problem in error.errors(include_url=False)]) from error
            rays = codecs.rays_from_json(query)
        if len(rays[0]) > max_rays:
            raise LimitExceeded(f"{len(rays[0])} rays in one request; the limit is {max_rays}")
        columns = codecs.result_columns(query.query, run_query(entry.scene, rays, query))
        return codecs.columns_to_npy(columns) if as_npy else codecs.columns_to_json(columns)

    content = await state.compute(answer)
    return Response(content, media_type=codecs.NPY if as_npy else "application/json")


def run_query(scene, rays, options):
    """Answer ``options.query`` for ``rays`` (origins, directions, tmin, tmax) with ``scene``.

    Returns
    -------
    Hits (closest), AllHits (all), (N,) bool (any) or (N,) int64 (count)

    Raises
    ------
    ClientError
        With the library's message for rays it refuses.
    """
    if options.fields and options.query != "closest":
        raise ClientError(f"fields apply to closest-hit queries, not query={options.query}")
    test = options.triangle_test
    try:
        if options.query == "closest":
            return scene.intersect(*rays, triangle_test=test, fields=options.fields)
        if options.query == "any":
            return scene.occluded(*rays, triangle_test=test)
        if options.query == "all":
            return scene.intersect_all(*rays, triangle_test=test)
        return scene.count(*rays, triangle_test=test)
    except ValueError as error:
        raise ClientError(str(error)) from error


@router.post(
    "/{scene_id}/render", response_class=Response, summary="Render a PNG image",
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
    if pixels > limit:
        raise LimitExceeded(f"{camera.width}x{camera.height} is {pixels} pixels; the limit is "
                            f"{limit}")

    def draw():
        view = (camera.position, camera.look_at, camera.up)
        try:
            size = (camera.width, camera.height, entry.scene.dtype)
            if camera.type == "perspective":
                rays = perspective_rays(*view, camera.fov, *size)
            else:
                rays = orthographic_rays(*view, camera.view_height, *size)
            image = render(entry.scene, *rays, camera.width, camera.height, spec.shading,
                           light_direction=spec.light_direction, colors=entry.colors,
                           background=np.asarray(spec.background), ambient=spec.ambient,
                           triangle_test=spec.triangle_test)
        except ValueError as error:
            raise ClientError(str(error)) from error
        return codecs.png(image)

    return Response(await state.compute(draw), media_type="image/png")
