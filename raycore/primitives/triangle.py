"""Ray/triangle intersection: Möller–Trumbore, geometric (plane + edges) and watertight tests.

Three tests with one contract, so that the BVH leaf loop can switch between them and the tests in
``tests/primitives`` can measure how they differ:

* every kernel takes scalars and computes in the precision of its inputs; it is compiled once
  and inlined by LLVM (``forceinline``), not copied into each caller by Numba
  (``inline="always"``), which made every traversal kernel compile five times slower;
* it returns ``(t, u, v)``: the ray parameter of the hit (``tmin <= t <= tmax``, direction not
  normalised, hit point ``o + t d``) and barycentrics with hit point ``(1-u-v) a + u b + v c``
  (Embree's and Möller's convention); on a miss ``t`` is ``inf`` and ``u``, ``v`` are NaN;
* no backface culling; a degenerate triangle (edge cross product exactly zero) never hits;
* a NaN anywhere in the input is a miss, never ``t = NaN``: acceptance conditions are written
  so that NaN fails them.

Numba raises ``ZeroDivisionError`` on a float division by zero, so every divisor is checked
before use.
"""

from fractions import Fraction

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

from raycore._fp import like
from raycore.bvh.simd import permuted
from raycore.hits import Hits
from raycore.rays import as_float_array, prepare_rays, read_only, resolve_dtype

WATERTIGHT = 0
MOLLER = 1
GEOMETRIC = 2

#: Names accepted for ``triangle_test`` and the codes the kernels dispatch on.
TRIANGLE_TESTS = {"watertight": WATERTIGHT, "moller": MOLLER, "geometric": GEOMETRIC}


def triangle_test_code(name, argument="triangle_test"):
    """Return the code of a triangle test name.

    Parameters
    ----------
    name : str
        One of ``"watertight"``, ``"moller"``, ``"geometric"``.
    argument : str
        The caller's name for the argument, used in the error message.

    Raises
    ------
    ValueError
        Naming ``argument`` when ``name`` is not a known test.
    """
    try:
        return TRIANGLE_TESTS[name]
    except (KeyError, TypeError) as error:
        raise ValueError(
            f"{argument} must be one of {', '.join(map(repr, TRIANGLE_TESTS))}, got {name!r}"
        ) from error


@njit(cache=True, forceinline=True)
def _miss(x):
    return like(x, np.inf), like(x, np.nan), like(x, np.nan)


@njit(cache=True, forceinline=True)
def _dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@njit(cache=True, forceinline=True)
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, forceinline=True)
def _triple(nx, ny, nz, ex, ey, ez, px, py, pz):
    # N·(e × p)
    cx, cy, cz = _cross(ex, ey, ez, px, py, pz)
    return _dot(nx, ny, nz, cx, cy, cz)


@njit(cache=True, forceinline=True)
def _component(k, x, y, z):
    if k == 0:
        return x
    if k == 1:
        return y
    return z


@njit(cache=True, forceinline=True)
def _degenerate(ax, ay, az, bx, by, bz, cx, cy, cz):
    # pbrt-v4's test: the cross product of the edges is exactly zero (a repeated vertex, or
    # collinear vertices whose edge products cancel exactly).  Comparing the components rather
    # than the squared length keeps tiny triangles, whose squared normal would underflow.
    zero = like(ax, 0)
    nx, ny, nz = _cross(bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az)
    return nx == zero and ny == zero and nz == zero


