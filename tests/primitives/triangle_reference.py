"""Exact ray/triangle reference and test geometry for ``test_triangle.py``.

Exactness: every float is a dyadic rational ``M · 2**e`` with an integer ``M``.  Scaling the 15
numbers of one ray/triangle pair by a common power of two turns them into integers, and t and
the barycentrics are ratios of polynomials of equal degree, so they do not change under that
scaling: the whole solve is exact integer arithmetic (Python ints in NumPy object arrays).
That is Fraction arithmetic with one fixed denominator per pair, and fast enough for 100k pairs;
:func:`fraction_intersect` solves the same problem another way with ``fractions.Fraction`` to
check it.
"""

from fractions import Fraction
from typing import NamedTuple

import numpy as np
from numba import njit

from raycore.primitives.triangle import triangle_hit, watertight_setup

MISS, INSIDE, BOUNDARY = 0, 1, 2

#: Kinds of pairs made by :func:`random_pairs`.
KINDS = ("generic", "near_edge", "on_edge", "behind", "parallel", "degenerate", "tiny")


class Exact(NamedTuple):
    """Exact answer for N ray/triangle pairs.

    Attributes
    ----------
    status : ndarray of int, shape (N,)
        ``MISS``; ``INSIDE`` (strictly inside the triangle); ``BOUNDARY`` (exactly on an edge or
        a vertex).  Parallel rays and degenerate triangles (zero determinant) are misses.
    t, u, v, w : ndarray of float64, shape (N,)
        Exact hit parameter and barycentrics (``w = 1 - u - v``, the weight of ``a``), each
        correctly rounded to float64 (so 0 exactly when exactly 0); NaN on misses.
    """

    status: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray


#: Elementwise ``Fraction`` of a float array (an object array of exact rationals).
fractions = np.frompyfunc(lambda x: Fraction(float(x)), 1, 1)


def _scaled_integers(columns):
    """Return the (N,) float columns as object arrays of Python ints, row i scaled by 2**S_i."""
    stacked = np.stack([np.asarray(col, dtype=np.float64) for col in columns])
    mantissa, exponent = np.frexp(stacked)
    digits = (mantissa * 2.0**53).astype(np.int64)  # exact: |mantissa| < 1
    exponent = exponent - 53  # value = digits * 2**exponent
    # Scale row i by 2**-lowest_i, lowest_i = min(0, the row's smallest exponent of a non-zero
    # value): every value becomes an integer.
    nonzero = digits != 0
    lowest = np.where(nonzero, exponent, 0).min(axis=0)
    shift = np.where(nonzero, exponent - lowest, 0)
    return list(digits.astype(object) << shift.astype(object))


def exact_intersect(o, d, a, b, c, tmin=0.0, tmax=np.inf):
    """Solve ``o + t d = (1-u-v) a + u b + v c`` exactly for each pair.

    Cramer's rule in Möller–Trumbore's form: ``det = e1·(d × e2)``, ``u = s·(d × e2) / det``,
    ``v = d·(s × e1) / det``, ``t = e2·(s × e1) / det`` with ``e1 = b - a``, ``e2 = c - a``,
    ``s = o - a`` — on integers, so nothing rounds.

    Parameters
    ----------
    o, d, a, b, c : array_like, shape (N, 3)
        Rays and triangles (any floats).
    tmin, tmax : float
        Accepted range of t (inclusive).

    Returns
    -------
    Exact
    """
    arrays = [np.asarray(x, dtype=np.float64) for x in (o, d, a, b, c)]
    (ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, cx, cy, cz) = _scaled_integers(
        [x[:, k] for x in arrays for k in range(3)]
    )
    e1 = bx - ax, by - ay, bz - az
    e2 = cx - ax, cy - ay, cz - az
    s = ox - ax, oy - ay, oz - az
    p = dy * e2[2] - dz * e2[1], dz * e2[0] - dx * e2[2], dx * e2[1] - dy * e2[0]
    q = s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]
    det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2]
    u = s[0] * p[0] + s[1] * p[1] + s[2] * p[2]
    v = dx * q[0] + dy * q[1] + dz * q[2]
    t = e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]
    # Make det positive so that the inequalities below need no division.
    flip = det < 0
    det, u, v, t = (np.where(flip, -x, x) for x in (det, u, v, t))
    w = det - u - v
    inside = (det > 0) & (u >= 0) & (v >= 0) & (w >= 0)
    for bound, keep in ((tmin, np.greater_equal), (tmax, np.less_equal)):
        if np.isfinite(bound):
            num, den = float(bound).as_integer_ratio()
            inside &= keep(t * den, det * num).astype(bool)
    on_edge = (u == 0) | (v == 0) | (w == 0)
    status = np.where(inside, np.where(on_edge, BOUNDARY, INSIDE), MISS)
    floats = []
    for num in (t, u, v, w):
        out = np.full(len(status), np.nan)
        # int / int is correctly rounded in Python.
        out[inside] = (num[inside] / det[inside]).astype(np.float64)
        floats.append(out)
    return Exact(status, *floats)


