"""Independent references for the analytic shapes; they share no code with raycore.

Two families, both in plain Python:

* Scalar, one ray at a time, written for clarity (``*_mpmath``, ``*_fraction``): mpmath at 50
  digits for the sphere, the cylinder and the cone (the quadratic and the caps solved in mpmath),
  and ``fractions.Fraction`` for the plane, the disk, the box and the transformed box (a float is
  exactly a Fraction, so these are exact).  They serve the analytic cases and check the second
  family.
* Vectorised and exact (``sphere``, ``plane``, ...), for the 100k-ray bars, where the scalar ones
  would take minutes (mpmath has no gmpy backend here).  Every input float is written as an
  integer over one common power of two, every polynomial is evaluated exactly in Python integers
  (NumPy object arrays), and every hit/miss decision is an exact sign: a root
  ``(x + y√D) / den`` is compared with a bound through squares of integers, never rounded.  Only
  the returned t is rounded, once: an integer square root with 256 guard bits in the
  cancellation-free form of the quadratic formula, then Python's correctly rounded int / int.

Every function takes the rays (origins and directions, (N, 3) floats, or (3,) for the scalar
ones), the shape's parameters as a user gives them (normals and axes of any length), and the
bounds ``tmin``, ``tmax`` ((N,) arrays, or floats; ``tmax`` may be inf).  It returns the nearest
t with ``tmin <= t <= tmax`` on the shape's surface, as float64, inf where there is none.  Shapes
are closed sets: rims, edges and tangent points count.
"""

import math
from collections import namedtuple
from fractions import Fraction

import mpmath
import numpy as np

# ============================================================================ scalar references

DIGITS = 50


def _nearest(candidates, tmin, tmax):
    """The smallest candidate t with ``tmin <= t <= tmax`` as a float, inf if none."""
    kept = [t for t in candidates if tmin <= t <= tmax]
    return float(min(kept)) if kept else math.inf


def _mp_dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _mp_vector(values):
    return [mpmath.mpf(float(x)) for x in values]


def _mp_cap(o, d, center, axis, radius):
    """The t where the ray crosses the disk (centre, unit axis, radius), or None."""
    denominator = _mp_dot(d, axis)
    if denominator == 0:
        return None
    t = _mp_dot([c - x for c, x in zip(center, o, strict=True)], axis) / denominator
    offset = [x + t * y - c for x, y, c in zip(o, d, center, strict=True)]
    return t if _mp_dot(offset, offset) <= radius**2 else None


def _mp_quadratic(a, b, c):
    """Real roots of a t² + 2 b t + c = 0 (a list, a double root twice; linear when a = 0)."""
    if a == 0:
        return [] if b == 0 else [-c / (2 * b)]
    disc = b * b - a * c
    if disc < 0:
        return []
    root = mpmath.sqrt(disc)
    return [(-b - root) / a, (-b + root) / a]


def sphere_mpmath(o, d, center, radius, tmin=0.0, tmax=math.inf):
    """Nearest hit of one ray with a sphere, in mpmath."""
    with mpmath.workdps(DIGITS):
        o, d, center = _mp_vector(o), _mp_vector(d), _mp_vector(center)
        f = [x - c for x, c in zip(o, center, strict=True)]
        roots = _mp_quadratic(
            _mp_dot(d, d), _mp_dot(f, d), _mp_dot(f, f) - mpmath.mpf(float(radius)) ** 2
        )
        return _nearest(roots, tmin, tmax)


def _mp_axis_frame(start, end):
    """Unit axis from start to end, and the length."""
    axis = [e - s for s, e in zip(start, end, strict=True)]
    length = mpmath.sqrt(_mp_dot(axis, axis))
    return [x / length for x in axis], length


def _mp_perp(v, axis):
    s = _mp_dot(v, axis)
    return s, [x - s * w for x, w in zip(v, axis, strict=True)]


