"""Ray/plane intersection.

Parameters row: ``[p (3), N (3), n (3), e1 (3), e2 (3)]``: the given point p, the given normal
scaled by a power of two (N, exact), the unit normal n, and an orthonormal frame (e1, e2) of the
plane (:func:`~raycore.primitives._common.orthonormal_frame`, so that (e1, e2, n) is
right-handed).

``t = N·(p - o) / N·d`` with the caller's own normal rather than the rounded unit one, so that a
ray parallel to the plane, or starting on it, in exact arithmetic is seen as such.  The
difference ``p - o`` is taken before the dot product, which keeps the accuracy when the plane and
the ray are far from the origin (``N·p - N·o`` cancels).  A ray parallel to the plane misses,
even when it lies in it.

Surface: ``part`` is 0, the normal is n (the side it points to is "outside"), and
``(u, v) = ((x - p)·e1, (x - p)·e2)`` are the coordinates of the hit point x in the plane's
frame, in world units, unbounded.
"""

import numpy as np

from raycore.primitives._common import (
    as_point,
    as_unit,
    dot,
    exact_direction,
    in_range,
    inline_kernel,
    miss,
    no_uv,
    orthonormal_frame,
    param_row,
)


def pack(point, normal):
    """Parameter row of a plane through ``point`` with normal ``normal`` (any non-zero length).

    Parameters
    ----------
    point, normal : array_like, shape (3,)

    Returns
    -------
    ndarray, shape (PARAM_WIDTH,)

    Raises
    ------
    ValueError
        Naming ``point`` or ``normal``.
    """
    point = as_point(point, "point")
    normal = as_point(normal, "normal")
    n, _ = as_unit(normal, "normal")
    return param_row(point, exact_direction(normal), n, *orthonormal_frame(n))


def bounds(params):
    """An infinite plane has infinite bounds: ``(-inf, +inf)`` on every axis."""
    return np.full(3, -np.inf), np.full(3, np.inf)


@inline_kernel
def hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """``(t, 0)`` where the ray crosses the plane within ``[tmin, tmax]``, else ``(inf, -1)``."""
    nx, ny, nz = params[3], params[4], params[5]  # the exact normal N
    t = dot(nx, ny, nz, params[0] - ox, params[1] - oy, params[2] - oz) / dot(
        nx, ny, nz, dx, dy, dz
    )
    if in_range(t, tmin, tmax):
        return t, 0
    return miss(ox)


@inline_kernel
def surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """The plane's unit normal and the frame coordinates ``(u, v)`` of ``o + t d``
    (:func:`no_uv` unless ``want_uv``)."""
    if not want_uv:
        return (params[6], params[7], params[8]) + no_uv(ox)
    qx = (ox - params[0]) + t * dx
    qy = (oy - params[1]) + t * dy
    qz = (oz - params[2]) + t * dz
    u = dot(qx, qy, qz, params[9], params[10], params[11])
    v = dot(qx, qy, qz, params[12], params[13], params[14])
    return params[6], params[7], params[8], u, v
