"""Ray queries over Dask arrays: batches larger than one machine, traced on a Dask cluster.

Each function takes a built-or-not :class:`raycore.Scene` and (N, 3) Dask arrays (or anything
``dask.array.asarray`` takes) of origins and directions, and returns Dask arrays, one per field,
chunked as the rays are along N.  Each chunk of rays is one task that calls the Scene's own
method, so the answers are the Scene's.

The scene enters the graph once, as one task that every chunk depends on: on a distributed
cluster the scheduler runs it on one worker and the others fetch its result once each (a
pickled Scene is its scene file, :mod:`raycore.scene_file`, about the size of its arrays, and
loads without a build), rather than a copy travelling with every chunk.  Needs the ``dask``
extra (``pip install "raycore[dask]"``); any scheduler works: threads, processes, or
``distributed`` on a laptop or a cluster.

Examples
--------
>>> import dask.array as da
>>> from distributed import Client
>>> client = Client("tcp://scheduler:8786")                 # doctest: +SKIP
>>> origins = da.from_zarr("rays.zarr", component="origins")  # doctest: +SKIP
>>> hits = raycore.dask.intersect(scene, origins, directions, fields=("normal",))  # +SKIP
>>> t, normal = dask.compute(hits["t"], hits["normal"])      # doctest: +SKIP
"""

import uuid
from operator import getitem

import dask
import dask.array as da
import numpy as np

from raycore.hits import check_fields
from raycore.rays import integer
from raycore.scene import check_scene

__all__ = ["intersect", "occluded", "count", "intersect_all"]


def _scene_task(scene):
    """The scene as one task of the graph (built first, so that no worker builds it)."""
    scene._scene()
    return dask.delayed(scene, name=f"raycore-scene-{uuid.uuid4().hex}", traverse=False)


def _ray_chunks(origins, directions, tmin, tmax):
    """Per chunk of rays: delayed (origins, directions, tmin, tmax) and the chunk's length."""
    origins = da.asarray(origins)
    directions = da.asarray(directions)
    for name, array in (("origins", origins), ("directions", directions)):
        if array.ndim != 2 or array.shape[1] != 3:
            raise ValueError(f"{name} must have shape (N, 3), got {array.shape}")
    if origins.shape[0] != directions.shape[0]:
        raise ValueError(f"origins and directions must be as many, got {origins.shape[0]} and "
                         f"{directions.shape[0]}")
    origins = origins.rechunk({1: 3})
    rows = origins.chunks[0]
    parts = [origins.to_delayed()[:, 0], directions.rechunk((rows, 3)).to_delayed()[:, 0]]
    for name, bound in (("tmin", tmin), ("tmax", tmax)):
        if np.ndim(bound) == 0:  # a scalar travels in every task as it is
            parts.append([bound] * len(rows))
            continue
        bound = da.asarray(bound)
        if bound.shape != (origins.shape[0],):
            raise ValueError(f"{name} must be a scalar or have shape ({origins.shape[0]},), "
                             f"got {bound.shape}")
        parts.append(bound.rechunk((rows,)).to_delayed())
    return list(zip(*parts, strict=True)), rows


def _fields(parts, specs):
    """Dask arrays, one per field: ``specs`` maps a name to (dtype, trailing shape, sized)
    (``sized``: a chunk has as many rows as its rays, else an unknown number)."""
    out = {}
    for name, (dtype, tail, sized) in specs.items():
        out[name] = da.concatenate([
            da.from_delayed(dask.delayed(getitem)(part, name),
                            shape=((rows if sized else np.nan), *tail), dtype=dtype)
            for part, rows in parts])
    return out


# Each chunk's task: the scene, its rays, the index of its first ray, the query's options.

def _chunk_intersect(scene, origins, directions, tmin, tmax, start, options):
    hits = scene.intersect(origins, directions, tmin, tmax, **options)
    return {name: getattr(hits, name) for name in ("t", "geom_id", "prim_id",
                                                   *options["fields"])}


def _chunk_method(scene, origins, directions, tmin, tmax, start, options, method):
    return {method: getattr(scene, method)(origins, directions, tmin, tmax, **options)}


def _chunk_all(scene, origins, directions, tmin, tmax, start, options):
    hits = scene.intersect_all(origins, directions, tmin, tmax, **options)
    return {"ray_index": hits.ray_index + start, "t": hits.t, "geom_id": hits.geom_id,
            "prim_id": hits.prim_id, "counts": hits.counts}