def cylinder_mpmath(o, d, p0, p1, radius, tmin=0.0, tmax=math.inf):
    """Nearest hit of one ray with a capped cylinder, in mpmath."""
    with mpmath.workdps(DIGITS):
        o, d, p0, p1 = _mp_vector(o), _mp_vector(d), _mp_vector(p0), _mp_vector(p1)
        r = mpmath.mpf(float(radius))
        w, h = _mp_axis_frame(p0, p1)
        fw, fp = _mp_perp([x - p for x, p in zip(o, p0, strict=True)], w)
        dw, dp = _mp_perp(d, w)
        roots = _mp_quadratic(_mp_dot(dp, dp), _mp_dot(fp, dp), _mp_dot(fp, fp) - r * r)
        candidates = [t for t in roots if 0 <= fw + t * dw <= h]
        for center in (p0, p1):
            t = _mp_cap(o, d, center, w, r)
            if t is not None:
                candidates.append(t)
        return _nearest(candidates, tmin, tmax)


def cone_mpmath(o, d, base_center, apex, radius, tmin=0.0, tmax=math.inf):
    """Nearest hit of one ray with a cone capped at its base, in mpmath."""
    with mpmath.workdps(DIGITS):
        o, d = _mp_vector(o), _mp_vector(d)
        base, apex = _mp_vector(base_center), _mp_vector(apex)
        r = mpmath.mpf(float(radius))
        w, h = _mp_axis_frame(base, apex)
        k2 = (r / h) ** 2
        # g = x - apex = f + t d; the double cone is |g_perp|² = k² (g·w)²; the real nappe has
        # -h <= g·w <= 0
        fw, fp = _mp_perp([x - a for x, a in zip(o, apex, strict=True)], w)
        dw, dp = _mp_perp(d, w)
        roots = _mp_quadratic(
            _mp_dot(dp, dp) - k2 * dw * dw,
            _mp_dot(fp, dp) - k2 * fw * dw,
            _mp_dot(fp, fp) - k2 * fw * fw,
        )
        candidates = [t for t in roots if -h <= fw + t * dw <= 0]
        t = _mp_cap(o, d, base, w, r)
        if t is not None:
            candidates.append(t)
        return _nearest(candidates, tmin, tmax)


def _fractions(values):
    return [Fraction(float(x)) for x in values]


def _fr_dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _fr_plane_t(o, d, point, normal):
    """The t where the ray crosses the plane, or None when it is parallel to it."""
    denominator = _fr_dot(d, normal)
    if denominator == 0:
        return None
    return _fr_dot([p - x for p, x in zip(point, o, strict=True)], normal) / denominator


def plane_fraction(o, d, point, normal, tmin=0.0, tmax=math.inf):
    """Nearest hit of one ray with a plane, exact."""
    t = _fr_plane_t(_fractions(o), _fractions(d), _fractions(point), _fractions(normal))
    return math.inf if t is None else _nearest([t], tmin, tmax)


def disk_fraction(o, d, center, normal, radius, tmin=0.0, tmax=math.inf):
    """Nearest hit of one ray with a disk, exact (squared distances compared exactly)."""
    o, d, center = _fractions(o), _fractions(d), _fractions(center)
    t = _fr_plane_t(o, d, center, _fractions(normal))
    if t is None:
        return math.inf
    offset = [x + t * y - c for x, y, c in zip(o, d, center, strict=True)]
    if _fr_dot(offset, offset) > Fraction(float(radius)) ** 2:
        return math.inf
    return _nearest([t], tmin, tmax)


def _fr_slabs(lo, hi, o, d, tmin, tmax):
    """Exact slab test on Fractions: the entry if in range, else the exit, else inf."""
    enter, leave = None, None
    for low, high, x, y in zip(lo, hi, o, d, strict=True):
        if y == 0:
            if not low <= x <= high:
                return math.inf
            continue
        t0, t1 = sorted(((low - x) / y, (high - x) / y))
        enter = t0 if enter is None else max(enter, t0)
        leave = t1 if leave is None else min(leave, t1)
    if enter > leave:
        return math.inf
    for t in (enter, leave):
        if tmin <= t <= tmax:
            return float(t)
    return math.inf


