"""Exact answers for whole scenes, composed from the references in ``tests/primitives``.

The references there answer one ray against one triangle (``triangle_reference.exact_intersect``)
or one analytic shape (``reference.sphere``, ``reference.cylinder``, ``reference.cone``).  This
module only composes them: the nearest exact hit of a ray over a triangle mesh, and the rays whose
hit/miss answer a method in a given precision can be asked to get right.
"""

import numpy as np
from numba import njit

from tests.primitives import reference
from tests.primitives.triangle_reference import MISS, exact_intersect, fractions

#: Relative padding of the float64 candidate boxes in :func:`mesh_closest`, far above the
#: rounding of a float64 slab test, so that no triangle that the ray meets is left out.
_PAD = 1e-7


@njit(cache=True)
def _box_pairs(origins, directions, lo, hi, tmin, tmax, rows, faces):
    """Fill ``rows``/``faces`` with the pairs whose box the segment [tmin, tmax] of the ray may
    cross (a slab test with a relative slack); return how many, which may exceed the buffers'
    length (then call again with larger ones)."""
    count = 0
    for i in range(origins.shape[0]):
        for f in range(lo.shape[0]):
            enter = tmin
            leave = tmax
            for k in range(3):
                o = origins[i, k]
                d = directions[i, k]
                if d == 0.0:
                    if o < lo[f, k] or o > hi[f, k]:
                        enter = np.inf
                    continue
                t0 = (lo[f, k] - o) / d
                t1 = (hi[f, k] - o) / d
                enter = max(enter, min(t0, t1))
                leave = min(leave, max(t0, t1))
            if enter <= leave + 1e-9 * max(abs(enter), abs(leave)):
                if count < rows.shape[0]:
                    rows[count] = i
                    faces[count] = f
                count += 1
    return count


def _candidates(origins, directions, lo, hi, tmin, tmax):
    """(rows, faces): pairs whose padded box the ray's segment [tmin, tmax] may cross."""
    size = 4 * len(origins)
    while True:
        rows = np.empty(size, np.int64)
        faces = np.empty(size, np.int64)
        count = _box_pairs(origins, directions, lo, hi, float(tmin), float(tmax), rows, faces)
        if count <= size:
            return rows[:count], faces[:count]
        size = count


def _maybe(o, d, a, b, c, tmin, tmax):
    """Pairs that a float64 Möller–Trumbore solve cannot rule out with a wide margin.

    Each quantity's rounding error is far below 1e-9 times the product of the norms of its
    factors; a pair is dropped only when a barycentric or t lies beyond such a margin (never
    when the determinant is within its margin of zero: parallel rays, degenerate triangles).
    """
    def norm(x):
        return np.sqrt(np.einsum("ij,ij->i", x, x))

    def dot(x, y):
        return np.einsum("ij,ij->i", x, y)

    e1, e2, s = b - a, c - a, o - a
    p, q = np.cross(d, e2), np.cross(s, e1)
    det, u, v, t = dot(e1, p), dot(s, p), dot(d, q), dot(e2, q)
    n1, n2, nd, ns = norm(e1), norm(e2), norm(d), norm(s)
    margin = 1e-9
    e_det, e_u, e_v, e_t = (margin * x for x in (n1 * nd * n2, ns * nd * n2, nd * ns * n1,
                                                 n2 * ns * n1))
    sign = np.sign(det)
    size = np.abs(det)
    out = ((u * sign < -e_u) | (v * sign < -e_v) | ((det - u - v) * sign < -(e_det + e_u + e_v))
           | (t * sign - tmin * size < -(e_t + abs(tmin) * e_det)))
    if np.isfinite(tmax):
        out |= t * sign - tmax * size > e_t + tmax * e_det
    return ~(out & (size > e_det))


