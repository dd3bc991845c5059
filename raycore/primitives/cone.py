"""Ray/cone intersection: a finite right circular cone along any axis, capped at its base.

Parameters row: ``[b (3), A (3), w (3), h, r, r², k², e1 (3), e2 (3)]``: base centre b, apex A,
unit axis ``w = (A - b) / h`` from the base to the apex, height ``h = |A - b|``, base radius r and
its square, ``k² = (r / h)²``, and an orthonormal frame (e1, e2) perpendicular to the axis
(:func:`~raycore.primitives._common.orthonormal_frame`).

Side: with ``g = x - A`` for a point x, ``s = g·w`` and ``g⊥`` the component perpendicular to w,
the double cone is ``|g⊥|² = k² s²``.  Along the ray ``g = f + t d`` (``f = o - A``) this is
``a t² + 2 b t + c = 0`` with ``a = |d⊥|² - k² (d·w)²``, ``b = f⊥·d⊥ - k² (f·w)(d·w)``,
``c = |f⊥|² - k² (f·w)²``, written with perpendicular components so that no ``|d|² - (d·w)²``
cancels for rays near the axis.  The discriminant comes from the ray's moment about the apex
(:func:`_discriminant`), which stays accurate for tangent rays and far origins.  ``a`` is 0
exactly when the ray is parallel to a generator (a line of the surface); the shared solver then
takes the linear root ``-c / 2b``.  A root counts on the real nappe, ``-h <= s <= 0``; a double
root (tangent ray) is a hit.  Base: the shared disk test.  The nearest candidate in
``[tmin, tmax]`` wins, so a ray starting inside returns the far side.

Parts: 0 side, 1 base cap.

Surface: the side normal is the gradient ``g⊥ - k² s w``, normalised (it leans towards the
apex); at the apex itself, where it vanishes, the axis w.  The base normal is ``-w``.
Side ``(u, v)``: ``u`` is the angle around the axis from e1 towards e2 over 2π, in [0, 1); ``v``
runs along the axis from 0 at the base to 1 at the apex.  Base: polar, as the disk: the same
``u`` and ``v = ρ / r``.
"""

import math

import numpy as np

from raycore._fp import gamma, like
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
    stable_roots,
    widen,
)


def pack(base_center, apex, radius):
    """Parameter row of the cone.

    Parameters
    ----------
    base_center, apex : array_like, shape (3,)
        Distinct points.
    radius : float
        Radius of the base; positive.

    Returns
    -------
    ndarray, shape (PARAM_WIDTH,)

    Raises
    ------
    ValueError
        Naming ``base_center``, ``apex`` or ``radius``.
    """
    base = as_point(base_center, "base_center")
    apex = as_point(apex, "apex")
    radius = as_radius(radius)
    w, height = as_unit(apex - base, "apex", "must differ from base_center")
    slope = radius / height
    slope2 = slope * slope  # not ** 2, which raises OverflowError where this is inf
    if not slope2 < math.inf:
        raise ValueError(f"apex lies too near base_center for radius {radius:g}: the slope's "
                         f"square, (radius / height)^2, overflows float64")
    return param_row(
        base, apex, w, height, radius, radius * radius, slope2, *orthonormal_frame(w)
    )


def bounds(params):
    """Axis-aligned bounds ``(lo, hi)`` of the base disk and the apex, two (3,) float64 arrays."""
    params = np.asarray(params, dtype=np.float64)
    base, apex = params[:3], params[3:6]
    extent = disk_extent(params[6:9], params[10])
    return widen(np.minimum(base - extent, apex), np.maximum(base + extent, apex))


