"""The bounds of t_error.py hold against exact rational arithmetic, grazing rays included."""

from fractions import Fraction

import numpy as np
import pytest

from raycore import Scene
from raycore.primitives.triangle import intersect_triangles

from .brute import apply_affine, random_affine, unit
from .t_error import library_instance_bound, triangle_t_bound, unit_roundoff, world_instance_bound

TESTS = ("watertight", "moller", "geometric")


def exact_t(origin, direction, corners):
    """The ray parameter where the exact ray meets the exact plane of ``corners`` (float64
    values taken as exact rationals)."""
    o, d = [Fraction(x) for x in origin], [Fraction(x) for x in direction]
    a, b, c = ([Fraction(x) for x in v] for v in corners)
    e1 = [b[i] - a[i] for i in range(3)]
    e2 = [c[i] - a[i] for i in range(3)]
    n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
         e1[0] * e2[1] - e1[1] * e2[0]]
    return float(sum(n[i] * (a[i] - o[i]) for i in range(3))
                 / sum(n[i] * d[i] for i in range(3)))


def exact_world_t(origin, direction, vertices, transform):
    """:func:`exact_t` on the triangle ``L v + m``, mapped exactly."""
    m = [[Fraction(x) for x in row] for row in transform[:3].tolist()]
    world = [[sum((m[i][j] * Fraction(v[j]) for j in range(3)), m[i][3]) for i in range(3)]
             for v in vertices.tolist()]
    o, d = [Fraction(x) for x in origin], [Fraction(x) for x in direction]
    e1 = [world[1][i] - world[0][i] for i in range(3)]
    e2 = [world[2][i] - world[0][i] for i in range(3)]
    n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
         e1[0] * e2[1] - e1[1] * e2[0]]
    return float(sum(n[i] * (world[0][i] - o[i]) for i in range(3))
                 / sum(n[i] * d[i] for i in range(3)))


def aimed_rays(corners, rng, grazing):
    """A ray per triangle aimed at a random point inside it, from 5 to 40 units away: from any
    direction, or (``grazing``) at 0.06 to 6 degrees from the triangle's plane."""
    count = len(corners)
    weights = rng.dirichlet([1.0, 1.0, 1.0], count)
    target = np.einsum("hk,hki->hi", weights, corners)
    if grazing:
        normal = unit(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
        along = unit(np.cross(normal, rng.normal(size=(count, 3))))
        slope = np.tan(np.radians(10.0 ** rng.uniform(-1.2, 0.8, count)))
        direction = along + slope[:, None] * normal * rng.choice([-1, 1], (count, 1))
    else:
        direction = rng.normal(size=(count, 3))
    direction = unit(direction) * rng.uniform(0.2, 5.0, (count, 1))
    distance = rng.uniform(5.0, 40.0, count)
    return target - direction * (distance / np.linalg.norm(direction, axis=1))[:, None], direction


def random_triangles(rng, count):
    """Triangles of sizes 0.05 to 3 and aspect ratios up to 30, up to 20 units from the origin."""
    centre = rng.uniform(-20, 20, (count, 1, 3))
    size = 10.0 ** rng.uniform(-1.3, 0.5, (count, 1, 1))
    corners = rng.normal(size=(count, 3, 3))
    squash = unit(rng.normal(size=(count, 1, 3)))
    thin = 10.0 ** rng.uniform(-1.5, 0, (count, 1, 1))
    # shrink one direction by up to 30: thin triangles have large E^2 / A
    corners = corners - (1 - thin) * np.sum(corners * squash, axis=2, keepdims=True) * squash
    return centre + size * corners


@pytest.mark.parametrize("test", TESTS)
@pytest.mark.parametrize("grazing", [False, True], ids=["any", "grazing"])
def test_triangle_bound_holds_against_exact_arithmetic(dtype, test, grazing):
    rng = np.random.default_rng(7)
    corners = random_triangles(rng, 500).astype(dtype).astype(np.float64)
    origins, directions = (x.astype(dtype).astype(np.float64)
                           for x in aimed_rays(corners, rng, grazing))
    hits = intersect_triangles(origins, directions, corners[:, 0], corners[:, 1], corners[:, 2],
                               test=test, dtype=dtype)
    hit = np.flatnonzero(hits.t < np.inf)
    assert len(hit) > 0.9 * len(corners)
    exact = np.array([exact_t(origins[i], directions[i], corners[i]) for i in hit])
    bound = triangle_t_bound(test, unit_roundoff(dtype), origins[hit], directions[hit],
                             corners[hit], exact)
    error = np.abs(hits.t[hit] - exact)
    assert np.all(error <= bound), f"worst error / bound {np.max(error / bound):.3g}"
    # the bound is not vacuous: most errors use a sizeable part of it somewhere
    assert np.max(error / bound) > 0.01


@pytest.mark.parametrize("test", TESTS)
def test_instance_bounds_hold_against_exact_arithmetic(dtype, test):
    """The library's t on an instance (object space) and the brute force's (world space, on
    the triangle mapped by ``apply_affine``) are each within their bound of the exact t on the
    exact triangle ``L v + m``."""
    rng = np.random.default_rng(8)
    count = 300
    prototype = random_triangles(rng, 1)[0]
    scene = Scene(dtype=dtype)
    proto = scene.add_mesh(prototype, [[0, 1, 2]], visible=False)
    transforms = np.array([random_affine(rng, 0.3, 3.0, spread=30.0) for _ in range(count)])
    world = np.array([apply_affine(m, prototype) for m in transforms])
    origins, directions = aimed_rays(world, rng, grazing=False)
    graze_o, graze_d = aimed_rays(world, rng, grazing=True)
    origins = np.concatenate([origins, graze_o]).astype(dtype).astype(np.float64)
    directions = np.concatenate([directions, graze_d]).astype(dtype).astype(np.float64)
    aimed = np.tile(np.arange(count), 2)
    # one scene per ray would be slow: every instance is in one scene, and each ray is checked
    # against whichever instance it hits first
    ids = [scene.add_instance(proto, m) for m in transforms]
    hits = scene.intersect(origins, directions, triangle_test=test)
    hit = np.flatnonzero(hits.geom_id >= 0)
    assert len(hit) > 0.9 * len(origins)
    which = np.searchsorted(ids, hits.geom_id[hit])
    assert np.mean(which == aimed[hit]) > 0.5
    vertices = np.broadcast_to(prototype, (len(hit), 3, 3))
    exact = np.array([exact_world_t(origins[r], directions[r], prototype, transforms[k])
                      for r, k in zip(hit, which, strict=True)])
    args = (test, dtype, origins[hit], directions[hit], exact, vertices, transforms[which])
    error = np.abs(hits.t[hit] - exact)
    bound = library_instance_bound(*args)
    assert np.all(error <= bound), f"library: worst error / bound {np.max(error / bound):.3g}"
    assert np.max(error / bound) > 0.01
    # the brute force's world-space triangles
    corners = world[which].astype(dtype).astype(np.float64)
    brute = intersect_triangles(origins[hit], directions[hit], corners[:, 0], corners[:, 1],
                                corners[:, 2], test=test, dtype=dtype)
    found = brute.t < np.inf
    assert found.mean() > 0.9
    error = np.abs(brute.t[found] - exact[found])
    bound = world_instance_bound(*(a[found] if isinstance(a, np.ndarray) else a for a in args))
    assert np.all(error <= bound), f"brute force: worst error / bound {np.max(error / bound):.3g}"
    assert np.max(error / bound) > 0.01