def fraction_intersect(o, d, a, b, c):
    """Exact answer for one pair (tmin = 0, tmax = inf) by another route than
    :func:`exact_intersect`: the plane hit, then sub-triangle areas.

    ``N = (b - a) × (c - a)``, ``t = N·(a - o) / N·d``, ``P = o + t d`` and the barycentric
    weight of each vertex is ``N·(edge × (P - edge start)) / N·N`` — in ``fractions.Fraction``.

    Returns
    -------
    (status, t, u, v) : (int, Fraction or None, Fraction or None, Fraction or None)
    """
    o, d, a, b, c = ([Fraction(float(x)) for x in p] for p in (o, d, a, b, c))

    def sub(p, q):
        return [p[0] - q[0], p[1] - q[1], p[2] - q[2]]

    def dot(p, q):
        return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]

    def cross(p, q):
        return [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]]

    n = cross(sub(b, a), sub(c, a))
    nd = dot(n, d)
    if nd == 0:
        return MISS, None, None, None
    t = dot(n, sub(a, o)) / nd
    p = [o[k] + t * d[k] for k in range(3)]
    nn = dot(n, n)
    weights = [
        dot(n, cross(sub(end, start), sub(p, start))) / nn
        for start, end in ((b, c), (c, a), (a, b))
    ]
    if t < 0 or min(weights) < 0:
        return MISS, None, None, None
    return (BOUNDARY if min(weights) == 0 else INSIDE), t, weights[1], weights[2]


# ----------------------------------------------------------------------------- test geometry


def icosphere(subdivisions, radius=1.0, grid=None, center=(0.0, 0.0, 0.0)):
    """Closed icosphere: an icosahedron whose faces are split in four ``subdivisions`` times.

    Vertices are pushed onto the sphere, scaled by ``radius``, rounded to multiples of ``grid``
    if given (so that edge points ``p + k/2**m (q - p)`` are exactly representable), then moved
    by ``center``.  Shared vertices are stored once, so the mesh is closed.

    Returns
    -------
    vertices : ndarray of float64, shape (V, 3)
    faces : ndarray of int64, shape (F, 3)
        Counter-clockwise seen from outside.
    """
    g = (1.0 + 5.0**0.5) / 2.0
    vertices = [
        (-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g),
        (0, -1, -g), (0, 1, -g), (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1),
    ]  # fmt: skip
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
        (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
        (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]  # fmt: skip
    vertices = [np.array(v, dtype=np.float64) / np.linalg.norm(v) for v in vertices]
    for _ in range(subdivisions):
        midpoint = {}

        def middle(i, j, midpoint=midpoint):
            key = (min(i, j), max(i, j))
            if key not in midpoint:
                m = vertices[i] + vertices[j]
                vertices.append(m / np.linalg.norm(m))
                midpoint[key] = len(vertices) - 1
            return midpoint[key]

        faces = [
            face
            for i, j, k in faces
            for face in (
                (i, middle(i, j), middle(k, i)),
                (j, middle(j, k), middle(i, j)),
                (k, middle(k, i), middle(j, k)),
                (middle(i, j), middle(j, k), middle(k, i)),
            )
        ]
    points = np.array(vertices) * radius
    if grid is not None:
        points = np.round(points / grid) * grid
    return points + np.asarray(center), np.array(faces, dtype=np.int64)


def rotated(vertices):
    """``vertices`` (V, 3) turned by a fixed rotation with no special angles (full mantissas)."""
    cz, sz, cx, sx = np.cos(0.7), np.sin(0.7), np.cos(1.1), np.sin(1.1)
    rotation = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]]
    )
    return vertices @ rotation.T


