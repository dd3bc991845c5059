"""Ray/box intersection: an axis-aligned box, and a box under an affine transform.

Axis-aligned box, parameters row ``[lox, loy, loz, hix, hiy, hiz]``: :func:`pack`, :func:`hit`,
:func:`surface`, :func:`bounds`.

Transformed box, parameters row ``[lo (3), hi (3), m (12)]`` with ``m`` the inverse of the 4x4
transform's top 3x4 rows, row-major (world -> local): :func:`pack_transformed`,
:func:`hit_transformed`, :func:`surface_transformed`, :func:`bounds_transformed`.  The ray is
mapped into the box's local frame, where the same slab test runs; an affine map keeps ``t``.

The slab test (Kay–Kajiya, as in pbrt's ``Bounds3::IntersectP``) is written for the edge cases:

* slab distances use ``1 / d``, which is ±inf for a zero component; with ``d + 0`` first, so that
  ``-0`` and ``+0`` both give ``+inf`` and a ray behaves the same whatever the sign of its zeros;
* a ray parallel to a slab with its origin on the slab's plane gives ``0 · inf = NaN``; every
  comparison is written so that NaN falls through to "no narrowing": the boundary is inside
  (inclusive), consistently for all axis-parallel rays on face planes;
* a NaN or infinite ray component anywhere is a miss;
* the exit distance is widened by ``2 γ(3) |t_far|`` before the enter <= exit test (Ize 2013,
  "Robust BVH ray traversal"), so that rounding cannot open a crack along edges and corners.

A ray starting inside returns the exit (far side).  Parts are faces: ``2k`` is the face at lo
and ``2k + 1`` the face at hi on axis ``k`` (0 -x, 1 +x, 2 -y, 3 +y, 4 -z, 5 +z).

Surface: the normal is the face's outward normal (for the transformed box, the local normal
mapped by the inverse transpose and normalised).  ``(u, v)`` are face-local coordinates in
[0, 1]: for a face on axis k, ``u`` runs from lo to hi along axis ``(k + 1) % 3`` and ``v`` along
axis ``(k + 2) % 3`` (local axes for the transformed box).
"""

import numpy as np

from raycore._fp import gamma, like
from raycore.mesh import affine_inverse, condition_number, transform_points
from raycore.primitives._common import (
    as_point,
    clamp01,
    in_range,
    inline_kernel,
    miss,
    no_uv,
    normalized,
    param_row,
    widen,
)
from raycore.rays import as_float_array

#: Largest condition number (:func:`raycore.mesh.condition_number`) accepted for a transform's
#: linear part: beyond it, float32 rays in the local frame would carry no correct digit.
MAX_CONDITION = 2.0**23


def pack(lo, hi):
    """Parameter row of the axis-aligned box ``[lo, hi]``.

    Parameters
    ----------
    lo, hi : array_like, shape (3,)
        Corners with ``lo < hi`` on every axis.

    Returns
    -------
    ndarray, shape (PARAM_WIDTH,)

    Raises
    ------
    ValueError
        Naming ``lo`` or ``hi``; a flat or inverted box (``lo >= hi`` on some axis) is refused.
    """
    lo = as_point(lo, "lo")
    hi = as_point(hi, "hi")
    if not np.all(lo < hi):
        raise ValueError(f"hi must be greater than lo on every axis, got lo={lo}, hi={hi}")
    return param_row(lo, hi)


