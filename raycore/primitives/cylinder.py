"""Ray/cylinder intersection: a finite cylinder along any axis, capped at both ends.

Parameters row: ``[p0 (3), p1 (3), w (3), h, r, r², e1 (3), e2 (3)]``: the end centres, the unit
axis ``w = (p1 - p0) / h``, the height ``h = |p1 - p0|``, the radius and its square, and an
orthonormal frame (e1, e2) perpendicular to the axis
(:func:`~raycore.primitives._common.orthonormal_frame`).

Side: with ``f = o - p0`` and ``⊥`` the component perpendicular to w, the side is
``|f⊥ + t d⊥|² = r²``, a quadratic solved by the shared stable solver with Hearn and Baker's
discriminant (as for the sphere, in the plane perpendicular to the axis); a root counts when its
axial coordinate ``(f + t d)·w`` lies in ``[0, h]``.  A double root (tangent ray) is a hit.  A ray
parallel to the axis (``d⊥ = 0``) never meets the side and can only hit a cap.  Caps: the shared
disk test.  The nearest of the four candidates in ``[tmin, tmax]`` wins, so a ray starting inside
returns the far side.

Parts: 0 side, 1 cap at p0, 2 cap at p1.

Surface: side normal ``(x - p0)⊥ / |(x - p0)⊥|``; cap normals ``-w`` (at p0) and ``+w`` (at p1).
Side ``(u, v)``: ``u`` is the angle around the axis from e1 towards e2 over 2π, in [0, 1);
``v`` the axial coordinate over h, 0 at p0 and 1 at p1.  Caps: polar, as the disk: the same ``u``
and ``v = ρ / r``, the distance from the axis over the radius.
"""

import numpy as np

from raycore._fp import like
from raycore.primitives._common import (
    as_point,
    as_radius,
    as_unit,
    axial_split,
    clamp01,
    closer,
    closer_on_side,
    disk_extent,
    disk_hit,
    dot,
    inline_kernel,
    miss,
    no_uv,
    normalized,
    orthonormal_frame,
    param_row,
    polar_uv,
    precise_discriminant,
    stable_roots,
    widen,
)


def pack(p0, p1, radius):
    """Parameter row of the cylinder from ``p0`` to ``p1``.

    Parameters
    ----------
    p0, p1 : array_like, shape (3,)
        Centres of the two caps; distinct.
    radius : float
        Positive.

    Returns
    -------
    ndarray, shape (PARAM_WIDTH,)

    Raises
    ------
    ValueError
        Naming ``p0``, ``p1`` or ``radius``.
    """
    p0 = as_point(p0, "p0")
    p1 = as_point(p1, "p1")
    radius = as_radius(radius)
    w, height = as_unit(p1 - p0, "p1", "must differ from p0")
    return param_row(p0, p1, w, height, radius, radius * radius, *orthonormal_frame(w))


def bounds(params):
    """Axis-aligned bounds ``(lo, hi)`` of the two caps, two (3,) float64 arrays."""
    params = np.asarray(params, dtype=np.float64)
    p0, p1 = params[:3], params[3:6]
    extent = disk_extent(params[6:9], params[10])
    return widen(np.minimum(p0, p1) - extent, np.maximum(p0, p1) + extent)


@inline_kernel
def hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """Nearest crossing in ``[tmin, tmax]`` as ``(t, part)``; ``(inf, -1)`` on a miss."""
    wx, wy, wz = params[6], params[7], params[8]
    fw, fx, fy, fz = axial_split(ox - params[0], oy - params[1], oz - params[2], wx, wy, wz)
    dw, px, py, pz = axial_split(dx, dy, dz, wx, wy, wz)
    r2 = params[11]
    a = dot(px, py, pz, px, py, pz)
    b = dot(fx, fy, fz, px, py, pz)
    c = dot(fx, fy, fz, fx, fy, fz) - r2
    t0, t1 = stable_roots(a, b, c, precise_discriminant(fx, fy, fz, px, py, pz, a, b, r2))
    zero = like(ox, 0.0)
    t, part = miss(ox)
    t, part = closer_on_side(t0, fw, dw, zero, params[9], t, part, tmin, tmax)
    t, part = closer_on_side(t1, fw, dw, zero, params[9], t, part, tmin, tmax)
    cap0 = disk_hit(params[0], params[1], params[2], wx, wy, wz, r2, ox, oy, oz, dx, dy, dz)
    t, part = closer(cap0, 1, t, part, tmin, tmax)
    cap1 = disk_hit(params[3], params[4], params[5], wx, wy, wz, r2, ox, oy, oz, dx, dy, dz)
    return closer(cap1, 2, t, part, tmin, tmax)


@inline_kernel
def surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """Unit outward normal and ``(u, v)`` (see the module docstring; :func:`no_uv` unless
    ``want_uv``) at ``o + t d``."""
    s, qx, qy, qz = axial_split(
        (ox - params[0]) + t * dx, (oy - params[1]) + t * dy, (oz - params[2]) + t * dz,
        params[6], params[7], params[8],
    )
    if part == 0:
        normal = normalized(qx, qy, qz)
    else:
        sign = like(ox, 1.0) if part == 2 else like(ox, -1.0)
        normal = (sign * params[6], sign * params[7], sign * params[8])
    if not want_uv:
        return normal + no_uv(ox)
    u, v = polar_uv(
        qx, qy, qz, params[12], params[13], params[14], params[15], params[16], params[17],
        params[10],
    )
    return normal + (u, clamp01(s / params[9]) if part == 0 else v)