def box_fraction(o, d, lo, hi, tmin=0.0, tmax=math.inf):
    """Nearest hit of one ray with the axis-aligned box [lo, hi], exact."""
    return _fr_slabs(_fractions(lo), _fractions(hi), _fractions(o), _fractions(d), tmin, tmax)


def fraction_inverse(m):
    """Exact inverse of a 3x3 matrix of Fractions (Gauss–Jordan)."""
    rows = [list(row) + [Fraction(int(i == j)) for j in range(3)] for i, row in enumerate(m)]
    for col in range(3):
        pivot = next(r for r in range(col, 3) if rows[r][col] != 0)
        rows[col], rows[pivot] = rows[pivot], rows[col]
        rows[col] = [x / rows[col][col] for x in rows[col]]
        for r in range(3):
            if r != col:
                factor = rows[r][col]
                rows[r] = [x - factor * y for x, y in zip(rows[r], rows[col], strict=True)]
    return [row[3:] for row in rows]


def transformed_box_fraction(o, d, lo, hi, transform, tmin=0.0, tmax=math.inf):
    """Nearest hit of one ray with the box [lo, hi] under an affine transform, exact."""
    matrix = [_fractions(row) for row in np.asarray(transform)[:3]]
    inverse = fraction_inverse([row[:3] for row in matrix])
    offset = [x - row[3] for x, row in zip(_fractions(o), matrix, strict=True)]
    local_o = [_fr_dot(row, offset) for row in inverse]
    local_d = [_fr_dot(row, _fractions(d)) for row in inverse]
    return _fr_slabs(_fractions(lo), _fractions(hi), local_o, local_d, tmin, tmax)


# ============================================================================ vectorised, exact

GUARD_BITS = 256

#: A root ``(x + y √disc) / den`` of each ray (object arrays of ints; ``y`` is 0 for a rational
#: root), where ``valid``, and its float64 value (rounded once).
Root = namedtuple("Root", "x y disc den valid value")


def _powers_of_two_needed(values):
    """Smallest s >= 0 such that every finite value times 2**s is an integer."""
    values = np.asarray(values, dtype=np.float64).ravel()
    values = values[np.isfinite(values) & (values != 0)]
    if not values.size:
        return 0
    fraction, exponent = np.frexp(values)
    mantissa = (fraction * 2.0**53).astype(np.int64)
    trailing_zeros = np.frexp((mantissa & -mantissa).astype(np.float64))[1] - 1
    return max(0, int((53 - exponent - trailing_zeros).max()))


class Exact:
    """Writes floats as Python integers over one common power of two, ``2**scale``.

    Parameters
    ----------
    *arrays : array_like
        Every float that the computation will see, so that one scale serves them all.
    """

    def __init__(self, *arrays):
        self.scale = max(_powers_of_two_needed(a) for a in arrays)

    def __call__(self, values):
        """``values * 2**scale`` as an object array of ints (exact); ``values`` finite."""
        values = np.asarray(values, dtype=np.float64)
        fraction, exponent = np.frexp(values)
        mantissa = (fraction * 2.0**53).astype(np.int64)
        shift = exponent.astype(np.int64) - 53 + self.scale
        # a right shift only drops trailing zero bits, by the choice of the scale
        left = np.maximum(shift, 0).astype(object)
        right = np.maximum(-shift, 0).astype(object)
        return (mantissa.astype(object) << left) >> right

    def bound(self, values):
        """A (N,) bound as a fraction ``(num, den)`` with den >= 0; den = 0 encodes ±inf."""
        values = np.asarray(values, dtype=np.float64)
        finite = np.isfinite(values)
        infinite = np.where(values > 0, 1, -1).astype(object)
        num = np.where(finite, self(np.where(finite, values, 0.0)), infinite)
        den = np.where(finite, 1 << self.scale, 0).astype(object)
        return num, den


def _sign(v):
    return (v > 0).astype(np.int64) - (v < 0).astype(np.int64)


def _dot(u, v):
    return (u * v).sum(axis=-1)


