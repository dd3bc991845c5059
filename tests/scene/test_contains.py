"""Scene.contains: closed meshes against trimesh, closed analytic shapes against their equations."""

import numpy as np
import pytest
import trimesh

import raycore.scene
from raycore import Scene

from .brute import CLOSED_MESHES, mesh_scene, random_affine, shared_mesh, unit

#: The directions along which Scene.contains casts its rays, when it says so (grazing points
#: are built on them); otherwise the axes, a common choice.
DIRECTIONS = unit(np.asarray(getattr(raycore.scene, "_CONTAINS_DIRECTIONS", np.eye(3))))


def away_from_surface(mesh, points, margin):
    """(N,) bool: no triangle's bounding box comes within ``margin`` (per axis) of the point, so
    the point is farther than ``margin`` from the surface."""
    tree = mesh.triangles_tree
    return np.array([next(iter(tree.intersection(np.concatenate([p - margin, p + margin]))),
                          None) is None for p in points])


def grazing_points(mesh, rng, count):
    """Points from which one of the contains rays passes through a vertex or an edge's
    midpoint of the mesh (the rays graze or cross the surface exactly there)."""
    size = np.linalg.norm(mesh.extents)
    vertices = mesh.vertices[rng.integers(0, len(mesh.vertices), count)]
    edges = mesh.edges_unique[rng.integers(0, len(mesh.edges_unique), count)]
    midpoints = mesh.vertices[edges].mean(axis=1)
    targets = np.concatenate([vertices, midpoints])
    direction = DIRECTIONS[rng.integers(0, len(DIRECTIONS), len(targets))]
    return targets - direction * rng.uniform(0.02, 0.3, (len(targets), 1)) * size


@pytest.mark.parametrize("name", CLOSED_MESHES)
def test_contains_agrees_with_trimesh_on_closed_meshes(name, dtype):
    mesh = shared_mesh(name)
    scene = mesh_scene(name, dtype)
    rng = np.random.default_rng(3)
    lo, hi = mesh.bounds
    pad = 0.1 * (hi - lo)
    random = rng.uniform(lo - pad, hi + pad, (3000, 3))
    grazing = grazing_points(mesh, rng, 1500)
    margin = 1e-4 * np.linalg.norm(mesh.extents)
    for kind, points in (("random", random), ("grazing", grazing)):
        points = points[away_from_surface(mesh, points, margin)]
        expected = mesh.contains(points)
        got = scene.contains(points)
        assert got.dtype == bool and got.shape == (len(points),)
        # the data: many points on both sides
        assert len(points) > 1000 and 0.05 < expected.mean() < 0.95
        differ = np.flatnonzero(got != expected)
        print(f"\n{name} {dtype} {kind}: contains agrees with trimesh on "
              f"{1 - len(differ) / len(points):.4%} of {len(points)} points")
        assert len(differ) == 0, f"points {points[differ[:5]].tolist()} differ"