@njit(cache=True, forceinline=True)
def moller(ox, oy, oz, dx, dy, dz, tmin, tmax, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Möller–Trumbore ray/triangle test (Möller & Trumbore 1997), without determinant epsilon.

    Solves ``o + t d = a + u (b - a) + v (c - a)`` by Cramer's rule written with scalar triple
    products.  Only ``det == 0`` is rejected, with no epsilon: the usual epsilon would miss
    small triangles, and the test's failures near edges are part of what this library measures.
    Degenerate triangles are rejected up front: for collinear vertices the rounded
    ``det = e1·(d × e2)`` need not cancel to 0 (measured: 9 % of rays aimed at the segment of
    ``(0, e, 2e)`` hit without the check).

    Parameters
    ----------
    ox, oy, oz, dx, dy, dz : float
        Ray origin and direction (not necessarily unit length).
    tmin, tmax : float
        Accepted range of the ray parameter.
    ax, ay, az, bx, by, bz, cx, cy, cz : float
        Triangle vertices.

    Returns
    -------
    t, u, v : float
        Hit parameter and barycentrics, or ``(inf, nan, nan)`` on a miss.
    """
    zero = like(ox, 0)
    one = like(ox, 1)
    if _degenerate(ax, ay, az, bx, by, bz, cx, cy, cz):
        return _miss(ox)
    e1x, e1y, e1z = bx - ax, by - ay, bz - az
    e2x, e2y, e2z = cx - ax, cy - ay, cz - az
    px, py, pz = _cross(dx, dy, dz, e2x, e2y, e2z)
    det = _dot(e1x, e1y, e1z, px, py, pz)
    # det = 0: the ray is parallel to the plane.
    if det == zero:
        return _miss(ox)
    inv_det = one / det
    sx, sy, sz = ox - ax, oy - ay, oz - az
    u = _dot(sx, sy, sz, px, py, pz) * inv_det
    if not (u >= zero and u <= one):
        return _miss(ox)
    qx, qy, qz = _cross(sx, sy, sz, e1x, e1y, e1z)
    v = _dot(dx, dy, dz, qx, qy, qz) * inv_det
    if not (v >= zero and u + v <= one):
        return _miss(ox)
    t = _dot(e2x, e2y, e2z, qx, qy, qz) * inv_det
    if not (t >= tmin and t <= tmax):
        return _miss(ox)
    return t, u, v


@njit(cache=True, forceinline=True)
def geometric(ox, oy, oz, dx, dy, dz, tmin, tmax, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Geometric ray/triangle test: hit the plane, then test the point against each edge.

    The textbook construction (Scratchapixel, "Ray-triangle intersection: geometric solution"):
    the plane hit ``t = N·(a - o) / N·d`` with ``N = (b - a) × (c - a)``, the point
    ``P = o + t d``, and ``P`` inside when ``N·(edge × (P - edge start)) >= 0`` for all three
    edges.  Because ``P`` is rounded to absolute coordinates before the edge tests, this test
    loses the most accuracy far from the origin and near edges.

    Parameters and returns are those of :func:`moller`.
    """
    zero = like(ox, 0)
    e1x, e1y, e1z = bx - ax, by - ay, bz - az
    e2x, e2y, e2z = cx - ax, cy - ay, cz - az
    nx, ny, nz = _cross(e1x, e1y, e1z, e2x, e2y, e2z)
    nn = _dot(nx, ny, nz, nx, ny, nz)
    nd = _dot(nx, ny, nz, dx, dy, dz)
    # nd = 0: parallel ray or degenerate triangle; nn = 0 also when squaring a tiny N underflows.
    if nd == zero or nn == zero:
        return _miss(ox)
    t = _dot(nx, ny, nz, ax - ox, ay - oy, az - oz) / nd
    if not (t >= tmin and t <= tmax):
        return _miss(ox)
    px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
    # N·(edge × (P - start)) is twice the area of the sub-triangle (edge, P) times |N|: the
    # barycentric weight of the vertex opposite the edge, times N·N.
    wa = _triple(nx, ny, nz, cx - bx, cy - by, cz - bz, px - bx, py - by, pz - bz)
    wb = _triple(nx, ny, nz, ax - cx, ay - cy, az - cz, px - cx, py - cy, pz - cz)
    wc = _triple(nx, ny, nz, e1x, e1y, e1z, px - ax, py - ay, pz - az)
    if not (wa >= zero and wb >= zero and wc >= zero):
        return _miss(ox)
    return t, wb / nn, wc / nn


@njit(cache=True, forceinline=True)
def watertight_setup(dx, dy, dz):
    """Per-ray set-up of the watertight test (Woop, Benthin & Wald 2013, JCGT 2(1), §3).

    Parameters
    ----------
    dx, dy, dz : float
        Ray direction.

    Returns
    -------
    kx, ky, kz : int
        Axis permutation: ``kz`` is the axis of the largest ``|d|``, ``kx``, ``ky`` the next two
        cyclically, swapped when ``d[kz] < 0`` so that the permutation keeps the winding.
    sx, sy, sz : float
        Shear ``d[kx]/d[kz]``, ``d[ky]/d[kz]`` and scale ``1/d[kz]`` that map the ray onto +z with
        unit length.  NaN for a zero direction, which makes every :func:`watertight` test miss.
    """
    # the axes from comparisons and integer choices, the components by one permutation
    # (simd.permuted): choices of floats were branches, taken at random on random rays
    wx, wy, wz = abs(dx), abs(dy), abs(dz)
    kz = 2 if (wz > wx) & (wz > wy) else (1 if wy > wx else 0)
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    backward = ((kz == 0) & (dx < 0)) | ((kz == 1) & (dy < 0)) | ((kz == 2) & (dz < 0))
    if backward:
        kx, ky = ky, kx
    dkx, dky, dkz = permuted(kx, ky, kz, dx, dy, dz)
    if dkz == like(dx, 0):
        nan = like(dx, np.nan)
        return kx, ky, kz, nan, nan, nan
    return kx, ky, kz, dkx / dkz, dky / dkz, like(dx, 1) / dkz


def _edge_exact(px, py, qx, qy):
    """Return ``qx·py - qy·px`` correctly rounded to the precision of ``px``.

    Called by :func:`watertight` when the plain evaluation gave 0, whose sign may then be wrong.
    This pure-Python version (exact rational arithmetic) runs when Numba's JIT is disabled.
    """
    exact = Fraction(float(qx)) * Fraction(float(py)) - Fraction(float(qy)) * Fraction(float(px))
    return type(px)(float(exact))


@njit(cache=True, forceinline=True)
def _product_error(a, b):
    # Dekker's TwoProduct (1971) with Veltkamp's split at 27 bits: a·b - fl(a·b), exactly, in
    # float64 without FMA (Numba does not contract a·b + c unless fastmath is on).
    split = like(a, 134217729.0)  # 2**27 + 1
    p = a * b
    ca = split * a
    a_hi = ca - (ca - a)
    a_lo = a - a_hi
    cb = split * b
    b_hi = cb - (cb - b)
    b_lo = b - b_hi
    return ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


@overload(_edge_exact, inline="always")
def _edge_exact_kernel(px, py, qx, qy):
    if px == types.float32:

        def impl(px, py, qx, qy):
            # Woop et al.'s double-precision fallback: products of float32 are exact in float64.
            exact = np.float64(qx) * np.float64(py) - np.float64(qy) * np.float64(px)
            return np.float32(exact)

        return impl

    def impl(px, py, qx, qy):
        # fl(p - q) = 0 only when the rounded products p, q are equal, so the exact value is the
        # difference of their rounding errors, which one subtraction rounds correctly.
        return _product_error(qx, py) - _product_error(qy, px)

    return impl


@njit(cache=True, forceinline=True)
def watertight(ox, oy, oz, kx, ky, kz, sx, sy, sz, tmin, tmax, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Watertight ray/triangle test (Woop, Benthin & Wald 2013, JCGT 2(1)).

    The vertices are moved into a frame where the ray starts at the origin and runs along +z,
    and the hit is decided by the signs of three 2D edge functions there.  A shared edge gets
    exactly opposite edge functions in its two triangles and every sign is exact (re-evaluated
    when it rounds to 0), so a ray through a closed mesh cannot slip between triangles.

    Parameters
    ----------
    ox, oy, oz : float
        Ray origin.
    kx, ky, kz, sx, sy, sz : int, int, int, float, float, float
        The ray's permutation and shear, from :func:`watertight_setup`.
    tmin, tmax : float
        Accepted range of the ray parameter.
    ax, ay, az, bx, by, bz, cx, cy, cz : float
        Triangle vertices.

    Returns
    -------
    t, u, v : float
        Hit parameter and barycentrics, or ``(inf, nan, nan)`` on a miss.
    """
    zero = like(ox, 0)
    # The shear below rounds, which can turn collinear vertices into a sliver that a ray through
    # the segment would hit: reject degenerate triangles first.
    if _degenerate(ax, ay, az, bx, by, bz, cx, cy, cz):
        return _miss(ox)
    # Translate the vertices by the ray origin and permute the axes so that kz is "forward".
    ax, ay, az = ax - ox, ay - oy, az - oz
    bx, by, bz = bx - ox, by - oy, bz - oz
    cx, cy, cz = cx - ox, cy - oy, cz - oz
    a_z = _component(kz, ax, ay, az)
    b_z = _component(kz, bx, by, bz)
    c_z = _component(kz, cx, cy, cz)
    # Shear so that the ray is the z axis (paper §3: A_x = A[kx] - S_x A[kz], ...).
    a_x = _component(kx, ax, ay, az) - sx * a_z
    a_y = _component(ky, ax, ay, az) - sy * a_z
    b_x = _component(kx, bx, by, bz) - sx * b_z
    b_y = _component(ky, bx, by, bz) - sy * b_z
    c_x = _component(kx, cx, cy, cz) - sx * c_z
    c_y = _component(ky, cx, cy, cz) - sy * c_z
    # Scaled barycentrics: U is the edge function of edge b->c (the weight of a), V of c->a
    # (weight of b), W of a->b (weight of c); one formula for every directed edge p->q, so a
    # shared edge gives exactly negated values in its two triangles.
    u_a = c_x * b_y - c_y * b_x
    v_b = a_x * c_y - a_y * c_x
    w_c = b_x * a_y - b_y * a_x
    # Rounding is monotonic, so fl(p) - fl(q) has the sign of p - q unless the rounded products
    # are equal; only a 0 can be wrong, and is re-evaluated exactly (paper §3, double fallback).
    if u_a == zero:
        u_a = _edge_exact(b_x, b_y, c_x, c_y)
    if v_b == zero:
        v_b = _edge_exact(c_x, c_y, a_x, a_y)
    if w_c == zero:
        w_c = _edge_exact(a_x, a_y, b_x, b_y)
    # Inside when the signs do not differ (zeros allowed): both windings hit.
    if not (
        (u_a >= zero and v_b >= zero and w_c >= zero)
        or (u_a <= zero and v_b <= zero and w_c <= zero)
    ):
        return _miss(ox)
    det = u_a + v_b + w_c
    if det == zero:
        return _miss(ox)
    # Scaled hit distance T = t·det from the scaled z of the vertices.
    t_det = u_a * (sz * a_z) + v_b * (sz * b_z) + w_c * (sz * c_z)
    # Range test without a division, after making det positive (the paper's sign-mask xor).
    if det < zero:
        det, t_det, v_b, w_c = -det, -t_det, -v_b, -w_c
    if not (t_det >= tmin * det and t_det <= tmax * det):
        return _miss(ox)
    t = t_det / det
    # inf / inf when the edge functions overflow (coordinates near the top of the range)
    if t != t:
        return _miss(ox)
    # T/det can round one ulp past a bound that the product test accepted: clamp into range.
    t = min(max(t, tmin), tmax)
    return t, v_b / det, w_c / det


@njit(cache=True, forceinline=True)
def triangle_hit(
    test, ox, oy, oz, dx, dy, dz, kx, ky, kz, sx, sy, sz, tmin, tmax,
    ax, ay, az, bx, by, bz, cx, cy, cz,
):  # fmt: skip
    """Run the triangle test with code ``test`` (``WATERTIGHT``, ``MOLLER`` or ``GEOMETRIC``).

    ``kx ... sz`` come from :func:`watertight_setup` for the ray and are ignored by the other two
    tests.  Returns ``(t, u, v)`` as the tests do.
    """
    if test == WATERTIGHT:
        return watertight(
            ox, oy, oz, kx, ky, kz, sx, sy, sz, tmin, tmax, ax, ay, az, bx, by, bz, cx, cy, cz
        )
    if test == MOLLER:
        return moller(ox, oy, oz, dx, dy, dz, tmin, tmax, ax, ay, az, bx, by, bz, cx, cy, cz)
    return geometric(ox, oy, oz, dx, dy, dz, tmin, tmax, ax, ay, az, bx, by, bz, cx, cy, cz)


@njit(cache=True, forceinline=True)
def triangle_normal(ax, ay, az, bx, by, bz, cx, cy, cz):
    """Unit normal ``(b - a) × (c - a) / |(b - a) × (c - a)|``; NaN for a degenerate triangle."""
    nx, ny, nz = _cross(bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az)
    # Divide by the largest component first so that squaring neither underflows nor overflows.
    scale = max(abs(nx), abs(ny), abs(nz))
    if not (scale > like(ax, 0)):
        nan = like(ax, np.nan)
        return nan, nan, nan
    nx, ny, nz = nx / scale, ny / scale, nz / scale
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    return nx / length, ny / length, nz / length


@njit(cache=True, parallel=True)
def _intersect_pairs(test, origins, directions, tmin, tmax, a, b, c, t, uv, normal):
    # Triangle i of a, b, c for ray i, or triangle 0 for every ray when only one is given.
    step = 1 if a.shape[0] > 1 else 0
    for i in prange(origins.shape[0]):
        j = i * step
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        kx, ky, kz, sx, sy, sz = watertight_setup(dx, dy, dz)
        t[i], u, v = triangle_hit(
            test, ox, oy, oz, dx, dy, dz, kx, ky, kz, sx, sy, sz, tmin[i], tmax[i],
            a[j, 0], a[j, 1], a[j, 2], b[j, 0], b[j, 1], b[j, 2], c[j, 0], c[j, 1], c[j, 2],
        )  # fmt: skip
        if uv.shape[0] > 0:
            uv[i, 0], uv[i, 1] = u, v
        if normal.shape[0] > 0 and t[i] < np.inf:
            normal[i, 0], normal[i, 1], normal[i, 2] = triangle_normal(
                a[j, 0], a[j, 1], a[j, 2], b[j, 0], b[j, 1], b[j, 2], c[j, 0], c[j, 1], c[j, 2]
            )


def _as_triangle_vertices(value, name, count, dtype):
    array = as_float_array(value, name, dtype)
    if array.shape == (3,):
        return array.reshape(1, 3)
    if array.shape != (count, 3):
        raise ValueError(f"{name} must have shape (3,) or ({count}, 3), got {array.shape}")
    return array


def intersect_triangles(
    origins,
    directions,
    a,
    b,
    c,
    *,
    test="watertight",
    tmin=0.0,
    tmax=np.inf,
    normal=False,
    uv=False,
    dtype="float64",
):
    """Intersect each ray with one triangle (pairwise, no acceleration structure).

    Parameters
    ----------
    origins, directions : array_like, shape (N, 3)
        Rays; directions need not be unit length (hit point ``origin + t * direction``).
    a, b, c : array_like, shape (3,) or (N, 3)
        Triangle vertices: one triangle for every ray, or triangle i for ray i.
    test : {"watertight", "moller", "geometric"}
        Which ray/triangle test to run.
    tmin, tmax : float or array_like of shape (N,)
        Accepted range of t.
    normal, uv : bool
        Also return unit geometric normals / barycentrics ``(u, v)`` (hit point
        ``(1-u-v) a + u b + v c``).
    dtype : {"float32", "float64"}
        Precision of the computation and of the returned floats.

    Returns
    -------
    raycore.hits.Hits
        ``t`` (N,) with ``inf`` on misses; ``geom_id`` and ``prim_id`` (N,) 0 on hits and -1 on
        misses; ``uv`` (N, 2) and ``normal`` (N, 3) when asked for (NaN rows on misses), else
        None.

    Raises
    ------
    ValueError
        Naming the argument: bad shapes, NaN or inf coordinates, zero directions, NaN bounds,
        unknown ``test`` or ``dtype``.
    """
    code = triangle_test_code(test, argument="test")
    precision = resolve_dtype(dtype)
    origins, directions, tmin, tmax = prepare_rays(origins, directions, tmin, tmax, precision)
    count = len(origins)
    a, b, c = (
        _as_triangle_vertices(value, name, count, precision)
        for value, name in ((a, "a"), (b, "b"), (c, "c"))
    )
    if not len(a) == len(b) == len(c):  # one shared vertex among per-ray ones: a row for each
        a, b, c = (np.repeat(x, count // len(x), axis=0) for x in (a, b, c))
    t = np.empty(count, dtype=precision)
    uv_out = np.full((count if uv else 0, 2), np.nan, dtype=precision)
    normal_out = np.full((count if normal else 0, 3), np.nan, dtype=precision)
    inputs = (read_only(x) for x in (origins, directions, tmin, tmax, a, b, c))
    _intersect_pairs(code, *inputs, t, uv_out, normal_out)
    ids = np.where(t < np.inf, 0, -1).astype(np.int64)
    return Hits(
        t=t,
        geom_id=ids,
        prim_id=ids.copy(),
        uv=uv_out if uv else None,
        normal=normal_out if normal else None,
    )