def _sign_with_sqrt(x, y, disc):
    """Exact sign of ``x + y √disc`` for integer arrays, ``disc >= 0``."""
    sx = _sign(x)
    sy = _sign(y) * (disc > 0)
    squares = _sign(x * x - y * y * disc)
    return np.where(sx == sy, sx, np.where(sx == 0, sy, np.where(sy == 0, sx, sx * squares)))


def _minus_bound(root, bound):
    """Exact sign of ``root - num / den`` (den >= 0; den = 0 is ±inf)."""
    num, den = bound
    sign = _sign_with_sqrt(root.x * den - num * root.den, root.y * den, root.disc)
    return np.where(den != 0, sign * _sign(root.den), -_sign(num))


def _affine_sign(root, start, slope):
    """Exact sign of ``start + root * slope`` (integer arrays of one scale)."""
    x = start * root.den + slope * root.x
    return _sign_with_sqrt(x, slope * root.y, root.disc) * _sign(root.den)


def _rational(num, den, valid):
    """The root num / den (rounded once where valid)."""
    valid = valid & (den != 0)
    safe = np.where(valid, den, 1)
    value = np.where(valid, num / safe, np.inf).astype(np.float64)
    zero = np.zeros(len(num), dtype=object)
    return Root(num, zero, zero, safe, valid, value)


_isqrt = np.frompyfunc(math.isqrt, 1, 1)


def _quadratic(a, b, c):
    """The two roots of ``a t² + 2 b t + c = 0`` (integer arrays); one, -c / 2b, when a = 0.

    Values come from ``q = -(b + sign(b) √D)``, evaluated with GUARD_BITS fractional bits, as
    ``q / a`` and ``c / q``: no cancellation, so the single rounding of int / int decides.
    """
    disc = b * b - a * c
    quadratic = (a != 0) & (disc >= 0)
    disc = np.where(quadratic, disc, 0)
    sb = np.where(b >= 0, 1, -1).astype(object)
    scaled_q = -((b << GUARD_BITS) + sb * _isqrt(disc << (2 * GUARD_BITS)))
    safe_a = np.where(quadratic, a, 1)
    safe_q = np.where(scaled_q != 0, scaled_q, 1)
    big_value = np.where(quadratic, scaled_q / (safe_a << GUARD_BITS), np.inf)
    # q = 0 only for b = 0 and D = 0, where c = 0 and both roots are 0
    small_value = np.where(quadratic, np.where(scaled_q != 0, (c << GUARD_BITS) / safe_q, 0.0),
                           np.inf)
    big = Root(-b, -sb, disc, safe_a, quadratic, big_value.astype(np.float64))
    small = Root(-b, sb, disc, safe_a, quadratic, small_value.astype(np.float64))
    linear = _rational(-c, 2 * b, a == 0)
    first = Root(*(np.where(a == 0, lin, quad) for lin, quad in zip(linear, big, strict=True)))
    return first, small


def _nearest_roots(candidates, tmin, tmax):
    """Smallest value among valid candidate roots within [tmin, tmax]; inf where none."""
    best = np.full(len(candidates[0].value), np.inf)
    for root in candidates:
        inside = root.valid & (_minus_bound(root, tmin) >= 0) & (_minus_bound(root, tmax) <= 0)
        best = np.where(inside, np.minimum(best, root.value), best)
    return best


def _restrict(root, start, slope, low, high):
    """``root`` kept only where ``start + root * slope`` lies in [low, high]."""
    keep = (_affine_sign(root, start - low, slope) >= 0) & (
        _affine_sign(root, start - high, slope) <= 0
    )
    return root._replace(valid=root.valid & keep)


def _disk_root(o, d, center, normal, radius2):
    """The crossing of the disk (centre, normal of any length, squared radius), exactly."""
    num = _dot(center - o, normal)
    den = _dot(d, normal)
    # (o - c) + (num / den) d, times den
    offset = (o - center) * den[:, None] + num[:, None] * d
    inside = _dot(offset, offset) <= radius2 * den * den
    return _rational(num, den, inside)


