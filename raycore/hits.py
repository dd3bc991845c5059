"""Result types of ray queries."""

from collections import namedtuple
from dataclasses import dataclass

import numpy as np

#: Surface fields a closest-hit query can be asked for, besides t and the ids it always returns.
SURFACE_FIELDS = ("uv", "normal", "point", "shading_normal")


def check_fields(fields):
    """``fields`` (a name, or names) as a tuple of :data:`SURFACE_FIELDS`; ``ValueError``
    naming the unknown ones."""
    try:
        fields = (fields,) if isinstance(fields, str) else tuple(fields)
    except TypeError as error:  # not iterable
        raise ValueError(f"fields must be a field name or names, got {fields!r}") from error
    unknown = [f for f in fields if not isinstance(f, str) or f not in SURFACE_FIELDS]
    if unknown:
        raise ValueError(f"fields must be among {SURFACE_FIELDS}, got {unknown}")
    return fields


#: Closest hits as a compiled pass over them takes them (``Scene._surface_hits``): the scene's
#: record, its vertex normal tables (:attr:`raycore.shading.NormalTables.arrays`), the rays as
#: traced ((N, 3) each), and per ray t, geometry and primitive ids, barycentrics and slot (as
#: :func:`raycore.queries.closest_hits` gives them).
SurfaceHits = namedtuple("SurfaceHits", ["record", "tables", "origins", "directions", "t",
                                         "geom_id", "prim_id", "u", "v", "slot"])


@dataclass(frozen=True, init=False)
class Hits:
    """Closest hit of each ray.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Ray parameter of the hit (``origin + t * direction``); ``inf`` where the ray missed.
    geom_id, prim_id : ndarray of int64, shape (N,)
        Geometry id (as returned by ``Scene.add_*``) and primitive index within it (the face index
        for meshes, 0 for analytic shapes); -1 where the ray missed.
    uv : ndarray, shape (N, 2), or None
        Barycentrics (u, v) of the hit for triangles, the shape's surface parameters otherwise;
        NaN where missed.  Only computed when asked for.
    normal : ndarray, shape (N, 3), or None
        Unit geometric normal (facing is not flipped towards the ray); NaN where missed.
    point : ndarray, shape (N, 3), or None
        Hit point ``origin + t * direction``; NaN where missed.
    shading_normal : ndarray, shape (N, 3), or None
        Unit normal for smooth shading: on meshes, their vertex normals (see
        :mod:`raycore.shading`) interpolated with the barycentrics; the geometric normal on
        analytic shapes; on the geometric normal's side.  NaN where missed.
    """

    t: np.ndarray
    geom_id: np.ndarray
    prim_id: np.ndarray
    uv: np.ndarray | None = None
    normal: np.ndarray | None = None
    point: np.ndarray | None = None
    shading_normal: np.ndarray | None = None

    def __init__(self, t, geom_id, prim_id, uv=None, normal=None, point=None,
                 shading_normal=None):
        # one update of the instance's dict: a frozen dataclass's own __init__ makes a call to
        # object.__setattr__ per field, 0.8 us of a one-ray intersect (this takes 0.3)
        self.__dict__.update(t=t, geom_id=geom_id, prim_id=prim_id, uv=uv, normal=normal,
                             point=point, shading_normal=shading_normal)

    @property
    def hit(self):
        """(N,) bool: whether each ray hit anything."""
        return self.geom_id >= 0

    def __len__(self):
        return len(self.t)


@dataclass(frozen=True)
class AllHits:
    """Every hit along every ray, sorted by (ray, t).

    Attributes
    ----------
    ray_index : ndarray of int64, shape (H,)
        Which ray each hit belongs to; non-decreasing.
    t : ndarray, shape (H,)
    geom_id, prim_id : ndarray of int64, shape (H,)
    counts : ndarray of int64, shape (N,)
        Number of hits of each ray; ``offsets`` gives where each ray's hits start.
    """

    ray_index: np.ndarray
    t: np.ndarray
    geom_id: np.ndarray
    prim_id: np.ndarray
    counts: np.ndarray

    @property
    def offsets(self):
        """(N + 1,) int64: the hits of ray i are ``[offsets[i], offsets[i + 1])``."""
        return np.concatenate(([0], np.cumsum(self.counts)))

    def __len__(self):
        return len(self.t)


class TooManyHits(ValueError):
    """:meth:`raycore.Scene.intersect_all`'s answer would list more than its ``max_hits``
    crossings: raised once they are counted, before any memory is taken for them.

    Attributes
    ----------
    crossings, max_hits : int
    """

    def __init__(self, crossings, max_hits):
        super().__init__(f"the rays cross the scene {crossings} times, more than max_hits "
                         f"({max_hits})")
        self.crossings, self.max_hits = crossings, max_hits

    def __reduce__(self):
        # an exception pickles as its class called with self.args (the message alone): one
        # raised in a Dask worker or a child process could not be rebuilt where it is reported
        return type(self), (self.crossings, self.max_hits)
