"""A Python client for the service: ray batches go out and come back as NumPy arrays.

A batch is sent as one .npy body straight from an array's memory, and the answer is read into
one buffer that becomes the result's table, with no copy in between: a million float32 rays are
24 MB out and 12 MB back, and a general-purpose HTTP client's chunking and joining of them costs
about as much as tracing them (``python -m benchmarks.service_bench``).  Standard library
(``http.client``) and NumPy only, so that it needs none of the service's dependencies.
"""

import http.client
import json
import os
from urllib.parse import quote, urlencode, urlsplit

import numpy as np

from service.codecs import NPY, npy_header, parse_npy_header


class ServiceError(RuntimeError):
    """The service answered with an error status.

    Attributes
    ----------
    status : int
        The HTTP status, 4xx for a request the service refused.
    detail : str
        The service's explanation.
    """

    def __init__(self, status, detail):
        super().__init__(f"{status}: {detail}")
        self.status = status
        self.detail = detail


class Client:
    """A keep-alive connection to a raycore service; one per thread.

    Parameters
    ----------
    url : str
        ``http://host[:port]``, e.g. what ``raycore serve`` prints.
    api_key : str, optional
        Sent as ``X-API-Key``: uploads, scene builds and deletions need it when the service has
        one.
    timeout : float
        Seconds that one socket operation may wait.

    Attributes
    ----------
    last_headers : http.client.HTTPMessage or None
        The headers of the last answer; its ``Server-Timing`` is the service's own time.

    Examples
    --------
    >>> with Client("http://127.0.0.1:8000") as client:
    ...     hits = client.intersect("demo", origins, directions, fields=["normal"])
    ...     hits["t"], hits["prim_id"], hits["normal"]
    """

    def __init__(self, url="http://127.0.0.1:8000", api_key=None, timeout=60.0):
        parts = urlsplit(url)
        if parts.scheme != "http" or not parts.hostname:
            raise ValueError(f"url must look like http://host[:port], got {url!r}")
        self._connection = http.client.HTTPConnection(parts.hostname, parts.port or 80,
                                                      timeout=timeout)
        self._root = parts.path.rstrip("/")
        self._headers = {} if api_key is None else {"x-api-key": api_key}
        self.last_headers = None

    def close(self):
        self._connection.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()

    def upload_mesh(self, source, format=None):
        """Upload a mesh file (OBJ, PLY, STL, OFF, GLB).

        Parameters
        ----------
        source : str, path-like or bytes
            The file, or its contents.
        format : str, optional
            The file's format; by default a path's extension.

        Returns
        -------
        dict
            The service's description: ``id``, vertex and face counts, bounds, closedness.
        """
        if isinstance(source, str | os.PathLike):
            format = format or os.path.splitext(source)[1][1:]
            with open(source, "rb") as file:
                source = file.read()
        if not format:
            raise ValueError("format is needed for a mesh given as bytes (e.g. 'ply')")
        return self._json("POST", "/v1/meshes?" + urlencode({"format": format}), source,
                          "application/octet-stream")

    def create_scene(self, spec):
        """Build a scene from its JSON description (``{"dtype": ..., "objects": [...]}``).

        Returns
        -------
        dict
            The scene's ``id``, bounds, counts and build time.
        """
        return self._json("POST", "/v1/scenes", _to_json(spec), "application/json")

    def scene(self, scene_id):
        """The description of a stored scene (``demo`` names the built-in one)."""
        return self._json("GET", _scene_path(scene_id))

    def delete_scene(self, scene_id):
        self._request("DELETE", _scene_path(scene_id))

    def intersect(self, scene_id, origins, directions, tmin=None, tmax=None, *,
                  query="closest", fields=(), triangle_test="watertight"):
        """Cast a batch of rays at a stored scene, as :meth:`raycore.Scene.intersect` does.

        Parameters
        ----------
        scene_id : str
        origins, directions : array_like, shape (N, 3)
            Sent as float32 when both are float32, else as float64 (the scene's precision
            decides how they are traced).
        tmin, tmax : float or array_like of shape (N,), optional
            Defaults 0 and no limit.
        query : {"closest", "any", "all", "count"}
        fields : sequence of {"uv", "normal", "point", "shading_normal"}
            Surface data of closest hits.
        triangle_test : {"watertight", "moller", "geometric"}

        Returns
        -------
        ndarray, structured, shape (N,) or, for ``all``, (H,)
            closest: ``t`` (inf on a miss), ``geom_id`` and ``prim_id`` (-1 on a miss) and the
            asked fields (NaN on a miss); any: ``occluded``; count: ``count``; all: one row per
            hit, sorted by ray and t: ``ray_index``, ``t``, ``geom_id``, ``prim_id``.

        Raises
        ------
        ValueError
            For arrays of the wrong shapes.
        ServiceError
            When the service refuses the batch.
        """
        origins, directions = np.asarray(origins), np.asarray(directions)
        if origins.ndim != 2 or origins.shape[1] != 3:
            raise ValueError(f"origins must have shape (N, 3), got {origins.shape}")
        if directions.shape != origins.shape:
            raise ValueError(f"directions must have the shape of origins, {origins.shape}, "
                             f"got {directions.shape}")
        count = len(origins)
        per_ray = {}
        for name, value in (("tmin", tmin), ("tmax", tmax)):
            if np.ndim(value) and np.shape(value) != (count,):
                raise ValueError(f"{name} must be a number or of shape ({count},), got shape "
                                 f"{np.shape(value)}")
            per_ray[name] = np.ndim(value) > 0
        precision = np.float32 if origins.dtype == directions.dtype == np.float32 else np.float64
        # one (N, 6) array, or (N, 8) with each ray's own tmin and tmax
        rays = np.empty((count, 8 if any(per_ray.values()) else 6), precision)
        rays[:, :3], rays[:, 3:6] = origins, directions
        parameters = {"query": query, "fields": list(fields), "triangle_test": triangle_test}
        if rays.shape[1] == 8:
            rays[:, 6] = 0.0 if tmin is None else tmin
            rays[:, 7] = np.inf if tmax is None else tmax
        else:
            parameters.update((name, value) for name, value in (("tmin", tmin), ("tmax", tmax))
                              if value is not None)
        path = _scene_path(scene_id) + "/intersect?" + urlencode(parameters, doseq=True)
        body = self._request("POST", path, (npy_header(precision, rays.shape), rays), NPY,
                             accept=NPY)
        shape, _, dtype, offset = parse_npy_header(body)
        return np.frombuffer(body, dtype, count=shape[0], offset=offset)

    def render(self, scene_id, camera, shading="lambert", **options):
        """Render a stored scene.

        Parameters
        ----------
        scene_id : str
        camera : dict
            ``type`` (perspective or orthographic), ``position``, ``look_at``, ``up``, ``fov`` or
            ``view_height``, ``width``, ``height``, as the service documents them.
        shading : {"lambert", "depth", "normal", "id"}
        **options
            ``light_direction``, ``ambient``, ``background``, ``triangle_test``.

        Returns
        -------
        bytes
            The PNG file.
        """
        body = _to_json({"camera": camera, "shading": shading, **options})
        return bytes(self._request("POST", _scene_path(scene_id) + "/render",
                                   (body,), "application/json"))

    def _json(self, method, path, body=None, content_type=None):
        answer = self._request(method, path, () if body is None else (body,), content_type)
        return json.loads(answer.tobytes())

    def _request(self, method, path, parts=(), content_type=None, accept=None):
        """Send a request whose body is ``parts`` (bytes-like, each sent from its own memory)
        and return its answer's body, as an array of uint8.

        A connection that the service closed while it was idle (uvicorn does after 5 s) fails at
        the next request: the request is then sent again, once, on a new connection.  That is
        safe because every request of this API is idempotent (ids are content hashes).

        Raises
        ------
        ServiceError
            For an answer with an error status.
        """
        headers = dict(self._headers)
        if parts:
            headers["content-length"] = str(sum(memoryview(part).nbytes for part in parts))
        if content_type:
            headers["content-type"] = content_type
        if accept:
            headers["accept"] = accept
        connection = self._connection
        for attempt in range(2):
            reused = connection.sock is not None
            try:
                connection.putrequest(method, self._root + path, skip_accept_encoding=True)
                for name, value in headers.items():
                    connection.putheader(name, value)
                connection.endheaders()
                for part in parts:
                    connection.send(part)
                response = connection.getresponse()
                body = _read_body(response)
                break
            except Exception as error:  # the connection's state is unknown: start afresh
                connection.close()
                # reset, broken pipe, closed before the answer
                if not isinstance(error, ConnectionError) or not reused or attempt:
                    raise
        self.last_headers = response.headers
        if response.status >= 400:
            try:
                detail = json.loads(body.tobytes())["detail"]
            except (ValueError, KeyError, TypeError):
                detail = body.tobytes().decode(errors="replace")
            raise ServiceError(response.status, detail)
        return body


def _scene_path(scene_id):
    """The path of a scene's resource; the id is quoted, as it is the client's to choose."""
    return f"/v1/scenes/{quote(scene_id, safe='')}"


def _read_body(response):
    """The body of an ``http.client`` response, read into one array of uint8 when its length
    is announced."""
    length = response.getheader("content-length", "")
    if not length.isdigit():
        return np.frombuffer(response.read(), np.uint8)
    body = np.empty(int(length), np.uint8)
    view, filled = memoryview(body), 0
    while filled < len(body):
        count = response.readinto(view[filled:])
        if not count:
            raise http.client.IncompleteRead(view[:filled].tobytes(), len(body) - filled)
        filled += count
    return body


def _to_json(value):
    """JSON bytes of ``value``, where NumPy arrays and numbers may stand for lists and numbers;
    NaN and infinities raise ValueError (JSON has none)."""

    def plain(item):
        if isinstance(item, np.ndarray | np.generic):
            return item.tolist()
        raise TypeError(f"{type(item).__name__} cannot be sent as JSON")

    return json.dumps(value, default=plain, allow_nan=False, separators=(",", ":")).encode()
