"""Ray/sphere intersection with three methods of computing the roots.

Parameters row: ``[cx, cy, cz, r, r²]`` (r² rounded once from float64).

Methods (``method`` argument of :func:`hit`):

* ``PRECISE`` (0, default): the stable quadratic (:func:`stable_roots`) with Hearn and Baker's
  discriminant (Ray Tracing Gems ch. 7), accurate for small spheres seen from far away;
* ``GEOMETRIC`` (1): Scratchapixel's geometric solution, projecting the centre on the ray and
  applying Pythagoras, ``d² = |L|² - tca²``, which cancels catastrophically when |L| ≫ r;
* ``ANALYTIC`` (2): the textbook ``(-b ± √(b² - 4ac)) / 2a``, which cancels in ``b² - 4ac`` and
  in ``-b + √…``.

The latter two exist to be measured against the first (DESIGN.md, "Numerics").

Surface: ``part`` is always 0.  The normal is ``(p - c) / |p - c|``.  With ``(x, y, z)`` the
unit offset of the hit point from the centre, ``u = φ / 2π`` in [0, 1) with
``φ = atan2(y, x)`` the azimuth around the world z axis measured from +x, and ``v = θ / π`` in
[0, 1] with ``θ = acos(z)`` the polar angle from +z (v = 0 at the +z pole).
"""

import math

import numpy as np

from raycore._fp import like
from raycore.primitives._common import (
    as_point,
    as_radius,
    azimuth,
    clamp01,
    closer,
    dot,
    inline_kernel,
    miss,
    no_uv,
    normalized,
    param_row,
    precise_discriminant,
    stable_roots,
    widen,
)

PRECISE = 0
GEOMETRIC = 1
ANALYTIC = 2


def pack(center, radius):
    """Parameter row of a sphere.

    Parameters
    ----------
    center : array_like, shape (3,)
    radius : float
        Positive.

    Returns
    -------
    ndarray, shape (PARAM_WIDTH,)

    Raises
    ------
    ValueError
        Naming ``center`` or ``radius``.
    """
    radius = as_radius(radius)
    return param_row(as_point(center, "center"), radius, radius * radius)


def bounds(params):
    """Axis-aligned bounds ``(lo, hi)``, two (3,) float64 arrays."""
    params = np.asarray(params, dtype=np.float64)
    center, radius = params[:3], params[3]
    return widen(center - radius, center + radius)


@inline_kernel
def _geometric_roots(fx, fy, fz, dx, dy, dz, r2):
    # Scratchapixel works with a unit direction; scale its distances back to units of |d|
    inf = like(fx, np.inf)
    length = math.sqrt(dot(dx, dy, dz, dx, dy, dz))
    tca = -dot(fx, fy, fz, dx, dy, dz) / length
    d2 = dot(fx, fy, fz, fx, fy, fz) - tca * tca
    if not (d2 <= r2):
        return inf, inf
    thc = math.sqrt(r2 - d2)
    return (tca - thc) / length, (tca + thc) / length


@inline_kernel
def _analytic_roots(fx, fy, fz, dx, dy, dz, r2):
    inf = like(fx, np.inf)
    two = like(fx, 2.0)
    a = dot(dx, dy, dz, dx, dy, dz)
    b = two * dot(fx, fy, fz, dx, dy, dz)
    c = dot(fx, fy, fz, fx, fy, fz) - r2
    disc = b * b - like(fx, 4.0) * a * c
    if not (disc >= like(disc, 0.0)):
        return inf, inf
    root = math.sqrt(disc)
    return (-b - root) / (two * a), (-b + root) / (two * a)


@inline_kernel
def _precise_roots(fx, fy, fz, dx, dy, dz, r2):
    a = dot(dx, dy, dz, dx, dy, dz)
    b = dot(fx, fy, fz, dx, dy, dz)
    c = dot(fx, fy, fz, fx, fy, fz) - r2
    return stable_roots(a, b, c, precise_discriminant(fx, fy, fz, dx, dy, dz, a, b, r2))


@inline_kernel
def hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """Nearest root in ``[tmin, tmax]`` as ``(t, 0)``; ``(inf, -1)`` on a miss."""
    fx = ox - params[0]
    fy = oy - params[1]
    fz = oz - params[2]
    r2 = params[4]
    if method == GEOMETRIC:
        t0, t1 = _geometric_roots(fx, fy, fz, dx, dy, dz, r2)
    elif method == ANALYTIC:
        t0, t1 = _analytic_roots(fx, fy, fz, dx, dy, dz, r2)
    else:
        t0, t1 = _precise_roots(fx, fy, fz, dx, dy, dz, r2)
    t, part = miss(ox)
    t, part = closer(t0, 0, t, part, tmin, tmax)
    return closer(t1, 0, t, part, tmin, tmax)


@inline_kernel
def surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """Unit outward normal and ``(u, v)`` (see the module docstring; :func:`no_uv` unless
    ``want_uv``) at ``o + t d``."""
    # offset from the centre as (o - c) + t d: no cancellation of large coordinates
    ex = (ox - params[0]) + t * dx
    ey = (oy - params[1]) + t * dy
    ez = (oz - params[2]) + t * dz
    if ex == 0 and ey == 0 and ez == 0:
        # a sphere below the precision's resolution: the hit point rounds onto its centre, and
        # the surface the ray met faces it
        ex, ey, ez = -dx, -dy, -dz
    nx, ny, nz = normalized(ex, ey, ez)
    if not want_uv:
        return (nx, ny, nz) + no_uv(nx)
    u = azimuth(nx, ny)
    v = math.acos(min(max(nz, like(nz, -1.0)), like(nz, 1.0))) / like(nz, math.pi)
    return nx, ny, nz, u, clamp01(v)