def tessellated_box(n, half=1.0):
    """Closed cube ``[-half, half]**3``, each face split into n × n squares of two triangles.

    Returns
    -------
    vertices : ndarray of float64, shape (V, 3)
    faces : ndarray of int64, shape (12 n**2, 3)
        Counter-clockwise seen from outside.
    """
    index = {}
    vertices = []
    faces = []

    def vertex(p):
        key = tuple(p)
        if key not in index:
            index[key] = len(vertices)
            vertices.append(key)
        return index[key]

    ticks = np.linspace(-half, half, n + 1)
    for axis in range(3):
        for side in (-half, half):
            u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
            if side < 0:  # keep the outward normal on both sides
                u_axis, v_axis = v_axis, u_axis
            for i in range(n):
                for j in range(n):
                    corners = []
                    for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = [0.0, 0.0, 0.0]
                        p[axis], p[u_axis], p[v_axis] = side, ticks[i + du], ticks[j + dv]
                        corners.append(vertex(p))
                    faces.append((corners[0], corners[1], corners[2]))
                    faces.append((corners[0], corners[2], corners[3]))
    return np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int64)


def edges(faces):
    """Unique undirected edges (E, 2) of a triangle mesh."""
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(pairs, axis=1), axis=0)


def edge_and_vertex_targets(vertices, faces, levels=2):
    """Points on the mesh's edges, and its vertices.

    For every edge (p, q): ``p + k/2**levels (q - p)`` for ``0 < k < 2**levels`` (midpoints and
    the like), computed in the precision of ``vertices``: exactly on the edge when the vertices
    lie on a coarse enough dyadic grid, else within rounding of it.

    Returns
    -------
    targets : ndarray, shape (E (2**levels - 1) + V, 3)
    exact : bool
        Whether every edge point is exactly ``p + k/2**levels (q - p)``.
    """
    pairs = edges(faces)
    p, q = vertices[pairs[:, 0]], vertices[pairs[:, 1]]
    k = (np.arange(1, 2**levels)[:, None, None] / 2.0**levels).astype(vertices.dtype)
    points = p + k * (q - p)
    exact = np.all(fractions(points) == fractions(p) + fractions(k) * (fractions(q) - fractions(p)))
    return np.concatenate([points.reshape(-1, 3), vertices]), exact


@njit(cache=True)
def closest_hits(test, origins, directions, tmin, tmax, vertices, faces):
    """Closest hit of each ray over all triangles, by brute force with :func:`triangle_hit`.

    Parameters
    ----------
    test : int
        Triangle test code.
    origins, directions : ndarray, shape (N, 3)
    tmin, tmax : ndarray, shape (N,)
    vertices : ndarray, shape (V, 3)
    faces : ndarray of int, shape (F, 3)

    Returns
    -------
    t : ndarray, shape (N,)
        ``inf`` where no triangle was hit.
    prim : ndarray of int64, shape (N,)
        Face of the closest hit, -1 where none.
    """
    n = origins.shape[0]
    t_out = np.full(n, np.inf, dtype=origins.dtype)
    prim = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        kx, ky, kz, sx, sy, sz = watertight_setup(dx, dy, dz)
        best = tmax[i]
        for f in range(faces.shape[0]):
            a, b, c = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
            t, _, _ = triangle_hit(
                test, ox, oy, oz, dx, dy, dz, kx, ky, kz, sx, sy, sz, tmin[i], best,
                a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2],
            )  # fmt: skip
            if t < np.inf:
                best = t
                t_out[i] = t
                prim[i] = f
    return t_out, prim


def _float32(x):
    return x.astype(np.float32).astype(np.float64)