def _prepare(origins, directions, tmin, tmax, *shape):
    exact = Exact(origins, directions, tmin, tmax, *shape)
    return (exact, exact(origins), exact(directions), exact.bound(tmin), exact.bound(tmax),
            *(exact(np.asarray(p, dtype=np.float64)) for p in shape))


def sphere(origins, directions, center, radius, tmin, tmax):
    """Nearest hits with a sphere, exact decisions."""
    _, o, d, tmin, tmax, c, r = _prepare(origins, directions, tmin, tmax, center, radius)
    f = o - c
    roots = _quadratic(_dot(d, d), _dot(f, d), _dot(f, f) - r * r)
    return _nearest_roots(roots, tmin, tmax)


def plane(origins, directions, point, normal, tmin, tmax):
    """Nearest hits with a plane, exact."""
    _, o, d, tmin, tmax, p, n = _prepare(origins, directions, tmin, tmax, point, normal)
    den = _dot(d, n)
    root = _rational(_dot(p - o, n), den, np.ones(len(o), dtype=bool))
    return _nearest_roots([root], tmin, tmax)


def disk(origins, directions, center, normal, radius, tmin, tmax):
    """Nearest hits with a disk, exact."""
    _, o, d, tmin, tmax, c, n, r = _prepare(origins, directions, tmin, tmax, center, normal,
                                            radius)
    return _nearest_roots([_disk_root(o, d, c, n, r * r)], tmin, tmax)


def _perpendicular(v, axis, axis2):
    """``(v·axis, axis2 v - (v·axis) axis)``: the component of v perpendicular to an axis of
    squared length axis2, scaled by axis2 to stay integral."""
    along = _dot(v, axis)
    return along, axis2 * v - along[:, None] * axis


def cylinder(origins, directions, p0, p1, radius, tmin, tmax):
    """Nearest hits with a capped cylinder, exact decisions."""
    _, o, d, tmin, tmax, p0, p1, r = _prepare(origins, directions, tmin, tmax, p0, p1, radius)
    w = p1 - p0
    w2 = _dot(w, w)
    fw, fp = _perpendicular(o - p0, w, w2)
    dw, dp = _perpendicular(d, w, w2)
    # |f⊥ + t d⊥|² = r², with both perpendicular parts scaled by |w|²
    roots = _quadratic(_dot(dp, dp), _dot(fp, dp), _dot(fp, fp) - r * r * w2 * w2)
    # the axial coordinate times |w|, fw + t dw, must lie in [0, |w|²]
    sides = [_restrict(root, fw, dw, 0, w2) for root in roots]
    caps = [_disk_root(o, d, end, w, r * r) for end in (p0, p1)]
    return _nearest_roots(sides + caps, tmin, tmax)


def cone(origins, directions, base_center, apex, radius, tmin, tmax):
    """Nearest hits with a cone capped at its base, exact decisions."""
    _, o, d, tmin, tmax, base, apex, r = _prepare(origins, directions, tmin, tmax, base_center,
                                                  apex, radius)
    w = apex - base
    w2 = _dot(w, w)
    fw, fp = _perpendicular(o - apex, w, w2)
    dw, dp = _perpendicular(d, w, w2)
    # |g⊥|² = (r / h)² (g·ŵ)² becomes |w|⁴ |g⊥|² = r² (g·w)² with the scaled perpendicular parts
    r2 = r * r
    roots = _quadratic(_dot(dp, dp) - r2 * dw * dw, _dot(fp, dp) - r2 * fw * dw,
                       _dot(fp, fp) - r2 * fw * fw)
    # the real nappe: g·w in [-|w|², 0]
    sides = [_restrict(root, fw, dw, -w2, 0) for root in roots]
    return _nearest_roots(sides + [_disk_root(o, d, base, w, r2)], tmin, tmax)


def _compare(n1, d1, n2, d2):
    """Exact sign of n1/d1 - n2/d2 for denominators >= 0 (a zero one encodes ±inf)."""
    return _sign(n1 * d2 - n2 * d1)


