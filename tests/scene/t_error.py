"""Bounds on the rounding error of a hit's ``t``, derived from the arithmetic of each test.

Instances are tested by the library in object space (the ray mapped by the stored inverse
transform) and by the brute force in world space (the triangle mapped by the transform), so the
two ``t`` differ by rounding.  Each is bounded here against the exact ``t``: the exact ray (as
the scene's precision holds it) against the exact triangle ``L v + m``.  The tolerance between
them is the sum of the two bounds (:func:`instance_tolerance`).

Everything is first order in the unit roundoff u (2^-53 in float64, 2^-24 in float32), except
the division by each test's determinant: when its relative error ``ρ`` (given with each test) is
not small, as on a thin triangle grazed in float32, the error grows by ``1 / (1 − ρ)``, and the
bound is divided by that (infinite for ``ρ ≥ 1``).

**Moving the ray or the triangle.**  A ray ``o + t d`` meets a plane with unit normal ``n`` at
``t``.  Moving the plane by ``δ`` along ``n``, the origin by ``δo`` and the direction by ``δd``
moves ``t`` by ``(δ − n·δo − t n·δd) / (n·d)``.  A vertex moved by ``δv_i`` moves the plane at the
hit point by ``Σ w_i n·δv_i`` (``w`` the barycentrics, which sum to 1).  So a rounding that
amounts to moving the vertices or the ray by at most ``ε`` per coordinate costs at most
``‖n‖₁ ε / |n·d|``: nothing special head-on, ``1 / cos θ`` for a ray meeting the plane at a
grazing angle.  The tolerance this replaces, ``16 ε (|o| + R) / |d|``, had no ``1 / |cos θ|``:
ray 583 of the seed-1 scene meets its instance triangle with ``cos θ = 0.023`` (1.3 degrees from
the plane); on the AVX2 machine the library's float64 ``t`` was 103 ulps below the exact one and
the brute force's 19 below, 84 ulps apart where that tolerance allowed 75.  The bound below
allows about 1900 there.  Over the instance hits of the seeded scenes, the watertight test's bound
is below the old tolerance on 34 to 48 % of them, 1.0 to 1.2 times it at the median, 2.5 times at
the 90th percentile.

**The watertight test** (``raycore.primitives.triangle.watertight``), with ``D = max_i ‖v_i −
o‖∞``, ``E`` the longest edge in the ∞-norm, ``A`` the area and ``kz`` the axis of the largest
``|d|``:

* ``v − o`` rounds each coordinate: a vertex move of at most ``u D``;
* the shear ``A_x = A[kx] − S_x A[kz]`` (``|S_x| ≤ 1``) adds ``u (|A[kx]| + 2 |S_x A[kz]|) ≤ 3u D``
  on the two lateral axes, and leaves ``z`` alone: again a vertex move, so together
  ``4u ‖n‖₁ D / |n·d|``;
* ``S_x = d[kx] / d[kz]`` rounded is the direction moved by ``u |d[kx]|``: ``u t ‖n‖₁ ‖d‖∞ /
  |n·d|``;
* the edge functions ``U = C_x B_y − C_y B_x`` round by ``2u (|C_x B_y| + |C_y B_x|)``.  The ray
  passes inside the triangle, so the lateral coordinates are at most ``2E`` and the three
  together err by ``Σ|δU| ≤ 48u E²``, against ``det = U + V + W = 2A |n·d| / ‖d‖∞``.  ``t`` is the
  mean of the vertices' ``z_i = A_i[kz] / d[kz]`` weighted by ``U / det`` (weights summing to 1),
  and ``|z_i − t| ≤ E / ‖d‖∞``, so the weights' errors move ``t`` by at most
  ``(2 Σ|δU| / det) E / ‖d‖∞ = 48u E³ / (A |n·d|)``; ``ρ = Σ|δU| / det = 24u (E² / A) ‖d‖∞ /
  |n·d|``;
* ``z_i = S_z A[kz]`` (two roundings), ``T = Σ U z_i`` (three more on each term), ``det`` (two,
  relative: the ``U`` share a sign) and ``T / det`` (one): ``8u max|z_i| ≤ 8u D / ‖d‖∞``.

**Möller–Trumbore** (``moller``): ``e1 = b − a``, ``e2 = c − a`` and ``s = o − a`` rounded move
``b``, ``c`` by ``u E`` and ``o`` by ``u D``: ``u ‖n‖₁ (D + E) / |n·d|``.  ``p = d × e2`` errs by
``4u ‖d‖∞ E`` per component (each at most ``2 ‖d‖∞ E``), ``q = s × e1`` by ``4u D E`` (each at most
``2 D E``); the dot products ``e1·p`` and ``e2·q`` then err by ``30u E² ‖d‖∞`` and ``30u E² D``,
against ``det = 2A |n·d|``: ``15u (E² / A) (D + t ‖d‖∞) / |n·d|``, with ``ρ = 15u (E² / A) ‖d‖∞ /
|n·d|``; the reciprocal and the product, ``2u t``.

**The geometric test** (``geometric``): ``e1``, ``e2`` rounded move ``b``, ``c``: ``u ‖n‖₁ E``.
``N = e1 × e2`` errs by ``4u E²`` per component, which turns the plane about ``a``: ``δN·(a − p) /
(N·d)`` with ``|a − p| ≤ E``, at most ``6u E³ / (A |n·d|)``.  ``a − o`` rounded moves ``a``:
``u ‖n‖₁ D``; the dot products ``N·(a − o)`` and ``N·d`` err by ``3u ‖n‖₁ D`` and ``3u t ‖n‖₁ ‖d‖∞``
over ``|n·d|``, with ``ρ = 3u ‖n‖₁ ‖d‖∞ / |n·d|``; the division, ``u t``.

**Mapping the ray into object space** (the library): the stored inverse ``[X̂ | b̂]`` is the
exact ``[X | b]`` rounded once to float64 (``raycore.mesh.affine_inverse``) and then to the
scene's precision, so ``|X̂ − X| ≤ η |X|`` and ``|b̂ − b| ≤ η |b|`` with ``η = u + 2^-53``.
``X0 o0 + X1 o1 + X2 o2 + b``, summed in any order, rounds each of its four terms at most four
times, and the direction's three terms three times: the object-space origin is off by
``(η + 4u) (|X| |o| + |b|)`` and the direction by ``(η + 3u) |X| |d|``, which the first rule
turns into ``t``.  The mesh's vertices are stored in the scene's precision: they move by exactly
``v_dtype − v``.

**The brute force's world triangle** (``apply_affine``): ``((L0 v0 + L1 v1) + L2 v2) + m`` in
float64 is within ``4 · 2^-53 (|L| |v| + |m|)``, then rounded to the scene's precision (``u |w|``).
"""

