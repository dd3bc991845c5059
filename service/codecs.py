"""Encoding at the service's edge: rays in (JSON or .npy), query results out (JSON or .npy), PNG.

A query result is a dict of named columns (NumPy arrays with one row per ray, or per hit for
``all``), so that JSON and .npy answers carry the same numbers.
"""

import io
import json
import tokenize
import zlib
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from raycore.hits import SURFACE_FIELDS
from service.errors import BadRequest, ClientError

NPY = "application/x-npy"

#: .npy result columns: ids fit in int32 (stored triangles and objects are limited), which
#: keeps binary answers small.
_ID_DTYPE = np.dtype("<i4")


PLY = "model/ply"


def accepts_npy(accept):
    """Whether an Accept header lists .npy."""
    return accepts(accept, NPY)


def accepts(accept, media_type):
    """Whether an Accept header lists ``media_type``."""
    return any(part.split(";")[0].strip().lower() == media_type for part in accept.split(","))


#: Bytes of an .npy file that can hold its header: NumPy refuses headers over 10,000 bytes.
_NPY_HEADER_MAX = 65536


def npy_header(dtype, shape):
    """The header of an .npy file (format 1.0) that holds a C-ordered array.

    Parameters
    ----------
    dtype : numpy dtype, plain or structured
    shape : tuple of int

    Returns
    -------
    bytes
        To be followed by the array's bytes.
    """
    stream = io.BytesIO()
    np.lib.format.write_array_header_1_0(stream, {
        "descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
        "shape": tuple(shape)})
    return stream.getvalue()


def parse_npy_header(body):
    """Read the header of an .npy file from its first bytes, as a literal (never unpickled).

    Only the 1.0 and 2.0 formats.

    Parameters
    ----------
    body : bytes-like
        The file, or at least its header.

    Returns
    -------
    shape : tuple of int
    fortran_order : bool
    dtype : numpy dtype
    offset : int
        Where the data starts in ``body``.

    Raises
    ------
    ValueError
        When the bytes do not start an .npy file.
    """
    stream = io.BytesIO(memoryview(body)[:_NPY_HEADER_MAX])
    try:
        version = np.lib.format.read_magic(stream)
        if version == (1, 0):
            shape, fortran_order, dtype = np.lib.format.read_array_header_1_0(stream)
        elif version == (2, 0):
            shape, fortran_order, dtype = np.lib.format.read_array_header_2_0(stream)
        else:
            raise ValueError(f"format version {version} is not supported (1.0 or 2.0)")
    # numpy's header parser lets the tokenizer's and literal_eval's errors through
    except (ValueError, TypeError, SyntaxError, tokenize.TokenError) as error:
        raise ValueError(f"not a valid .npy file: {error}") from error
    return shape, fortran_order, dtype, stream.tell()


def read_npy(body):
    """Parse an .npy body into an array of floats without copying it, trusting nothing.

    The header is parsed by :func:`parse_npy_header`; object and structured dtypes are refused,
    and the body's length must match the announced shape.

    Parameters
    ----------
    body : bytes-like

    Raises
    ------
    BadRequest
        Saying what does not match.
    """
    try:
        shape, fortran_order, dtype, offset = parse_npy_header(body)
    except ValueError as error:
        raise BadRequest(f"the body is {error}") from error
    if dtype.hasobject or dtype.kind != "f" or dtype.itemsize not in (4, 8):
        raise BadRequest(f"the .npy array must hold float32 or float64, got dtype {dtype.str}")
    if any(size < 0 for size in shape):
        raise BadRequest(f"the .npy header announces a negative size in its shape {shape}")
    count = 1
    for size in shape:  # Python integers: a lying header must not overflow int64
        count *= size
    data = len(body) - offset
    if data != count * dtype.itemsize:
        raise BadRequest(f"the .npy header announces shape {shape} of {dtype.str} "
                         f"({count * dtype.itemsize} bytes), the body holds {data} bytes of data")
    array = np.frombuffer(body, dtype=dtype, count=count, offset=offset)
    return array.reshape(shape, order="F" if fortran_order else "C")


def rays_from_npy(array, tmin, tmax):
    """Split an (N, 6) or (N, 8) ray array (origin, direction[, tmin, tmax]) into columns.

    ``tmin``/``tmax`` (from the URL; None when not given) apply to (N, 6) rays; (N, 8) rays
    carry their own, which win.

    Returns
    -------
    origins, directions : ndarray, shape (N, 3)
    tmin, tmax : float or ndarray, shape (N,)
    """
    if array.ndim != 2 or array.shape[1] not in (6, 8):
        raise ClientError(f"the .npy rays must have shape (N, 6) or (N, 8), got {array.shape}")
    if array.shape[1] == 8:
        return array[:, :3], array[:, 3:6], array[:, 6], array[:, 7]
    return (array[:, :3], array[:, 3:6], 0.0 if tmin is None else tmin,
            np.inf if tmax is None else tmax)


def rays_from_json(request):
    """Origins, directions, tmin and tmax of an IntersectRequest (null tmax: no limit)."""
    tmax = request.tmax
    if tmax is None:
        tmax = np.inf
    elif isinstance(tmax, list):
        tmax = [np.inf if value is None else value for value in tmax]
    # (0, 3) for an empty batch, which np.asarray alone would make (0,)
    origins = np.asarray(request.origins, dtype=np.float64).reshape(-1, 3)
    directions = np.asarray(request.directions, dtype=np.float64).reshape(-1, 3)
    return origins, directions, request.tmin, tmax


