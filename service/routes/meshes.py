"""Mesh uploads: a file's raw bytes or a multipart form, parsed by trimesh, stored by content."""

from pathlib import PurePath
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response

from service.auth import require_api_key
from service.builder import MESH_FORMATS, parse_mesh
from service.errors import ClientError, UnsupportedMedia
from service.runtime import Runtime, runtime
from service.schemas import MESH_LINKS, MeshInfo, error_responses

router = APIRouter(prefix="/v1/meshes", tags=["meshes"])

#: Content types that name a mesh format (the ``format`` parameter overrides them).
MEDIA_TYPES = {"model/obj": "obj", "model/stl": "stl", "application/sla": "stl",
               "model/ply": "ply", "application/ply": "ply", "model/off": "off",
               "model/gltf-binary": "glb"}

_TRIANGLE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
_UPLOAD_BODY = {"content": {
    **{media: {"schema": {"type": "string", "format": "binary"}, "example": _TRIANGLE_OBJ}
       for media in ("model/obj", "application/octet-stream")},
    **{media: {"schema": {"type": "string", "format": "binary"},
               "example": "<the file's bytes>"}
       for media in ("model/stl", "model/ply", "model/off", "model/gltf-binary")},
    "multipart/form-data": {
        "schema": {"type": "object", "required": ["file"],
                   "properties": {"file": {"type": "string", "format": "binary"}}},
        "example": {"file": "bunny.ply"}}},
    "description": "The mesh file: its raw bytes (format from the format parameter or the "
                   "Content-Type), or a multipart form whose 'file' part has a file name with "
                   "the format's extension.", "required": True}
_FORMAT_DOC = (f"File format, one of {', '.join(MESH_FORMATS)}; needed when the Content-Type "
               "or the file name does not say")


def _file_type(given, media_type, filename=None):
    """The upload's format: the parameter, else the file name's extension, else the media type."""
    if given is not None:
        return given.lower()
    if filename and PurePath(filename).suffix:
        return PurePath(filename).suffix[1:].lower()
    if MEDIA_TYPES.get(media_type) is None:
        raise UnsupportedMedia(f"cannot tell the mesh format from Content-Type {media_type!r}: "
                               f"add ?format= (one of {', '.join(MESH_FORMATS)})")
    return MEDIA_TYPES[media_type]


@router.post("", status_code=201, response_model=MeshInfo, summary="Upload a mesh file",
             openapi_extra={"requestBody": _UPLOAD_BODY}, dependencies=[Depends(require_api_key)],
             responses={201: {"links": MESH_LINKS},
                        200: {"model": MeshInfo, "description": "The same mesh was stored already",
                              "links": MESH_LINKS},
                        **error_responses(400, 401, 408, 413, 415, 422)})
async def upload_mesh(request: Request, response: Response,
                      state: Annotated[Runtime, Depends(runtime)],
                      file_format: Annotated[str | None, Query(alias="format",
                                                               description=_FORMAT_DOC)] = None):
    media_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media_type == "multipart/form-data":
        async with request.form(max_files=1, max_fields=1) as form:
            upload = form.get("file")
            if upload is None or isinstance(upload, str):
                raise ClientError("the multipart form needs a 'file' part holding the mesh file")
            file_type = _file_type(file_format, upload.content_type, upload.filename)
            data = await upload.read()
    else:
        file_type = _file_type(file_format, media_type)
        data = await request.body()
    entry = await state.compute(parse_mesh, data, file_type, state.settings.max_triangles)
    entry, created = state.store.put("mesh", entry.info.id, entry, entry.nbytes)
    if not created:
        response.status_code = 200
    return entry.info


@router.get("/{mesh_id}", response_model=MeshInfo, summary="Describe an uploaded mesh",
            responses=error_responses(404, 422))
async def get_mesh(mesh_id: str, state: Annotated[Runtime, Depends(runtime)]):
    return (await state.get("mesh", mesh_id)).info


@router.delete("/{mesh_id}", status_code=204, summary="Forget an uploaded mesh",
               dependencies=[Depends(require_api_key)], responses=error_responses(401, 404, 422))
async def delete_mesh(mesh_id: str, state: Annotated[Runtime, Depends(runtime)]):
    state.delete("mesh", mesh_id)