import numpy as np

#: Per test, the coefficients of the bound on ``|t̂ − t|`` derived above, in units of u:
#: ``{[‖n‖₁ (cD D + cE E + ct t ‖d‖∞) + (E² / A) (c3 E + cM (D + t ‖d‖∞))] / |n·d|
#: + cz D / ‖d‖∞ + cT t} / (1 − ρ)`` with ``ρ = u (rG E² / A + rn ‖n‖₁) ‖d‖∞ / |n·d|``.
COEFFICIENTS = {
    #             cD cE ct  c3  cM cz cT  rG rn
    "watertight": (4, 0, 1, 48, 0, 8, 0, 24, 0),
    "moller": (1, 1, 0, 0, 15, 0, 2, 15, 0),
    "geometric": (4, 1, 3, 6, 0, 0, 1, 0, 3),
}


def unit_roundoff(dtype):
    return float(np.finfo(np.dtype(dtype)).eps) / 2


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _plane(corners):
    """Unit normals (H, 3), areas (H,) and longest edges in the ∞-norm (H,) of (H, 3, 3)
    triangles."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    normal = np.cross(b - a, c - a)
    double_area = np.linalg.norm(normal, axis=1)
    edges = np.stack([b - a, c - b, a - c], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return normal / double_area[:, None], double_area / 2, np.abs(edges).max(axis=(1, 2))


def _moved(normal, directions, move):
    """``|n|·move / |n·d|``: what moving the plane or the ray by ``move`` (H, 3), per coordinate,
    does to ``t``."""
    with np.errstate(divide="ignore"):
        return _dot(np.abs(normal), move) / np.abs(_dot(normal, directions))


def triangle_t_bound(test, u, origins, directions, corners, t):
    """(H,) bound on the rounding error of ``t`` of ray/triangle ``test`` computing with unit
    roundoff ``u``, for hits ``t`` of rays ``origins``, ``directions`` (H, 3) on triangles
    ``corners`` (H, 3, 3), all as the computation sees them (see the module's docstring)."""
    c_d, c_e, c_t, c_3, c_m, c_z, c_t_flat, r_g, r_n = COEFFICIENTS[test]
    normal, area, edge = _plane(corners)
    reach = np.abs(corners - origins[:, None]).max(axis=(1, 2))  # D
    longest = np.abs(directions).max(axis=1)  # ‖d‖∞
    along = np.abs(t) * longest  # t ‖d‖∞
    l1 = np.abs(normal).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        shape = edge**2 / area  # E² / A
        facing = np.abs(_dot(normal, directions))  # |n·d|
        lengths = (l1 * (c_d * reach + c_e * edge + c_t * along)
                   + shape * (c_3 * edge + c_m * (reach + along)))
        bound = u * (lengths / facing + c_z * reach / longest + c_t_flat * np.abs(t))
        rho = u * (r_g * shape + r_n * l1) * longest / facing
        bound = np.where(rho < 1, bound / (1 - rho), np.inf)
    return np.where(np.isnan(bound), np.inf, bound)


def library_instance_bound(test, dtype, origins, directions, t, vertices, transforms):
    """(H,) bound on ``|t − t_exact|`` for the library's hits on instance triangles: the ray
    mapped into object space by the rounded inverse, then the test there.

    Parameters
    ----------
    test : str
        The triangle test.
    dtype : the scene's precision
    origins, directions : (H, 3) float64
        The rays as the scene's precision holds them.
    t : (H,) float64
        The hits (any estimate: ``t`` enters the bound only as a size).
    vertices : (H, 3, 3) float64
        The triangles in object space, as given to ``Scene.add_mesh``.
    transforms : (H, 4, 4) float64
        Each hit's instance transform (world from object).
    """
    u = unit_roundoff(dtype)
    inverse = np.linalg.inv(transforms[:, :3, :3])  # exact enough for a bound
    local_shift = -np.einsum("hij,hj->hi", inverse, transforms[:, :3, 3])
    local_origins = np.einsum("hij,hj->hi", inverse, origins) + local_shift
    local_directions = np.einsum("hij,hj->hi", inverse, directions)
    eta = u + unit_roundoff(np.float64)
    ray_move = ((eta + 4 * u) * (np.einsum("hij,hj->hi", np.abs(inverse), np.abs(origins))
                                 + np.abs(local_shift))
                + np.abs(t)[:, None] * (eta + 3 * u) * np.einsum(
                    "hij,hj->hi", np.abs(inverse), np.abs(directions)))
    stored = vertices.astype(dtype).astype(np.float64)
    vertex_move = np.abs(stored - vertices).max(axis=1)
    return (_moved(_plane(stored)[0], local_directions, ray_move + vertex_move)
            + triangle_t_bound(test, u, local_origins, local_directions, stored, t))


def world_instance_bound(test, dtype, origins, directions, t, vertices, transforms):
    """(H,) bound on ``|t − t_exact|`` for the brute force's hits on instance triangles: the
    triangle mapped to world space in float64 (``apply_affine``), rounded to the scene's
    precision, and tested there.  Parameters as :func:`library_instance_bound`."""
    u = unit_roundoff(dtype)
    linear, shift = transforms[:, :3, :3], transforms[:, :3, 3]
    world = np.einsum("hij,hkj->hki", linear, vertices) + shift[:, None]
    size = np.einsum("hij,hkj->hki", np.abs(linear), np.abs(vertices)) + np.abs(shift)[:, None]
    move = (4 * unit_roundoff(np.float64) * size + u * np.abs(world)).max(axis=1)
    return (_moved(_plane(world)[0], directions, move)
            + triangle_t_bound(test, u, origins, directions, world, t))


def instance_tolerance(*args):
    """(H,) bound on ``|t_library − t_brute_force|`` on an instance triangle: the sum of the
    two bounds (parameters as :func:`library_instance_bound`)."""
    return library_instance_bound(*args) + world_instance_bound(*args)
