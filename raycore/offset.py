"""Origins of secondary rays that do not hit the surface they start on.

A hit point is rounded: it lies a little in front of or behind the true surface, so a ray spawned
from it with ``tmin = 0`` re-hits that surface about half the time, and a fixed epsilon fails once
coordinates are large.  Wächter & Binder ("A Fast and Robust Method for Avoiding Self-Intersection",
Ray Tracing Gems, ch. 6) move the point along the normal by a number of units in the last place of
each coordinate, so the offset grows with the point's magnitude, and by a small absolute amount
near the origin where units in the last place become tiny.
"""

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

from raycore._fp import like
from raycore.rays import as_float_array

#: Per precision: (coordinates below this use the absolute offset, absolute offset per unit
#: normal, units in the last place per unit normal).  The float32 values are Wächter & Binder's;
#: the float64 ones keep the same ratio to the precision's epsilon (2**-29 times smaller).
_CONSTANTS = {
    np.float32: (1.0 / 32.0, 2.0**-16, 256.0),
    np.float64: (1.0 / 32.0, 2.0**-45, 256.0),
}


def step_ulps(x, steps):
    """``x`` moved by ``steps`` units in the last place, away from zero for positive ``steps``
    (for finite ``x`` away from the largest floats; usable inside kernels)."""
    bits = np.asarray(x).view(np.int32 if isinstance(x, np.float32) else np.int64)
    return (bits + steps).view(type(x))[()]


@overload(step_ulps, inline="always")
def _step_ulps(x, steps):
    if x == types.float32:
        def impl(x, steps):
            return np.int32(np.float32(x).view(np.int32) + steps).view(np.float32)
    else:
        def impl(x, steps):
            return np.int64(np.float64(x).view(np.int64) + steps).view(np.float64)
    return impl


def offset_constants(dtype):
    """(near, float_scale, int_scale) of :func:`offset_coordinate` for ``dtype``'s precision,
    each of that type."""
    return tuple(dtype(value) for value in _CONSTANTS[dtype])


@njit(inline="always")
def offset_coordinate(p, n, near, float_scale, int_scale):
    """Coordinate ``p`` of a point moved off its surface along ``n``, that coordinate of the unit
    normal turned to the side the new ray leaves on (constants from :func:`offset_constants`)."""
    if abs(p) < near:
        return p + float_scale * n
    # a negative float grows in magnitude as its bit pattern grows: step the other way
    steps = int(int_scale * n)
    return step_ulps(p, -steps if p < 0 else steps)


@njit(cache=True, parallel=True, error_model="numpy")
def _offset(points, normals, directions, reach, near, float_scale, int_scale, out):
    for i in prange(len(points)):
        facing = (normals[i, 0] * directions[i, 0] + normals[i, 1] * directions[i, 1]
                  + normals[i, 2] * directions[i, 2])
        side = like(near, -1.0) if facing < 0 else like(near, 1.0)
        for k in range(3):
            n = side * normals[i, k]
            out[i, k] = offset_coordinate(like(near, points[i, k] + reach[i] * n), n, near,
                                          float_scale, int_scale)


def offset_ray_origin(points, normals, directions, *, error=None):
    """Move spawned ray origins off their surface, to the side the new rays leave on.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Hit points on surfaces.  float32 input is offset in float32 (and returned as float32);
        anything else in float64.
    normals : array_like, shape (N, 3)
        Surface normals at the points, of any non-zero length (they are scaled to unit
        length); their orientation does not matter.
    directions : array_like, shape (N, 3)
        Directions of the new rays: the origins move to the side of the surface these point to.
    error : array_like, shape (N,) or (N, 3), optional
        Absolute error bound of the points when it may exceed a few hundred units in the last
        place: per coordinate (N, 3), or already projected on the normal (N,).  A point computed
        as ``origin + t * direction`` is off by a few epsilons of ``|origin| + |t * direction|``,
        much more than its own ulps when the ray came from far away.  The origins then first
        move this far along the normal (as pbrt-v4's ``OffsetRayOrigin``).

    Returns
    -------
    ndarray, shape (N, 3)
        Ray origins: use them with ``tmin = 0``.

    Raises
    ------
    ValueError
        Naming the argument: wrong shape, NaN or inf entries, zero normals, negative errors.
    """
    points = np.asarray(points)
    dtype = np.float32 if points.dtype == np.float32 else np.float64
    points = as_float_array(points, "points", dtype, (None, 3))
    shape = (len(points), 3)
    normals = as_float_array(normals, "normals", dtype, shape)
    # unit length, which the steps (int_scale * n units in the last place) assume: a normal of
    # 1e17 stepped by an overflowed count; scaled to its largest component first, so that its
    # squares neither overflow nor vanish
    largest = np.max(np.abs(normals), axis=1, keepdims=True)
    if np.any(largest == 0):
        raise ValueError("normals must be non-zero")
    normals = normals / largest
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    directions = as_float_array(directions, "directions", dtype, shape)
    if error is None:
        reach = np.zeros(len(points))
    else:
        error = as_float_array(error, "error", np.float64)
        if error.shape not in ((len(points),), shape) or np.any(error < 0):
            raise ValueError(f"error must be non-negative with shape ({len(points)},) or "
                             f"({len(points)}, 3), got {error.shape}")
        # the error box's extent along the normal
        reach = error if error.ndim == 1 else np.sum(np.abs(normals) * error, axis=1)
    out = np.empty(shape, dtype)
    _offset(points, normals, directions, reach, *offset_constants(dtype), out)
    return out
