"""Schemathesis hooks (loaded by schemathesis.toml): request bodies that the tool cannot make
from the OpenAPI document alone.

The document can only say that mesh files and .npy ray batches are binary strings; any bytes
fit that, and random bytes are neither.  These serializers turn whatever the tool generated into
a real file of the body's media type, seeded by it, so that generated uploads and binary
queries reach the service's geometry rather than its parse errors.
"""

import io
import zlib

import numpy as np
import schemathesis
import trimesh
from schemathesis.transport.requests import REQUESTS_TRANSPORT, multipart_serializer

from service.codecs import NPY
from service.routes.meshes import MEDIA_TYPES

#: The part type schemathesis gives a form's 'file' when it picks none: the first the
#: document's encoding lists.
DEFAULT_PART_TYPE = next(iter(MEDIA_TYPES))


def _rng(value):
    """A random generator seeded by the generated value, so that a case replays the same."""
    return np.random.default_rng(zlib.crc32(repr(value).encode()))


def mesh_file(value, media_type):
    """Bytes of a small closed mesh, placed and sized by ``value``, in ``media_type``'s format."""
    rng = _rng(value)
    mesh = trimesh.creation.icosphere(subdivisions=int(rng.integers(0, 2)),
                                      radius=float(rng.uniform(0.1, 10.0)))
    mesh.apply_translation(rng.uniform(-100.0, 100.0, 3))
    exported = mesh.export(file_type=MEDIA_TYPES[media_type])
    return exported.encode() if isinstance(exported, str) else exported


def npy_rays(value):
    """Bytes of an .npy ray batch: (N, 6) or (N, 8), float32 or float64, N from 0 to 16, with
    finite origins, non-zero directions and tmin <= tmax."""
    rng = _rng(value)
    count = int(rng.integers(0, 17))
    origins = rng.uniform(-10.0, 10.0, (count, 3))
    directions = rng.normal(size=(count, 3)) + [0.0, 0.0, 1e-3]  # never exactly zero
    columns = [origins, directions]
    if rng.integers(0, 2):
        tmin = rng.uniform(0.0, 1.0, (count, 1))
        columns += [tmin, tmin + rng.uniform(0.0, 100.0, (count, 1))]
    stream = io.BytesIO()
    np.save(stream, np.hstack(columns).astype(rng.choice([np.float32, np.float64])))
    return stream.getvalue()


for _media_type in MEDIA_TYPES:
    schemathesis.serializer(_media_type)(
        lambda ctx, value, media_type=_media_type: mesh_file(value, media_type))


@schemathesis.serializer(NPY)
def _npy(ctx, value):
    return npy_rays(value)


def _multipart(ctx, value):
    """A schema-valid upload form's 'file' part as a real mesh file of the type chosen for the
    part, then the tool's own multipart encoding; negative cases go out as generated.

    In place of the tool's multipart serializer because that one sends a part that is already
    bytes as it is, past the serializers above; and not as a ``map_case`` hook, because a case
    whose body a hook changes is validated again, and the tool then takes the mesh bytes for a
    schema violation.
    """
    case = ctx.case
    positive = case.meta is not None and case.meta.generation.mode.is_positive
    if positive and isinstance(value, dict) and isinstance(value.get("file"), bytes | str):
        part_type = (case.multipart_content_types or {}).get("file", DEFAULT_PART_TYPE)
        if part_type in MEDIA_TYPES:
            value = {**value, "file": mesh_file(value["file"], part_type)}
    return multipart_serializer(ctx, value)


REQUESTS_TRANSPORT.serializer("multipart/form-data")(_multipart)