def _run(function, scene, origins, directions, tmin, tmax, *args):
    """``(delayed result, rays)`` of ``function`` on each chunk of rays."""
    check_scene(scene)
    chunks, rows = _ray_chunks(origins, directions, tmin, tmax)
    task = _scene_task(scene)
    call = dask.delayed(function, pure=True)
    starts = np.cumsum((0, *rows[:-1])).tolist()
    return [(call(task, *chunk, start, *args), length)
            for chunk, start, length in zip(chunks, starts, rows, strict=True)]


def intersect(scene, origins, directions, tmin=0.0, tmax=np.inf, *, triangle_test="watertight",
              sphere_method="precise", fields=()):
    """Closest hit of each ray, as :meth:`raycore.Scene.intersect`.

    Parameters
    ----------
    scene : raycore.Scene
    origins, directions : dask.array.Array or array_like, shape (N, 3)
    tmin, tmax : float or array_like of shape (N,)
    triangle_test, sphere_method, fields
        As :meth:`raycore.Scene.intersect`.

    Returns
    -------
    dict of str to dask.array.Array
        ``t`` (N,), ``geom_id`` and ``prim_id`` (N,) int64, and each of ``fields``: ``uv``
        (N, 2), ``normal``, ``point`` and ``shading_normal`` (N, 3).
    """
    fields = check_fields(fields)
    options = {"triangle_test": triangle_test, "sphere_method": sphere_method, "fields": fields}
    parts = _run(_chunk_intersect, scene, origins, directions, tmin, tmax, options)
    real = np.dtype(scene.dtype)
    specs = {"t": (real, (), True), "geom_id": (np.int64, (), True),
             "prim_id": (np.int64, (), True), "uv": (real, (2,), True),
             "normal": (real, (3,), True), "point": (real, (3,), True),
             "shading_normal": (real, (3,), True)}
    return _fields(parts, {name: specs[name] for name in ("t", "geom_id", "prim_id", *fields)})


def occluded(scene, origins, directions, tmin=0.0, tmax=np.inf, *, triangle_test="watertight",
             sphere_method="precise"):
    """(N,) bool Dask array: :meth:`raycore.Scene.occluded` of each ray."""
    options = {"triangle_test": triangle_test, "sphere_method": sphere_method}
    parts = _run(_chunk_method, scene, origins, directions, tmin, tmax, options, "occluded")
    return _fields(parts, {"occluded": (bool, (), True)})["occluded"]


def count(scene, origins, directions, tmin=0.0, tmax=np.inf, *, triangle_test="watertight",
          sphere_method="precise"):
    """(N,) int64 Dask array: :meth:`raycore.Scene.count` of each ray."""
    options = {"triangle_test": triangle_test, "sphere_method": sphere_method}
    parts = _run(_chunk_method, scene, origins, directions, tmin, tmax, options, "count")
    return _fields(parts, {"count": (np.int64, (), True)})["count"]


def intersect_all(scene, origins, directions, tmin=0.0, tmax=np.inf, *,
                  triangle_test="watertight", sphere_method="precise", max_hits=None):
    """Every crossing along each ray, as :meth:`raycore.Scene.intersect_all`.

    Parameters
    ----------
    max_hits : int, optional
        Crossings one chunk's answer may list at most, which bounds a worker's memory: a chunk
        with more raises :class:`raycore.TooManyHits` when it is computed, before memory is
        taken for its crossings.  Other parameters as :func:`intersect`.

    Returns
    -------
    dict of str to dask.array.Array
        ``ray_index``, ``t``, ``geom_id``, ``prim_id``: (H,) with chunks of unknown length,
        sorted by (ray, t) as the Scene's; ``counts``: (N,) int64 crossings of each ray.
    """
    if max_hits is not None:  # refused now, not when a worker computes the first chunk
        integer(max_hits, "max_hits", 0, np.inf)
    options = {"triangle_test": triangle_test, "sphere_method": sphere_method,
               "max_hits": max_hits}
    parts = _run(_chunk_all, scene, origins, directions, tmin, tmax, options)
    real = np.dtype(scene.dtype)
    return _fields(parts, {"ray_index": (np.int64, (), False), "t": (real, (), False),
                           "geom_id": (np.int64, (), False), "prim_id": (np.int64, (), False),
                           "counts": (np.int64, (), True)})