def _slabs(low, high, o, d, tmin, tmax):
    """Exact slab test, t = (low - o) / d per axis on integer arrays (N, 3) of one scale."""
    count = len(o)
    enter = (np.full(count, -1, dtype=object), np.zeros(count, dtype=object))
    leave = (np.full(count, 1, dtype=object), np.zeros(count, dtype=object))
    outside = np.zeros(count, dtype=bool)
    for axis in range(3):
        y = d[:, axis]
        parallel = y == 0
        outside |= parallel & ((o[:, axis] < low[:, axis]) | (o[:, axis] > high[:, axis]))
        sign = np.where(y < 0, -1, 1).astype(object)
        den = np.where(parallel, 0, y * sign)
        near = np.where(y < 0, high[:, axis], low[:, axis]) - o[:, axis]
        far = np.where(y < 0, low[:, axis], high[:, axis]) - o[:, axis]
        # parallel axes do not narrow: encode them as -inf / +inf
        near = (np.where(parallel, -1, near * sign), den)
        far = (np.where(parallel, 1, far * sign), den)
        later = _compare(*near, *enter) > 0
        enter = tuple(np.where(later, a, b) for a, b in zip(near, enter, strict=True))
        sooner = _compare(*far, *leave) < 0
        leave = tuple(np.where(sooner, a, b) for a, b in zip(far, leave, strict=True))
    crossing = ~outside & (_compare(*enter, *leave) <= 0)
    result = np.full(count, np.inf)
    for t in (leave, enter):  # the entry wins where both are in range
        keep = crossing & (_compare(*t, *tmin) >= 0) & (_compare(*t, *tmax) <= 0)
        value = np.where(keep, t[0] / np.where(keep, t[1], 1), np.inf).astype(np.float64)
        result = np.where(keep, value, result)
    return result


def box(origins, directions, lo, hi, tmin, tmax):
    """Nearest hits with the axis-aligned box [lo, hi], exact."""
    _, o, d, tmin, tmax, lo, hi = _prepare(origins, directions, tmin, tmax, lo, hi)
    count = len(o)
    return _slabs(np.tile(lo, (count, 1)), np.tile(hi, (count, 1)), o, d, tmin, tmax)


def _adjugate(m):
    """Adjugate (transposed cofactors) of a 3x3 integer matrix, and its determinant."""
    adj = np.empty((3, 3), dtype=object)
    for i in range(3):
        for j in range(3):
            rows = [r for r in range(3) if r != j]
            cols = [c for c in range(3) if c != i]
            minor = m[rows[0], cols[0]] * m[rows[1], cols[1]] - m[rows[0], cols[1]] * m[
                rows[1], cols[0]]
            adj[i, j] = minor if (i + j) % 2 == 0 else -minor
    return adj, _dot(m[0], adj[:, 0])


def transformed_box(origins, directions, lo, hi, transform, tmin, tmax):
    """Nearest hits with the box [lo, hi] under an affine (4, 4) transform, exact.

    With M = [A | T], the local ray is A⁻¹ (o - T) + t A⁻¹ d and A⁻¹ = adj(A) / det(A).  On the
    integer scale 2**s, the slab t = (lo - o') / d' becomes
    ``(lo det(A) - 2**s adj(A)(o - T)) / (2**s adj(A) d)``, all integers.
    """
    exact, o, d, tmin, tmax, lo, hi, m = _prepare(origins, directions, tmin, tmax, lo, hi,
                                                  np.asarray(transform)[:3])
    adj, det = _adjugate(m[:, :3])
    if det < 0:
        adj, det = -adj, -det
    local_o = _dot((o - m[:, 3])[:, None, :], adj[None, :, :]) << exact.scale
    local_d = _dot(d[:, None, :], adj[None, :, :]) << exact.scale
    count = len(o)
    return _slabs(np.tile(lo * det, (count, 1)), np.tile(hi * det, (count, 1)), local_o,
                  local_d, tmin, tmax)
