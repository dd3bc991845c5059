"""Pieces shared by the analytic shape modules.

Python side (used by every ``pack`` and ``bounds``): argument validation that names the argument,
an orthonormal frame around an axis, the fixed-width parameter row, disk extents and bound padding.

Kernel side (compiled inline into every shape's ``hit`` and ``surface``; each computes in the
precision of its arguments):

* :func:`in_range` and :func:`closer` accept a root only when ``tmin <= t <= tmax`` and ``t`` is
  finite, written so that NaN fails every test: a NaN in a ray or its bounds becomes a miss,
  never ``t = NaN``;
* :func:`stable_roots` is the one quadratic solver (sphere, cylinder, cone), and
  :func:`precise_discriminant` the Hearn–Baker discriminant used by the sphere and the cylinder;
* :func:`disk_hit` is the one disk test (disk, cylinder caps, cone base).
"""

import math

import numpy as np
from numba import njit

from raycore._fp import like
from raycore.rays import as_float_array

#: Width of a shape's parameter row (unused slots are 0).
PARAM_WIDTH = 20


# ----------------------------------------------------------------------------- Python side


def as_point(value, name):
    """Return ``value`` as a finite (3,) float64 array, or raise ``ValueError`` naming ``name``."""
    return as_float_array(value, name, np.float64, (3,))


def as_radius(value, name="radius"):
    """Return ``value`` as a positive finite float whose square is finite too."""
    radius = as_float_array(value, name, np.float64, ()).item()
    if not (radius > 0 and math.isfinite(radius * radius)):
        raise ValueError(f"{name} must be positive and finite, got {radius!r}")
    return radius


def as_unit(vector, name, message="must be non-zero", shortest=0.0):
    """Return ``vector / |vector|`` and its length; raise ``ValueError`` naming ``name`` unless
    the length is finite and above ``shortest`` (a cross product or a projection of unit
    vectors that short leaves no direction to speak of)."""
    # not np.linalg.norm: its dot product runs an OpenBLAS kernel whose last bit depends on the CPU
    x, y, z = np.asarray(vector, np.float64).tolist()
    length = math.sqrt((x * x + y * y) + z * z)
    largest = max(abs(x), abs(y), abs(z))
    if not (length > 0 and math.isfinite(length)) and 0 < largest < math.inf:
        # its squares overflowed (from about 1e154) or vanished: scaled to its largest component
        # first (only then, so that every other vector keeps the bits it had)
        x, y, z = x / largest, y / largest, z / largest
        length = largest * math.sqrt((x * x + y * y) + z * z)
    if not (length > shortest and math.isfinite(length)):
        raise ValueError(f"{name} {message}")
    return vector / length, length


def exact_direction(vector):
    """``vector`` scaled by a power of two to a largest component in [0.5, 1).

    The scaling is exact, so tests of a ray against the plane of this normal see the plane the
    caller gave: a ray parallel to it in exact arithmetic stays parallel (dividing by the norm
    would round the normal and tilt the plane by an ulp).
    """
    return np.ldexp(vector, -np.frexp(np.max(np.abs(vector)))[1])


def orthonormal_frame(n):
    """Return unit vectors ``e1, e2`` with ``(e1, e2, n)`` a right-handed orthonormal basis.

    The branchless construction of Duff et al. 2017 ("Building an orthonormal basis, revisited",
    JCGT 6(1)): no singular direction (the sign switch avoids the one at ``n = -z``); the frame
    jumps only where ``n`` crosses the plane ``n_z = 0``.  For ``n = +z`` it is ``(+x, +y)``.

    Parameters
    ----------
    n : ndarray, shape (3,)
        Unit vector.
    """
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    e1 = np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    e2 = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    return e1, e2


def param_row(*values):
    """Concatenate scalars and vectors into a (PARAM_WIDTH,) float64 row, zero-padded."""
    flat = np.concatenate([np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in values])
    row = np.zeros(PARAM_WIDTH)
    row[: len(flat)] = flat
    return row


def disk_extent(axis, radius):
    """Half-extent per coordinate of a disk of ``radius`` with unit normal ``axis``: (3,) array."""
    return radius * np.sqrt(np.maximum(0.0, 1.0 - axis * axis))


def widen(lo, hi):
    """Pad computed bounds by a few float64 ulps so that rounding never makes them too tight."""
    pad = 16 * np.finfo(np.float64).eps * np.maximum(np.abs(lo), np.abs(hi))
    return lo - pad, hi + pad


# ----------------------------------------------------------------------------- kernels

#: Decorator of every shape kernel: compiled once with IEEE division (``x / 0`` is ±inf or NaN,
#: where Numba's default raises ``ZeroDivisionError``) and inlined by LLVM (``forceinline``).
#: Inlined by Numba instead (``inline="always"``), every caller re-typed and re-lowered each
#: shape: the traversal's first compile spent 54 of its 75 s in the analytic shapes.
inline_kernel = njit(cache=True, forceinline=True, error_model="numpy")


@inline_kernel
def dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@inline_kernel
def axial_split(x, y, z, wx, wy, wz):
    """Split ``(x, y, z)`` into its coordinate along the unit axis w and the perpendicular rest."""
    s = dot(x, y, z, wx, wy, wz)
    return s, x - s * wx, y - s * wy, z - s * wz


@inline_kernel
def miss(x):
    """The ``(t, part)`` of a miss in the precision of ``x``."""
    return like(x, np.inf), -1


