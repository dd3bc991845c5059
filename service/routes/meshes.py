"""Mesh uploads: a file's raw bytes or a multipart form, parsed by trimesh, stored by content.

Two routers: ``router`` (reading) is always open; ``guarded`` (uploads, deletions) changes the
store, and the app includes it behind the API key when one is configured.
"""

from pathlib import PurePath
from typing import Annotated, Literal

import anyio
from fastapi import APIRouter, Depends, Query, Request, Response

from service.builder import MESH_FORMATS, parse_mesh
from service.errors import ClientError, UnsupportedMedia
from service.listing import Limit, Offset, page
from service.runtime import Runtime, runtime
from service.schemas import MESH_LINKS, Listing, MeshInfo, error_responses

router = APIRouter(prefix="/v1/meshes", tags=["meshes"])
guarded = APIRouter(prefix="/v1/meshes", tags=["meshes"])

#: Content types that name a mesh format (they win over the ``format`` parameter).
MEDIA_TYPES = {"model/obj": "obj", "model/stl": "stl", "application/sla": "stl",
               "model/ply": "ply", "application/ply": "ply", "model/off": "off",
               "model/gltf-binary": "glb"}

_TRIANGLE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
_BINARY = {"type": "string", "format": "binary"}
_UPLOAD_BODY = {"content": {
    **{media: {"schema": _BINARY, "example": _TRIANGLE_OBJ} for media in ("model/obj",)},
    **{media: {"schema": _BINARY, "example": "<the file's bytes>"}
       for media in MEDIA_TYPES if media != "model/obj"},
    "multipart/form-data": {
        "schema": {"type": "object", "required": ["file"], "additionalProperties": False,
                   "properties": {"file": _BINARY}},
        "encoding": {"file": {"contentType": ", ".join(MEDIA_TYPES)}},
        "example": {"file": _TRIANGLE_OBJ}}},
    "description": "The mesh file: its raw bytes, or a multipart form whose one part, 'file', "
                   "holds it.  Its format is the first of: the Content-Type (of the part, in a "
                   "form) where it names one, the part's file name extension, the format "
                   "parameter (for bodies of other types, e.g. application/octet-stream).  The "
                   "file must hold at least one triangle, every face must index its vertices, "
                   "and vertices must be finite.", "required": True}
_FORMAT_DOC = (f"File format, one of {', '.join(MESH_FORMATS)}, for a body whose Content-Type "
               "(or form part) does not name one; a Content-Type or file name that names one wins")


def _file_type(given, media_type, filename=None):
    """The upload's format: the media type's, else the file name extension's, else the
    parameter's (see ``_UPLOAD_BODY``)."""
    media_type = (media_type or "").split(";")[0].strip().lower()
    if media_type in MEDIA_TYPES:
        return MEDIA_TYPES[media_type]
    extension = PurePath(filename).suffix[1:].lower() if filename else ""
    if extension in MESH_FORMATS:
        return extension
    if given is not None:
        return given
    raise UnsupportedMedia(f"cannot tell the mesh format from Content-Type {media_type!r}"
                           + (f" or file name {filename!r}" if filename else "")
                           + f": add ?format= (one of {', '.join(MESH_FORMATS)})")


@guarded.post("", status_code=201, response_model=MeshInfo, summary="Upload a mesh file",
              openapi_extra={"requestBody": _UPLOAD_BODY},
              responses={201: {"links": MESH_LINKS},
                         200: {"model": MeshInfo, "description": "The same mesh was stored "
                                                                "already", "links": MESH_LINKS},
                         **error_responses(400, 408, 413, 415, 422)})
async def upload_mesh(request: Request, response: Response,
                      state: Annotated[Runtime, Depends(runtime)],
                      file_format: Annotated[Literal[MESH_FORMATS] | None,
                                             Query(alias="format", description=_FORMAT_DOC)]
                      = None):
    media_type = request.headers.get("content-type", "")
    if media_type.split(";")[0].strip().lower() == "multipart/form-data":
        async with request.form(max_files=1, max_fields=0) as form:
            upload = form.get("file")
            if upload is None or isinstance(upload, str):
                raise ClientError("the multipart form needs a 'file' part holding the mesh file")
            file_type = _file_type(file_format, upload.content_type, upload.filename)
            data = await upload.read()
    else:
        file_type = _file_type(file_format, media_type)
        data = await request.body()
    entry = await state.compute(parse_mesh, data, file_type, state.settings.max_triangles)
    # a thread: with a data directory, keeping it writes and flushes a file
    entry, created = await anyio.to_thread.run_sync(state.keep, "mesh", entry.info.id, entry,
                                                    entry.nbytes)
    if not created:
        response.status_code = 200
    return entry.info


@router.get("", response_model=Listing, summary="List the stored meshes",
            responses=error_responses(422))
def list_meshes(state: Annotated[Runtime, Depends(runtime)], limit: Limit = 100,
                offset: Offset = 0):
    # a plain function, which FastAPI runs in a worker thread: the listing may read the data
    # directory, off the event loop (as the delete below may remove a file)
    return page(state.listing("mesh"), limit, offset)


@router.get("/{mesh_id}", response_model=MeshInfo, summary="Describe an uploaded mesh",
            responses=error_responses(404, 422))
async def get_mesh(mesh_id: str, state: Annotated[Runtime, Depends(runtime)]):
    return (await state.get("mesh", mesh_id)).info


@guarded.delete("/{mesh_id}", status_code=204, summary="Forget an uploaded mesh",
                responses=error_responses(404, 422))
def delete_mesh(mesh_id: str, state: Annotated[Runtime, Depends(runtime)]):
    state.delete("mesh", mesh_id)
