"""Ray/disk intersection: a flat disk, hit from either side.

Parameters row: ``[c (3), N (3), n (3), r, r², e1 (3), e2 (3)]``: centre c, the given normal
scaled by a power of two (N, exact: the plane test uses it, as the plane does), the unit normal
n, radius, its square, and an orthonormal frame (e1, e2) of the disk's plane
(:func:`~raycore.primitives._common.orthonormal_frame`).

The hit is the plane crossing when ``|x - c|² <= r²`` (the rim counts as inside), tested by
:func:`~raycore.primitives._common.disk_hit`, which the caps of the cylinder and the cone share.

Surface: ``part`` is 0 and the normal is n.  Polar ``(u, v)``: ``u`` is the angle of ``x - c``
from e1 towards e2 over 2π, in [0, 1); ``v = |x - c| / r`` in [0, 1] (0 at the centre, 1 on the
rim).
"""

import numpy as np

from raycore.primitives._common import (
    as_point,
    as_radius,
    as_unit,
    disk_extent,
    disk_hit,
    exact_direction,
    in_range,
    inline_kernel,
    miss,
    no_uv,
    orthonormal_frame,
    param_row,
    polar_uv,
    widen,
)


def pack(center, normal, radius):
    """Parameter row of a disk.

    Parameters
    ----------
    center, normal : array_like, shape (3,)
        The normal may have any non-zero length.
    radius : float
        Positive.

    Returns
    -------
    ndarray, shape (PARAM_WIDTH,)

    Raises
    ------
    ValueError
        Naming ``center``, ``normal`` or ``radius``.
    """
    center = as_point(center, "center")
    normal = as_point(normal, "normal")
    n, _ = as_unit(normal, "normal")
    radius = as_radius(radius)
    return param_row(center, exact_direction(normal), n, radius, radius * radius,
                     *orthonormal_frame(n))


def bounds(params):
    """Axis-aligned bounds ``(lo, hi)``, two (3,) float64 arrays."""
    params = np.asarray(params, dtype=np.float64)
    center = params[:3]
    extent = disk_extent(params[6:9], params[9])
    return widen(center - extent, center + extent)


@inline_kernel
def hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """``(t, 0)`` where the ray crosses the disk within ``[tmin, tmax]``, else ``(inf, -1)``."""
    t = disk_hit(
        params[0], params[1], params[2], params[3], params[4], params[5], params[10],
        ox, oy, oz, dx, dy, dz,
    )
    if in_range(t, tmin, tmax):
        return t, 0
    return miss(ox)


@inline_kernel
def surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """The disk's unit normal and polar ``(u, v)`` of ``o + t d`` (:func:`no_uv` unless
    ``want_uv``)."""
    if not want_uv:
        return (params[6], params[7], params[8]) + no_uv(ox)
    u, v = polar_uv(
        (ox - params[0]) + t * dx, (oy - params[1]) + t * dy, (oz - params[2]) + t * dz,
        params[11], params[12], params[13], params[14], params[15], params[16], params[9],
    )
    return params[6], params[7], params[8], u, v