@inline_kernel
def in_range(t, tmin, tmax):
    """Whether ``t`` is a finite root in ``[tmin, tmax]``; false for NaN."""
    return tmin <= t and t <= tmax and abs(t) < like(t, np.inf)


@inline_kernel
def closer(t, part, best_t, best_part, tmin, tmax):
    """Keep candidate root ``t`` of surface ``part`` if it is in range and nearer than the best."""
    if in_range(t, tmin, tmax) and t < best_t:
        return t, part
    return best_t, best_part


@inline_kernel
def precise_discriminant(fx, fy, fz, dx, dy, dz, a, b, r2):
    """Quarter discriminant ``b² - a c`` of ``|f + t d|² = r²`` in Hearn and Baker's form.

    ``b² - a (f·f - r²)`` equals ``a (r² - |f - (b/a) d|²)``: the vector ``f - (b/a) d`` joins the
    centre to the closest point of the line, so its length is of the order of r and the
    subtraction of two numbers of the order of |f|² (catastrophic for a small sphere seen from
    far away) is avoided (Ray Tracing Gems, ch. 7).  ``b = f·d``, ``a = d·d``.
    """
    s = b / a
    lx = fx - s * dx
    ly = fy - s * dy
    lz = fz - s * dz
    return a * (r2 - dot(lx, ly, lz, lx, ly, lz))


@inline_kernel
def closer_on_side(t, s0, ds, s_lo, s_hi, best_t, best_part, tmin, tmax):
    """:func:`closer` for a root of a lateral surface (part 0), kept only where its axial
    coordinate ``s0 + t ds`` lies in ``[s_lo, s_hi]``."""
    s = s0 + t * ds
    if s_lo <= s and s <= s_hi:
        return closer(t, 0, best_t, best_part, tmin, tmax)
    return best_t, best_part


@inline_kernel
def stable_roots(a, b, c, disc):
    """Roots of ``a t² + 2 b t + c = 0`` given its quarter discriminant ``disc = b² - a c``.

    The root of larger magnitude comes from ``q = -(b + sign(b) √disc)``, which adds numbers of
    one sign, and the other from ``c / q`` (Vieta), so neither suffers cancellation.  A double
    root (``disc == 0``) is returned twice: tangent rays hit.  When ``a == 0`` (a ray parallel to
    a cone's surface) the equation is linear, ``t = -c / 2b``.  Returns ``(inf, inf)`` for no
    real root; the roots are not sorted.
    """
    inf = like(a, np.inf)
    if a == like(a, 0.0):
        if b == like(b, 0.0):
            return inf, inf
        return -c / (like(b, 2.0) * b), inf
    if not (disc >= like(disc, 0.0)):
        return inf, inf
    root = math.sqrt(disc)
    q = -(b + root) if b >= like(b, 0.0) else root - b
    if q == like(q, 0.0):
        # b = 0 and disc = 0: the double root -b/a is 0
        return q / a, q / a
    return c / q, q / a


@inline_kernel
def disk_hit(cx, cy, cz, nx, ny, nz, r2, ox, oy, oz, dx, dy, dz):
    """Ray parameter where the ray crosses the disk (centre c, normal n of any length, squared
    radius r2).

    Returns ``inf`` when the ray is parallel to the disk's plane or crosses it outside the disk
    (the rim counts as inside).  The range check is left to the caller.
    """
    fx = ox - cx
    fy = oy - cy
    fz = oz - cz
    t = -dot(nx, ny, nz, fx, fy, fz) / dot(nx, ny, nz, dx, dy, dz)
    # the offset from the centre as (o - c) + t d, which keeps its accuracy far from the origin
    px = fx + t * dx
    py = fy + t * dy
    pz = fz + t * dz
    # a parallel ray gives t = ±inf or NaN and so an infinite or NaN offset, which fails this test
    if dot(px, py, pz, px, py, pz) <= r2:
        return t
    return like(t, np.inf)


@inline_kernel
def clamp01(x):
    """Clamp to [0, 1]; rounding can push a surface coordinate just outside."""
    return min(max(x, like(x, 0.0)), like(x, 1.0))


@inline_kernel
def azimuth(x, y):
    """``atan2(y, x) / 2π`` wrapped into [0, 1)."""
    u = math.atan2(y, x) / like(x, 2.0 * math.pi)
    if u < like(u, 0.0):
        u += like(u, 1.0)
    # -tiny + 1 rounds to 1, which belongs to the start of the period
    return u if u < like(u, 1.0) else like(u, 0.0)


@inline_kernel
def no_uv(x):
    """``(u, v)`` where a caller asks a shape's surface for its normal only: NaN, of ``x``'s
    precision.  Left unused, the shapes' own (u, v) were computed all the same: atan2 and acos
    are library calls, which the compiler does not drop."""
    nan = like(x, np.nan)
    return nan, nan


@inline_kernel
def polar_uv(px, py, pz, e1x, e1y, e1z, e2x, e2y, e2z, radius):
    """Polar coordinates of an in-plane offset p: ``u`` = angle from e1 towards e2 / 2π in [0, 1),
    ``v`` = distance / radius in [0, 1]."""
    u = azimuth(dot(px, py, pz, e1x, e1y, e1z), dot(px, py, pz, e2x, e2y, e2z))
    v = clamp01(math.sqrt(dot(px, py, pz, px, py, pz)) / radius)
    return u, v


@inline_kernel
def normalized(x, y, z):
    """``(x, y, z) / |(x, y, z)|``; NaN for the zero vector."""
    length = math.sqrt(dot(x, y, z, x, y, z))
    return x / length, y / length, z / length
