"""Watertightness through the BVH: rays from inside a closed mesh, aimed exactly at its vertices
and at points of its edges, must all hit (with the watertight test), in both precisions.

The other two tests' leak rates on the same rays are measured and printed, not asserted.
"""

import numpy as np
import pytest
import trimesh

from raycore import Scene
from raycore.primitives.triangle import intersect_triangles

from .brute import CLOSED_MESHES, DTYPES, MESH_DIR, mesh_scene, shared_mesh

TESTS = ("watertight", "moller", "geometric")


def two_sum(a, b):
    """a + b and its rounding error (Knuth), elementwise in float64."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def exact_targets(vertices, faces, dtype, rng, count, tries=100000):
    """Vertices and points ``v + k/2^m (w - v)`` of edges, exactly representable in ``dtype``.

    The coordinates are computed in float64 from the vertices as the scene stores them; a point
    is kept only when every step was exact (checked with error-free transforms) and it rounds
    to itself in ``dtype``.

    Returns
    -------
    targets : (T, 3) float64
    features : (T, 2) int
        The vertex ``(v, v)`` or the edge ``(v, w)`` each target lies on.
    """
    stored = vertices.astype(dtype).astype(np.float64)
    used = np.unique(faces)
    pick = rng.choice(used, min(count, len(used)), replace=False)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    # most edge points need more bits than dtype has: draw many, keep the exact ones
    edges = edges[rng.integers(0, len(edges), tries)]
    m = rng.integers(1, 5, tries)
    k = 2 * rng.integers(0, 2 ** (m - 1)) + 1  # odd: k/2^m in (0, 1), not a vertex
    fraction = (k / 2.0**m)[:, None]
    v, w = stored[edges[:, 0]], stored[edges[:, 1]]
    diff, e1 = two_sum(w, -v)
    scaled = fraction * diff
    # k < 16 takes 4 bits: the product is exact when diff's significand ends in 4 zero bits
    exact = (e1 == 0) & (np.ldexp(np.frexp(diff)[0], 53) % 16 == 0)
    point, e2 = two_sum(v, scaled)
    exact = (exact & (e2 == 0)).all(axis=1)
    targets = np.concatenate([stored[pick], point[exact]])
    features = np.concatenate([np.stack([pick, pick], axis=1), edges[exact]])
    keep = np.flatnonzero(np.all(targets.astype(dtype) == targets, axis=1))
    on_edge = keep[features[keep, 0] != features[keep, 1]]
    keep = np.concatenate([keep[features[keep, 0] == features[keep, 1]], on_edge[:count]])
    return targets[keep], features[keep]


def inside_points(mesh, scene, rng, count=4):
    """Points inside the mesh (trimesh and Scene.contains agree), nearest its centroid, on a
    coarse dyadic grid so that ``target - origin`` is often exact."""
    lo, hi = mesh.bounds
    step = 2.0 ** np.floor(np.log2(np.linalg.norm(hi - lo) / 64))
    candidates = np.round(rng.uniform(lo, hi, (400, 3)) / step) * step
    inside = mesh.contains(candidates) & scene.contains(candidates)
    candidates = candidates[inside]
    order = np.argsort(np.linalg.norm(candidates - mesh.centroid, axis=1))
    assert len(order) >= count
    return candidates[order[:count]]


def aimed_rays(name, dtype, rng):
    """Rays from points inside mesh ``name`` through exact targets (at t = 1), kept where
    ``target - origin`` is exact in ``dtype``: ``(origins, directions, features, targets)``."""
    mesh = shared_mesh(name)
    scene = mesh_scene(name, dtype)
    origins = inside_points(mesh, scene, rng)
    targets, features = exact_targets(mesh.vertices, mesh.faces, dtype, rng, 6000)
    o = np.repeat(origins, len(targets), axis=0)
    t = np.tile(targets, (len(origins), 1))
    d, err = two_sum(t, -o)
    keep = np.all((err == 0) & (d.astype(dtype) == d), axis=1)
    return o[keep], d[keep], np.tile(features, (len(origins), 1))[keep], len(targets)


def crosses_at_target(vertices, faces, origins, directions, features, rng, count=16):
    """(N,) bool: whether each ray crosses the surface at its target (t = 1) rather than only
    touching it, decided locally and independently of the BVH and of the watertight kernel.

    Rays tilted by 1e-7 of their length around the target cross the faces incident to the
    target's vertex or edge an odd number of times (in float64, Möller–Trumbore) when the
    surface is crossed there, an even number when it is only touched.
    """
    n = len(origins)
    if n == 0:
        return np.zeros(0, bool)
    # faces incident to each ray's vertex v (CSR over the vertex-face incidence)
    corner = faces.ravel()
    by_vertex = np.argsort(corner, kind="stable")
    starts = np.searchsorted(corner[by_vertex], features[:, 0])
    ends = np.searchsorted(corner[by_vertex], features[:, 0], side="right")
    ray = np.repeat(np.arange(n), ends - starts)
    face = by_vertex[np.concatenate([np.arange(s, e) for s, e in zip(starts, ends,
                                                                     strict=True)])] // 3
    # for an edge (v, w), only the faces holding w as well
    keep = np.any(faces[face] == features[ray, 1:2], axis=1)
    ray, face = ray[keep], face[keep]
    tilt = rng.normal(size=(n, count, 3))
    unit_d = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    tilt -= np.einsum("nkc,nc->nk", tilt, unit_d)[..., None] * unit_d[:, None]
    tilt *= 1e-7 * np.linalg.norm(directions, axis=1)[:, None, None] / np.linalg.norm(
        tilt, axis=2, keepdims=True)
    tilted = directions[:, None] + tilt  # (n, count, 3)
    pair_ray = np.repeat(ray, count)
    pair_tilt = np.tile(np.arange(count), len(ray))
    corners = vertices[faces[np.repeat(face, count)]]
    hits = intersect_triangles(origins[pair_ray], tilted[pair_ray, pair_tilt], corners[:, 0],
                               corners[:, 1], corners[:, 2], test="moller", tmin=0.5, tmax=1.5)
    crossings = np.bincount((pair_ray * count + pair_tilt)[hits.t < np.inf],
                            minlength=n * count).reshape(n, count)
    return (crossings % 2).mean(axis=1) > 0.5


def leaks(scene, name, origins, directions, features, test):
    """Rays that leak through the mesh at their target (t = 1), and the number that only
    touch it.

    A ray from inside reaches the surface at its target, so its closest hit must be at t <= 1,
    unless it merely touches the surface there (at a vertex or edge where the surface folds)
    and goes on inside: then its first hit lies farther.  A ray leaks when it misses, or when
    its first hit lies beyond the target although it crosses the surface there.
    """
    mesh = shared_mesh(name)
    hits = scene.intersect(origins, directions, triangle_test=test)
    missed = hits.geom_id < 0
    beyond = np.flatnonzero(~missed & (hits.t > 1 + np.sqrt(np.finfo(hits.t.dtype).eps)))
    stored = mesh.vertices.astype(scene.dtype).astype(np.float64)
    escaped = np.zeros(len(origins), bool)
    escaped[beyond] = crosses_at_target(stored, mesh.faces, origins[beyond], directions[beyond],
                                        features[beyond], np.random.default_rng(0))
    return missed | escaped, len(beyond) - escaped.sum()


@pytest.mark.parametrize("name", CLOSED_MESHES)
def test_no_ray_from_inside_leaks_through_a_closed_mesh(name):
    mesh = shared_mesh(name)
    assert mesh.is_watertight
    assert trimesh.load(MESH_DIR / f"{name}.obj", force="mesh").is_watertight
    for dtype in DTYPES:
        rng = np.random.default_rng(5)
        origins, directions, features, targets = aimed_rays(name, dtype, rng)
        # the data: thousands of exact rays through vertices and edges, from several origins
        assert len(origins) > 10000 and targets > 5000
        assert (features[:, 0] == features[:, 1]).mean() > 0.2
        assert (features[:, 0] != features[:, 1]).mean() > 0.2
        scene = mesh_scene(name, dtype)
        rates = {}
        for test in TESTS:
            leaked, touched = leaks(scene, name, origins, directions, features, test)
            rates[test] = leaked.mean()
            if test == "watertight":
                assert not leaked.any(), (
                    f"{leaked.sum()} of {len(origins)} rays leak, first: o="
                    f"{origins[leaked][0].tolist()} d={directions[leaked][0].tolist()}")
                touches = touched
        # the rays reach the cases where tests that are not watertight do leak
        assert rates["moller"] + rates["geometric"] > 0
        print(f"\n{name} {dtype}: {len(origins)} rays at vertices and edges from inside "
              f"({touches} only touch the surface there); leak "
              + ", ".join(f"{test} {rate:.3%}" for test, rate in rates.items()))


def tessellated_box(n=8):
    """The cube [-1, 1]^3 with each face an n x n grid of quads, each split into 2 triangles."""
    grid = np.linspace(-1, 1, n + 1)
    vertices, faces = [], []
    for axis in range(3):
        for side in (-1.0, 1.0):
            u, v = np.meshgrid(grid, grid, indexing="ij")
            p = np.zeros((n + 1, n + 1, 3))
            p[..., axis] = side
            p[..., (axis + 1) % 3] = u
            p[..., (axis + 2) % 3] = v
            base = sum(len(x) for x in vertices)
            vertices.append(p.reshape(-1, 3))
            i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
            a = base + i * (n + 1) + j
            b, c, d = a + n + 1, a + n + 2, a + 1
            faces.append(np.stack([a, b, c], -1).reshape(-1, 3))
            faces.append(np.stack([a, c, d], -1).reshape(-1, 3))
    vertices, faces = np.concatenate(vertices), np.concatenate(faces)
    # merge the vertices shared by two faces of the cube, so that it is one closed surface
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    mesh = trimesh.Trimesh(unique, inverse.reshape(-1)[faces], process=False)
    assert mesh.is_watertight and len(mesh.faces) == 12 * n * n
    return mesh


def grid_line_rays(n=8, seed=3):
    """Axis-aligned rays from inside the cube along its grid lines.

    For each axis direction (both signs): origins whose two other coordinates both lie on grid
    lines (the ray meets a vertex shared by up to 6 triangles), one on a grid line and the other
    random (it meets an edge), or on a quad's diagonal (the edge between its two triangles).
    Every such ray lies in planes of BVH boxes, where a plain slab test computes 0 * inf.
    """
    rng = np.random.default_rng(seed)
    grid = np.linspace(-1, 1, n + 1)[1:-1]
    origins, directions = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            a, b = (axis + 1) % 3, (axis + 2) % 3
            lateral = [(x, y) for x in grid for y in grid]
            lateral += [(x, rng.uniform(-1, 1)) for x in grid for _ in range(6)]
            lateral += [(rng.uniform(-1, 1), y) for y in grid for _ in range(6)]
            cells = rng.integers(0, n, (60, 2))
            f = rng.integers(1, 16, 60) / 16
            lateral += [(-1 + 2 * (i + g) / n, -1 + 2 * (j + g) / n)
                        for (i, j), g in zip(cells, f, strict=True)]
            for x, y in lateral:
                for depth in (-0.5, 0.0, 0.25, grid[1]):
                    o = np.zeros(3)
                    o[a], o[b], o[axis] = x, y, depth
                    d = np.zeros(3)
                    d[axis] = sign
                    origins.append(o)
                    directions.append(d)
    return np.array(origins), np.array(directions)


@pytest.mark.parametrize("instanced", [False, True], ids=["mesh", "instance"])
def test_axis_aligned_rays_along_grid_lines_do_not_leak(dtype, instanced):
    mesh = tessellated_box()
    scene = Scene(dtype=dtype)
    origins, directions = grid_line_rays()
    if instanced:
        proto = scene.add_mesh(mesh.vertices, mesh.faces, visible=False)
        shift = np.eye(4)
        shift[:3, 3] = [4.0, -2.0, 0.5]
        scene.add_instance(proto, shift)
        origins = origins + shift[:3, 3]
    else:
        scene.add_mesh(mesh.vertices, mesh.faces)
    axis = np.abs(directions).argmax(axis=1)
    along = directions[np.arange(len(directions)), axis]
    start = (origins - (shift[:3, 3] if instanced else 0))[np.arange(len(origins)), axis]
    distance = 1 - start * along  # to the face the ray leaves through, exactly
    rates = {}
    for test in TESTS:
        hits = scene.intersect(origins, directions, triangle_test=test)
        leaked = hits.geom_id < 0
        rates[test] = leaked.mean()
        if test == "watertight":
            assert not leaked.any(), f"{leaked.sum()} of {len(origins)} rays leak"
            # exact up to the rounding of t = T / det (the lateral coordinates are not dyadic)
            assert np.all(np.abs(hits.t - distance) <= 4 * np.finfo(dtype).eps * distance)
            assert np.all(scene.count(origins, directions) == 1)
            assert scene.occluded(origins, directions).all()
    print(f"\ntessellated box ({'instance' if instanced else 'mesh'}) {dtype}: {len(origins)} "
          "axis-aligned rays on grid lines; leak "
          + ", ".join(f"{test} {rate:.3%}" for test, rate in rates.items()))