def result_columns(query, result):
    """Named columns of a query's result (see :func:`service.answers.run_query`)."""
    if query == "any":
        return {"occluded": result}
    if query == "count":
        return {"count": result}
    if query == "all":
        return {"ray_index": result.ray_index, "t": result.t, "geom_id": result.geom_id,
                "prim_id": result.prim_id, "counts": result.counts}
    columns = {"t": result.t, "geom_id": result.geom_id, "prim_id": result.prim_id}
    for name in SURFACE_FIELDS:
        if getattr(result, name) is not None:
            columns[name] = getattr(result, name)
    return columns


def columns_to_json(columns):
    """JSON bytes of result columns: null for a miss's t (inf) and surface data (NaN)."""
    answer = {}
    for name, column in columns.items():
        values = column.tolist()
        if column.dtype.kind == "f":
            finite = np.isfinite(column)
            if column.ndim > 1:
                finite = finite.all(axis=1)
            for row in np.flatnonzero(~finite):
                values[row] = None
        answer[name] = values
    return json.dumps(answer, separators=(",", ":")).encode()


def columns_to_npy(columns):
    """An .npy file of result columns as one structured array (``counts`` of ``all`` is left
    out: it is ``np.bincount(ray_index)``); ids as int32.

    Returns
    -------
    memoryview
        The file's bytes: the table is filled in place after the header, never copied.
    """
    columns = {name: column for name, column in columns.items() if name != "counts"}
    length = len(next(iter(columns.values())))
    dtype = np.dtype([(name, _ID_DTYPE if column.dtype.kind in "iu"
                       else column.dtype.newbyteorder("<"), column.shape[1:])
                      for name, column in columns.items()])
    header = npy_header(dtype, (length,))
    buffer = bytearray(len(header) + length * dtype.itemsize)
    buffer[:len(header)] = header
    table = np.frombuffer(buffer, dtype, count=length, offset=len(header))
    for name, column in columns.items():
        table[name] = column
    return memoryview(buffer)


def array_to_npy(array):
    """An .npy file of a plain array, written straight after its header (as
    :func:`columns_to_npy`).

    Returns
    -------
    memoryview
    """
    array = np.ascontiguousarray(array, array.dtype.newbyteorder("<"))
    header = npy_header(array.dtype, array.shape)
    buffer = bytearray(len(header) + array.nbytes)
    buffer[:len(header)] = header
    buffer[len(header):] = memoryview(array).cast("B")
    return memoryview(buffer)


def points_to_ply(points):
    """Binary PLY bytes of an (M, 3) point cloud (its vertices only), written by trimesh, which
    stores them as float32 (as LiDAR point clouds usually are; .npy keeps the scene's dtype).
    trimesh is imported here, not with the module: the service and ``raycore cast`` start
    without it (0.15 s)."""
    import trimesh

    return trimesh.PointCloud(points).export(file_type="ply", encoding="binary")


def png(image):
    """PNG bytes of an (H, W, 3) uint8 image.

    Written here rather than by Pillow: each row "Sub"-filtered (the difference to the pixel on
    its left) and deflated at level 1 is three times faster for a similar size, and renders are
    encoded once, on the request's clock.
    """
    height, width, _ = image.shape
    rows = np.empty((height, 1 + 3 * width), np.uint8)
    rows[:, 0] = 1  # filter type Sub
    flat = image.reshape(height, 3 * width)
    rows[:, 1:4] = flat[:, :3]
    np.subtract(flat[:, 3:], flat[:, :-3], out=rows[:, 4:])  # wraps modulo 256, as PNG wants

    def chunk(kind, data):
        return (len(data).to_bytes(4, "big") + kind + data
                + zlib.crc32(kind + data).to_bytes(4, "big"))

    header = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([8, 2, 0, 0, 0])
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", _zlib_level_1(memoryview(rows).cast("B"))) + chunk(b"IEND", b""))


#: A thread that deflates the first half of a large PNG while the caller deflates the second.
_DEFLATE_HELPER = ThreadPoolExecutor(1, thread_name_prefix="deflate")


def _zlib_level_1(data):
    """``zlib.compress(data, 1)``, in two halves at once when ``data`` is large (zlib lets go of
    the GIL), as pigz does: the first half's deflate stream ends with a sync flush, on a byte
    boundary and without the final-block bit, so that the second's follows it as one stream
    (it starts without the first's window: about 0.3 % larger).  A 512x512 render: 2.1 -> 1.3 ms.
    """
    if len(data) < 2**18:
        return zlib.compress(data, 1)

    def deflate(part, last):
        compressor = zlib.compressobj(1, zlib.DEFLATED, -zlib.MAX_WBITS)
        return compressor.compress(part) + compressor.flush(
            zlib.Z_FINISH if last else zlib.Z_SYNC_FLUSH)

    half = len(data) // 2
    first = _DEFLATE_HELPER.submit(deflate, data[:half], False)
    second = deflate(data[half:], True)
    checksum = zlib.adler32(data).to_bytes(4, "big")
    # 0x78 0x01: a 32 KiB window, the fastest level, no dictionary
    return b"\x78\x01" + first.result() + second + checksum