def test_contains_on_closed_analytic_shapes_and_instances(dtype):
    """Random points against the shapes' own equations; planes and disks enclose nothing."""
    rng = np.random.default_rng(4)
    scene = Scene(dtype=dtype)
    inside, distance = [], []  # per shape: functions of points

    def around(lo, hi):
        """Points near a shape: uniform in its bounding box grown by a fifth."""
        pad = 0.2 * (hi - lo)
        samples.append(rng.uniform(lo - pad, hi + pad, (300, 3)))

    samples = [rng.uniform(-6, 6, (2000, 3))]

    def sphere(c, r):
        scene.add_sphere(c, r)
        around(c - r, c + r)
        inside.append(lambda p: np.linalg.norm(p - c, axis=1) < r)
        distance.append(lambda p: np.abs(np.linalg.norm(p - c, axis=1) - r))

    def box_sdf(p, lo, hi):
        q = np.abs(p - (lo + hi) / 2) - (hi - lo) / 2
        return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)

    def box(lo, hi):
        scene.add_box(lo, hi)
        around(lo, hi)
        inside.append(lambda p: box_sdf(p, lo, hi) < 0)
        distance.append(lambda p: np.abs(box_sdf(p, lo, hi)))

    def tbox(lo, hi, m):
        scene.add_box(lo, hi, m)
        corners = np.array([[x, y, z, 1] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])]) @ m[:3].T
        around(corners.min(axis=0), corners.max(axis=0))
        inv = np.linalg.inv(m)
        # local distances shrink or grow by at most the extreme singular values
        s = np.linalg.svd(m[:3, :3], compute_uv=False)

        def local(p):
            return p @ inv[:3, :3].T + inv[:3, 3]

        inside.append(lambda p: box_sdf(local(p), lo, hi) < 0)
        distance.append(lambda p: np.abs(box_sdf(local(p), lo, hi)) * s.min())

    def axial(p, base, top):
        axis = top - base
        height = np.linalg.norm(axis)
        w = axis / height
        h = (p - base) @ w
        radial = np.linalg.norm(p - base - h[:, None] * w, axis=1)
        return h, radial, height

    def cylinder(p0, p1, r):
        scene.add_cylinder(p0, p1, r)
        around(np.minimum(p0, p1) - r, np.maximum(p0, p1) + r)
        inside.append(lambda p: (lambda h, q, H: (h > 0) & (h < H) & (q < r))(*axial(p, p0, p1)))
        distance.append(lambda p: (lambda h, q, H: np.minimum(np.minimum(np.abs(h), np.abs(H - h)),
                                                              np.abs(q - r)))(*axial(p, p0, p1)))

    def cone(base, apex, r):
        scene.add_cone(base, apex, r)
        around(np.minimum(base, apex) - r, np.maximum(base, apex) + r)

        def parts(p):
            h, q, height = axial(p, base, apex)
            edge = r * (1 - h / height)  # radius of the cone at height h
            slant = np.cos(np.arctan(r / height))  # distance to the side per unit of radius
            return h, q, height, edge, slant

        inside.append(lambda p: (lambda h, q, H, e, s: (h > 0) & (h < H) & (q < e))(*parts(p)))
        distance.append(lambda p: (lambda h, q, H, e, s: np.minimum(
            np.minimum(np.abs(h), np.abs(H - h)), np.abs(q - e) * s))(*parts(p)))

    def instance(proto_mesh, m):
        scene.add_instance(proto, m)
        placed = proto_mesh.copy().apply_transform(m)
        around(*placed.bounds)
        inside.append(lambda p: placed.contains(p))
        margin = 1e-3
        distance.append(lambda p: np.where(away_from_surface(placed, p, margin), 1.0, 0.0))

    for _ in range(3):
        sphere(rng.uniform(-4, 4, 3), rng.uniform(0.5, 2))
        lo = rng.uniform(-4, 4, 3)
        box(lo, lo + rng.uniform(0.5, 2.5, 3))
        tbox(-rng.uniform(0.3, 1, 3), rng.uniform(0.3, 1, 3), random_affine(rng, spread=4))
        p0 = rng.uniform(-4, 4, 3)
        cylinder(p0, p0 + rng.normal(size=3) * 1.5, rng.uniform(0.3, 1))
        b = rng.uniform(-4, 4, 3)
        cone(b, b + rng.normal(size=3) * 1.5, rng.uniform(0.3, 1))
    ico = trimesh.creation.icosphere(subdivisions=2)
    proto = scene.add_mesh(ico.vertices, ico.faces, visible=False)
    for _ in range(3):
        instance(ico, random_affine(rng, spread=4))
    # open surfaces: ignored by contains
    scene.add_plane([0, 0, 0], [0.2, 1, 0.1])
    scene.add_disk([0, 0, 0], [1, 0, 0], 3.0)

    points = np.concatenate(samples)
    near = np.min([f(points) for f in distance], axis=0) < 1e-3
    points = points[~near]
    inside_any = np.any([f(points) for f in inside], axis=0)
    inside_each = np.array([f(points) for f in inside])
    # the data: points in every shape, in overlaps of two, and outside everything
    assert np.all(inside_each.sum(axis=1) > 10)
    assert np.sum(inside_each.sum(axis=0) >= 2) > 10
    assert 0.1 < inside_any.mean() < 0.9
    got = scene.contains(points)
    differ = np.flatnonzero(got != inside_any)
    assert len(differ) == 0, f"{len(differ)} points differ, first {points[differ[:3]].tolist()}"


def test_contains_ignores_open_surfaces_and_empty_scenes(dtype):
    points = np.random.default_rng(0).uniform(-1, 1, (50, 3))
    assert not Scene(dtype=dtype).contains(points).any()
    scene = Scene(dtype=dtype)
    scene.add_plane([0, 0, 0], [0, 0, 1])
    scene.add_disk([0, 0, 0], [0.3, 0.1, 1], 5.0)
    assert not scene.contains(points).any()
    scene.add_sphere([0, 0, 0], 0.5)
    got = scene.contains(points)
    assert np.array_equal(got, np.linalg.norm(points, axis=1) < 0.5) and got.any()
    assert scene.contains(np.zeros((0, 3))).shape == (0,)