def pack_transformed(lo, hi, transform):
    """Parameter row of the box ``[lo, hi]`` mapped to the world by an affine ``transform``.

    Parameters
    ----------
    lo, hi : array_like, shape (3,)
        Corners in the box's local frame, ``lo < hi`` on every axis.
    transform : array_like, shape (4, 4)
        Local -> world, acting on column vectors ``(x, y, z, 1)``; the last row must be
        ``[0, 0, 0, 1]`` and the linear part invertible (condition number below 2**23).

    Returns
    -------
    ndarray, shape (PARAM_WIDTH,)

    Raises
    ------
    ValueError
        Naming ``lo``, ``hi`` or ``transform``.
    """
    box = pack(lo, hi)
    matrix = as_float_array(transform, "transform", np.float64, (4, 4))
    if not np.array_equal(matrix[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"transform must be affine (last row [0, 0, 0, 1]), got {matrix[3]}")
    if not condition_number(matrix[:3, :3]) < MAX_CONDITION:
        raise ValueError("transform must be invertible: its linear part is singular or nearly so")
    # rounded once from the exact inverse: the same bits on every CPU, unlike np.linalg.inv
    return param_row(box[:6], affine_inverse(matrix).ravel())


def bounds(params):
    """The box itself: ``(lo, hi)``, two (3,) float64 arrays."""
    params = np.asarray(params, dtype=np.float64)
    return params[:3].copy(), params[3:6].copy()


def bounds_transformed(params):
    """Bounds of the eight transformed corners, ``(lo, hi)``, two (3,) float64 arrays."""
    params = np.asarray(params, dtype=np.float64)
    # the kernels test the box that the stored world -> local map sends to [lo, hi]: its exact
    # inverse, rounded once
    to_world = affine_inverse(params[6:18].reshape(3, 4))
    corners = np.array(np.meshgrid(*zip(params[:3], params[3:6], strict=True), indexing="ij"))
    corners = corners.reshape(3, 8).T
    world = transform_points(to_world, corners)
    # each coordinate is within γ(4)·(|L| |c| + |t|) of the exact corner's
    slack = gamma(4, 1.0) * transform_points(np.abs(to_world), np.abs(corners)).max(axis=0)
    return widen(world.min(axis=0) - slack, world.max(axis=0) + slack)


@inline_kernel
def _narrow(lo, hi, o, d, axis, tnear, tfar, near, far):
    """Intersect the running interval ``[tnear, tfar]`` with one slab; NaN never narrows it."""
    inv = like(d, 1.0) / (d + like(d, 0.0))
    t0 = (lo - o) * inv
    t1 = (hi - o) * inv
    face0 = 2 * axis
    face1 = face0 + 1
    if t0 > t1:
        t0, t1 = t1, t0
        face0, face1 = face1, face0
    if t0 > tnear:
        tnear, near = t0, face0
    if t1 < tfar:
        tfar, far = t1, face1
    return tnear, tfar, near, far


@inline_kernel
def _slab(params, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Slab test against ``[params[0:3], params[3:6]]``: ``(t, face)`` or ``(inf, -1)``."""
    zero = like(ox, 0.0)
    # x - x is 0 for finite x and NaN for NaN or ±inf (not folded away without fast-math)
    if (ox - ox) + (oy - oy) + (oz - oz) + (dx - dx) + (dy - dy) + (dz - dz) != zero:
        return miss(ox)
    inf = like(ox, np.inf)
    tnear, tfar, near, far = -inf, inf, -1, -1
    tnear, tfar, near, far = _narrow(params[0], params[3], ox, dx, 0, tnear, tfar, near, far)
    tnear, tfar, near, far = _narrow(params[1], params[4], oy, dy, 1, tnear, tfar, near, far)
    tnear, tfar, near, far = _narrow(params[2], params[5], oz, dz, 2, tnear, tfar, near, far)
    if not (tnear <= tfar + like(ox, 2.0) * gamma(3, ox) * abs(tfar)):
        return miss(ox)
    if in_range(tnear, tmin, tmax):
        return tnear, near
    if in_range(tfar, tmin, tmax):
        return tfar, far
    return miss(ox)


@inline_kernel
def _to_local(params, ox, oy, oz, dx, dy, dz):
    """Map a ray by the 3x4 world -> local matrix ``params[6:18]`` (the origin gets the
    translation, the direction does not)."""
    m = params
    lx = m[6] * ox + m[7] * oy + m[8] * oz + m[9]
    ly = m[10] * ox + m[11] * oy + m[12] * oz + m[13]
    lz = m[14] * ox + m[15] * oy + m[16] * oz + m[17]
    ldx = m[6] * dx + m[7] * dy + m[8] * dz
    ldy = m[10] * dx + m[11] * dy + m[12] * dz
    ldz = m[14] * dx + m[15] * dy + m[16] * dz
    return lx, ly, lz, ldx, ldy, ldz


@inline_kernel
def _face_uv(params, ox, oy, oz, dx, dy, dz, t, part):
    """Face-local ``(u, v)`` in [0, 1] of ``o + t d`` on face ``part``."""
    o = (ox, oy, oz)
    d = (dx, dy, dz)
    axis = part // 2
    i = (axis + 1) % 3
    j = (axis + 2) % 3
    # offsets from lo as (o - lo) + t d, without cancellation at large coordinates
    u = ((o[i] - params[i]) + t * d[i]) / (params[3 + i] - params[i])
    v = ((o[j] - params[j]) + t * d[j]) / (params[3 + j] - params[j])
    return clamp01(u), clamp01(v)


@inline_kernel
def hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """Nearest face crossing in ``[tmin, tmax]`` as ``(t, face)``; ``(inf, -1)`` on a miss."""
    return _slab(params, ox, oy, oz, dx, dy, dz, tmin, tmax)


@inline_kernel
def surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """The face's unit outward normal and face-local ``(u, v)`` of ``o + t d`` (:func:`no_uv`
    unless ``want_uv``)."""
    zero = like(ox, 0.0)
    sign = like(ox, 1.0) if part % 2 == 1 else like(ox, -1.0)
    axis = part // 2
    normal = (sign if axis == 0 else zero, sign if axis == 1 else zero,
              sign if axis == 2 else zero)
    if not want_uv:
        return normal + no_uv(ox)
    return normal + _face_uv(params, ox, oy, oz, dx, dy, dz, t, part)


@inline_kernel
def hit_transformed(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """As :func:`hit`, for the transformed box (the ray is mapped into the local frame)."""
    lx, ly, lz, ldx, ldy, ldz = _to_local(params, ox, oy, oz, dx, dy, dz)
    return _slab(params, lx, ly, lz, ldx, ldy, ldz, tmin, tmax)


@inline_kernel
def surface_transformed(params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """As :func:`surface`, for the transformed box: world normal, local face coordinates."""
    # the inverse transpose maps the local normal ±e_k to ± (row k of the world -> local matrix)
    row = 6 + 4 * (part // 2)
    sign = like(ox, 1.0) if part % 2 == 1 else like(ox, -1.0)
    normal = normalized(sign * params[row], sign * params[row + 1], sign * params[row + 2])
    if not want_uv:
        return normal + no_uv(ox)
    lx, ly, lz, ldx, ldy, ldz = _to_local(params, ox, oy, oz, dx, dy, dz)
    return normal + _face_uv(params, lx, ly, lz, ldx, ldy, ldz, t, part)