@inline_kernel
def _discriminant(fx, fy, fz, dx, dy, dz, wx, wy, wz, k2):
    """Quarter discriminant ``b² - a c`` from the moment ``m = f × d`` of the ray about the apex.

    For a symmetric 3x3 Q, ``(fᵀQd)² - (fᵀQf)(dᵀQd) = -mᵀ adj(Q) m``; the cone's
    ``Q = I - (1 + k²) w wᵀ`` has ``adj(Q) = w wᵀ - k² (I - w wᵀ)``, so ``b² - a c =
    k² |m⊥|² - (m·w)²``.  The moment does not change as the origin slides along the ray, so,
    unlike ``b² - a c``, this does not cancel catastrophically for origins far from the apex or
    for tangent rays (the cone's analogue of Hearn and Baker's form for the sphere).
    """
    mx = fy * dz - fz * dy
    my = fz * dx - fx * dz
    mz = fx * dy - fy * dx
    mw, qx, qy, qz = axial_split(mx, my, mz, wx, wy, wz)
    disc = k2 * dot(qx, qy, qz, qx, qy, qz) - mw * mw
    # A ray through (or within rounding of) the apex has m ≈ 0 and a discriminant whose sign is
    # rounding noise; a negative one would let it slip between the nappes.  A negative value
    # within the error bound counts as 0, a tangent.  Each component of m is off by at most
    # γ(3) times its two products (f itself was rounded once), which bounds the error of disc.
    if disc < like(disc, 0.0):
        g3 = gamma(3, fx)
        error = g3 * (abs(fy * dz) + abs(fz * dy) + abs(fz * dx) + abs(fx * dz)
                      + abs(fx * dy) + abs(fy * dx))
        scale = k2 * (abs(qx) + abs(qy) + abs(qz)) + abs(mw)
        bound = (like(fx, 2.0) * scale + (like(fx, 1.0) + k2) * error) * error + g3 * (
            k2 * dot(qx, qy, qz, qx, qy, qz) + mw * mw)
        if -disc <= bound:
            disc = like(disc, 0.0)
    return disc


@inline_kernel
def hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """Nearest crossing in ``[tmin, tmax]`` as ``(t, part)``; ``(inf, -1)`` on a miss."""
    wx, wy, wz = params[6], params[7], params[8]
    gx, gy, gz = ox - params[3], oy - params[4], oz - params[5]
    fw, fx, fy, fz = axial_split(gx, gy, gz, wx, wy, wz)
    dw, px, py, pz = axial_split(dx, dy, dz, wx, wy, wz)
    k2 = params[12]
    a = dot(px, py, pz, px, py, pz) - k2 * dw * dw
    b = dot(fx, fy, fz, px, py, pz) - k2 * fw * dw
    c = dot(fx, fy, fz, fx, fy, fz) - k2 * fw * fw
    t0, t1 = stable_roots(a, b, c, _discriminant(gx, gy, gz, dx, dy, dz, wx, wy, wz, k2))
    t, part = miss(ox)
    # Both nappes meet at the apex, where a root's axial coordinate s = fw + t dw is computed
    # with a few roundings: a ray leaving through the apex can land on s > 0 by rounding alone.
    # Accepting s up to that error keeps the apex closed; it admits nothing of the other nappe
    # farther than rounding from the apex.
    slack = gamma(4, ox)
    t, part = closer_on_side(t0, fw, dw, -params[9], slack * (abs(fw) + abs(t0 * dw)), t, part,
                             tmin, tmax)
    t, part = closer_on_side(t1, fw, dw, -params[9], slack * (abs(fw) + abs(t1 * dw)), t, part,
                             tmin, tmax)
    cap = disk_hit(params[0], params[1], params[2], wx, wy, wz, params[11], ox, oy, oz, dx, dy, dz)
    return closer(cap, 1, t, part, tmin, tmax)


@inline_kernel
def surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """Unit outward normal and ``(u, v)`` (see the module docstring; :func:`no_uv` unless
    ``want_uv``) at ``o + t d``."""
    wx, wy, wz = params[6], params[7], params[8]
    s, qx, qy, qz = axial_split(
        (ox - params[3]) + t * dx, (oy - params[4]) + t * dy, (oz - params[5]) + t * dz,
        wx, wy, wz,
    )
    if part != 0:
        normal = (-wx, -wy, -wz)
    else:
        lean = params[12] * s
        gx, gy, gz = qx - lean * wx, qy - lean * wy, qz - lean * wz
        normal = (wx, wy, wz) if dot(gx, gy, gz, gx, gy, gz) == like(ox, 0.0) \
            else normalized(gx, gy, gz)
    if not want_uv:
        return normal + no_uv(ox)
    u, v = polar_uv(
        qx, qy, qz, params[13], params[14], params[15], params[16], params[17], params[18],
        params[10],
    )
    return normal + (u, clamp01(like(ox, 1.0) + s / params[9]) if part == 0 else v)