def mesh_closest(origins, directions, vertices, faces, tmin=0.0, tmax=np.inf):
    """Exact nearest hit of each ray with a triangle mesh.

    Candidate triangles come from a padded float64 box test (conservative); each candidate pair
    is then solved exactly by ``triangle_reference.exact_intersect``.  Rays parallel to a
    triangle's plane, in it or not, and degenerate triangles are misses, as there.

    Parameters
    ----------
    origins, directions : array_like, shape (N, 3)
    vertices : array_like, shape (V, 3)
    faces : array_like of int, shape (F, 3)
    tmin, tmax : float
        Accepted range of t (inclusive).

    Returns
    -------
    ndarray of float64, shape (N,)
        The exact t correctly rounded to float64; inf where the ray meets no triangle.
    """
    origins = np.asarray(origins, np.float64)
    directions = np.asarray(directions, np.float64)
    corners = np.asarray(vertices, np.float64)[np.asarray(faces)]
    # a degenerate triangle (exactly zero cross product) is missed by every ray: leave it out
    exact = fractions(corners)
    normal = np.cross(exact[:, 1] - exact[:, 0], exact[:, 2] - exact[:, 0])
    corners = corners[np.any(normal != 0, axis=1)]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    pad = _PAD * (np.abs(lo) + np.abs(hi) + (hi - lo)).max(axis=1, keepdims=True)
    count = len(origins)
    rows, picked = _candidates(origins, directions, lo - pad, hi + pad, tmin, tmax)
    a, b, c = (corners[picked, k] for k in range(3))
    keep = _maybe(origins[rows], directions[rows], a, b, c, tmin, tmax)
    rows, a, b, c = rows[keep], a[keep], b[keep], c[keep]
    best = np.full(count, np.inf)
    if len(rows):
        exact = exact_intersect(origins[rows], directions[rows], a, b, c, tmin, tmax)
        hit = exact.status != MISS
        # rounding is monotonic: the smallest rounded t is the rounded smallest t
        np.minimum.at(best, rows[hit], exact.t[hit])
    return best


# ----------------------------------------------------------------------------- analytic shapes

QUADRICS = {"sphere": reference.sphere, "cylinder": reference.cylinder, "cone": reference.cone}


def quadric_closest(shape, origins, directions, params, tmin, tmax):
    """Exact nearest hit of each ray with one analytic shape (``reference.<shape>``).

    The rays and the shape are first scaled by a power of two (which changes no t) so that
    every coordinate is an integer: ``reference.Exact.bound`` overflows a C long when the
    common scale of tiny coordinates exceeds 2**62.
    """
    spatial = [np.asarray(x, np.float64) for x in (origins, directions, *params)]
    shift = 2.0 ** reference._powers_of_two_needed(np.concatenate([x.ravel() for x in spatial]))
    origins, directions, *params = (x * shift for x in spatial)
    params = [p if p.ndim else float(p) for p in params]
    return QUADRICS[shape](origins, directions, *params, tmin, tmax)


def scaled_params(shape, params, factor):
    """The shape scaled by ``factor`` about an interior point (for a convex shape: nested).

    Sphere ``(center, radius)``; cylinder ``(p0, p1, radius)``; cone ``(base, apex, radius)``.
    """
    if shape == "sphere":
        center, radius = params
        return np.asarray(center, np.float64), radius * factor
    start, end, radius = (np.asarray(p, np.float64) for p in params)
    # the cylinder's middle, the cone's point a quarter of the way up its axis: both interior
    middle = start + (0.5 if shape == "cylinder" else 0.25) * (end - start)
    return (middle + factor * (start - middle), middle + factor * (end - middle),
            float(radius) * factor)


def decided(shape, origins, directions, params, tmin, tmax, margin):
    """Rays whose hit/miss answer stays the same when the shape grows or shrinks by ``margin``
    (relative): a method that is accurate to about that much must get them right.

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    grown = quadric_closest(shape, origins, directions, scaled_params(shape, params, 1 + margin),
                            tmin, tmax)
    shrunk = quadric_closest(shape, origins, directions,
                             scaled_params(shape, params, 1 - margin), tmin, tmax)
    return np.isfinite(grown) == np.isfinite(shrunk)