def random_pairs(n, seed):
    """Seeded random ray/triangle pairs, every coordinate exactly representable in float32.

    Kinds (``kind`` holds the index into ``KINDS``):

    * ``generic``: vertices in [-1, 1]^3, the ray aimed at a point with barycentrics in
      [-0.25, 1.25] (hits and misses);
    * ``near_edge``: aimed at a point 1e-9 ... 1e-3 (in barycentric units) inside or outside an
      edge, before rounding to float32;
    * ``on_edge``: dyadic-grid data with the ray through ``p + k/16 (q - p)`` of an edge exactly
      (vertices when k is 0 or 16);
    * ``behind``: the triangle behind the origin;
    * ``parallel``: the triangle in a plane z = const, the ray with dz = 0, in that plane or not;
    * ``degenerate``: a repeated vertex or three collinear vertices;
    * ``tiny``: legs of about 1e-5, the ray aimed inside.

    Returns
    -------
    o, d, a, b, c : ndarray of float64, shape (n, 3)
    kind : ndarray of int64, shape (n,)
    """
    rng = np.random.default_rng(seed)
    shares = np.array([0.40, 0.25, 0.20, 0.05, 0.04, 0.03, 0.03])
    kind = rng.choice(len(KINDS), size=n, p=shares)
    a, b, c = (rng.uniform(-1, 1, (n, 3)) for _ in range(3))
    o = rng.uniform(-3, 3, (n, 3))
    weights = rng.uniform(-0.25, 1.25, (n, 2))

    near = kind == KINDS.index("near_edge")
    gap = 10.0 ** rng.uniform(-9, -3, n) * rng.choice([-1.0, 1.0], n)
    along = rng.uniform(0.05, 0.95, n)
    # Edge a-b: v = gap; edge c-a: u = gap; edge b-c: u + v = 1 - gap.
    edge = rng.integers(0, 3, n)
    near_w = np.stack(
        [
            np.select([edge == 0, edge == 1], [along, gap], along),
            np.select([edge == 0, edge == 1], [gap, along], 1 - gap - along),
        ],
        axis=1,
    )
    weights[near] = near_w[near]

    tiny = kind == KINDS.index("tiny")
    legs = rng.uniform(0.5e-5, 2e-5, (n, 2, 3))
    b[tiny] = a[tiny] + legs[tiny, 0]
    c[tiny] = a[tiny] + legs[tiny, 1]
    weights[tiny] = rng.uniform(0.1, 0.45, (int(tiny.sum()), 2))

    target = a + weights[:, :1] * (b - a) + weights[:, 1:] * (c - a)
    a, b, c, o, target = (_float32(x) for x in (a, b, c, o, target))
    d = _float32(target - o)

    behind = kind == KINDS.index("behind")
    d[behind] = -d[behind]

    # Dyadic grid: vertices on 2**-6 in [-2, 2], origins on 2**-3 in [-4, 4], targets on 2**-10.
    grid = kind == KINDS.index("on_edge")
    m = int(grid.sum())
    ga, gb, gc = (rng.integers(-128, 129, (m, 3)) / 64.0 for _ in range(3))
    go = rng.integers(-32, 33, (m, 3)) / 8.0
    k = rng.integers(0, 17, (m, 1)) / 16.0
    which = rng.integers(0, 3, (m, 1))
    start, end = np.choose(which, [ga, gb, gc]), np.choose(which, [gb, gc, ga])
    gt = start + k * (end - start)
    go[np.all(go == gt, axis=1), 0] += 1.0
    a[grid], b[grid], c[grid], o[grid], d[grid] = ga, gb, gc, go, gt - go

    flat = kind == KINDS.index("parallel")
    m = int(flat.sum())
    z = rng.integers(-8, 9, m) / 8.0
    for x in (a, b, c):
        x[flat, 2] = z
    o[flat, 2] = np.where(rng.random(m) < 0.5, z, z + 0.5)
    d[flat, 2] = 0.0

    degenerate = kind == KINDS.index("degenerate")
    m = int(degenerate.sum())
    repeated = rng.random(m) < 0.5
    # Collinear: c = a + 2 (b - a) on the 2**-6 grid, exact; else b is a copy of a or c.
    ga, gb = (rng.integers(-64, 65, (m, 3)) / 64.0 for _ in range(2))
    gc = np.where(repeated[:, None], np.where(rng.random((m, 1)) < 0.5, ga, gb), 2 * gb - ga)
    go = rng.integers(-32, 33, (m, 3)) / 8.0
    a[degenerate], b[degenerate], c[degenerate], o[degenerate] = ga, gb, gc, go
    # Aim exactly at the midpoint of a-b, on the degenerate triangle itself.
    d[degenerate] = (ga + gb) / 2 - go
    d[np.all(d == 0, axis=1), 0] = 1.0
    return o, d, a, b, c, kind
