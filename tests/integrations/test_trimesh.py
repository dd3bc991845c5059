"""raycore.integrations.trimesh.RayMeshIntersector against trimesh's own intersectors.

References are trimesh's NumPy intersector (``trimesh.ray.ray_triangle``, float64) and its
Embree one (``trimesh.ray.ray_pyembree``, embreex), never raycore.  Where those are known to be
wrong, the test names the trimesh issue and checks the right answer from geometry.
"""

import copy
import inspect
import pickle

import numpy as np
import pytest
import trimesh
from trimesh.ray import ray_pyembree, ray_triangle

from raycore.integrations.trimesh import RayMeshIntersector

from .conftest import edge_rays, load, random_rays

SMALL_MESHES = ("suzanne", "spot", "teapot", "fandisk")


def per_ray(index_tri, index_ray, count):
    """Each ray's sorted list of faces, as a tuple of tuples."""
    faces = [[] for _ in range(count)]
    for tri, ray in zip(index_tri.tolist(), index_ray.tolist(), strict=True):
        faces[ray].append(tri)
    return tuple(tuple(sorted(f)) for f in faces)


# ---------------------------------------------------------------------------- the interface


def undecorated(function):
    """``function`` without trimesh's ``log_time`` wrapper, which hides the signature (it sets
    no ``__wrapped__``): the wrapped method is the function in the wrapper's closure."""
    if function.__code__.co_name == "timed" and function.__closure__:
        return next(cell.cell_contents for cell in function.__closure__
                    if inspect.isfunction(cell.cell_contents))
    return function


def test_every_public_method_of_trimeshs_intersector_is_here_with_a_compatible_signature():
    theirs = ray_pyembree.RayMeshIntersector
    names = [name for name, member in inspect.getmembers(theirs, callable)
             if not name.startswith("_")] + ["__init__"]
    assert {"intersects_id", "intersects_location", "intersects_first", "intersects_any",
            "contains_points"} <= set(names)
    for name in names:
        ours = inspect.signature(getattr(RayMeshIntersector, name)).parameters
        for position, (param, spec) in enumerate(
                inspect.signature(undecorated(getattr(theirs, name))).parameters.items()):
            if param == "geometry":  # trimesh names it mesh in its other intersector
                param = "mesh"
            assert param in ours, f"{name} lacks {param}"
            assert list(ours).index(param) == position, f"{name}: {param} moved"
            assert ours[param].default == spec.default, f"{name}: default of {param}"


@pytest.mark.parametrize("name", SMALL_MESHES)
def test_first_hits_agree_with_embree_and_trimesh_on_random_rays(name):
    mesh = load(name)
    origins, directions = random_rays(mesh, 3000, seed=1)
    ours = RayMeshIntersector(mesh)
    first = ours.intersects_first(origins, directions)
    assert first.dtype == np.int64 and first.shape == (3000,)
    assert 0.3 < (first >= 0).mean() < 0.9  # the batch has both hits and misses
    embree = ray_pyembree.RayMeshIntersector(mesh).intersects_first(origins, directions)
    assert (first == embree).mean() >= 0.999
    numpy_first = ray_triangle.RayMeshIntersector(mesh).intersects_first(
        origins[:300], directions[:300])
    assert (first[:300] == numpy_first).mean() >= 0.99
    assert np.array_equal(ours.intersects_any(origins, directions), first >= 0)


@pytest.mark.parametrize("name", ["fandisk", "teapot"])
def test_every_hit_agrees_with_embree_in_its_order_and_with_trimeshs_locations(name):
    mesh = load(name)
    origins, directions = random_rays(mesh, 2000, seed=2)
    index_tri, index_ray, locations = RayMeshIntersector(mesh).intersects_id(
        origins, directions, multiple_hits=True, return_locations=True)
    assert (index_tri.dtype, index_ray.dtype, locations.dtype) == (np.int64, np.int64,
                                                                 np.float64)
    assert locations.shape == (len(index_tri), 3)
    assert np.bincount(index_ray).max() >= 4  # rays that cross the mesh several times
    e_tri, e_ray = ray_pyembree.RayMeshIntersector(mesh).intersects_id(
        origins, directions, multiple_hits=True)
    ours_per_ray, embree_per_ray = per_ray(index_tri, index_ray, 2000), per_ray(e_tri, e_ray,
                                                                                 2000)
    same = np.array([a == b for a, b in zip(ours_per_ray, embree_per_ray, strict=True)])
    assert same.mean() >= 0.995
    # on those rays, the same (face, ray) pairs in the same order: by depth, then by ray
    keep, e_keep = same[index_ray], same[e_ray]
    assert np.array_equal(index_tri[keep], e_tri[e_keep])
    assert np.array_equal(index_ray[keep], e_ray[e_keep])
    # trimesh's NumPy intersector: the same hit points (it reports each of them once per ray)
    n_tri, n_ray, n_loc = ray_triangle.RayMeshIntersector(mesh).intersects_id(
        origins[:200], directions[:200], multiple_hits=True, return_locations=True)
    mine = index_ray < 200
    assert np.array_equal(np.bincount(index_ray[mine], minlength=200),
                          np.bincount(n_ray, minlength=200))
    ours_sorted = np.lexsort((locations[mine, 2], locations[mine, 1], locations[mine, 0],
                              index_ray[mine]))
    theirs_sorted = np.lexsort((n_loc[:, 2], n_loc[:, 1], n_loc[:, 0], n_ray))
    assert np.allclose(locations[mine][ours_sorted], n_loc[theirs_sorted],
                       atol=1e-9 * mesh.scale)


def test_intersects_location_returns_trimeshs_tuple_order_and_max_hits_keeps_the_nearest():
    mesh = load("fandisk")
    origins, directions = random_rays(mesh, 500, seed=3)
    ours = RayMeshIntersector(mesh)
    locations, index_ray, index_tri = ours.intersects_location(origins, directions)
    tri, ray, loc = ours.intersects_id(origins, directions, return_locations=True)
    assert np.array_equal(index_tri, tri) and np.array_equal(index_ray, ray)
    assert np.array_equal(locations, loc)
    two_tri, two_ray = ours.intersects_id(origins, directions, max_hits=2)
    assert np.array_equal(two_tri, tri[:len(two_tri)])  # depth-major order: a prefix
    assert np.bincount(two_ray).max() == 2 < np.bincount(ray).max()
    first_tri, first_ray = ours.intersects_id(origins, directions, multiple_hits=False)
    assert np.array_equal(first_tri, tri[:len(first_tri)])
    assert np.array_equal(first_ray, np.flatnonzero(ours.intersects_first(origins, directions)
                                                    >= 0))


# ---------------------------------------------------------------------------- where trimesh errs


@pytest.mark.parametrize("at", ["edges", "vertices"])
def test_rays_at_shared_edges_and_vertices_never_slip_through(at):
    """trimesh #1766 and #1496: Embree lets rays through shared edges and vertices."""
    mesh = load("fandisk")  # closed: every point of its surface is on some face
    origins, directions = edge_rays(mesh, 3000, seed=4, at=at)
    assert len(origins) > 2900
    for dtype in ("float64", "float32"):
        ours = RayMeshIntersector(mesh, dtype=dtype)
        assert ours.intersects_any(origins, directions).all()
        assert (ours.intersects_first(origins, directions) >= 0).all()


def test_the_ray_of_trimesh_issue_1766_hits_the_seam_of_a_square():
    square = trimesh.Trimesh([[-1, -1, 0], [-1, 1, 0], [1, 1, 0], [1, -1, 0]],
                             [(0, 1, 2), (2, 3, 0)])
    locations, rays, faces = RayMeshIntersector(square).intersects_location(
        [[0, 0, 1]], [[0, 0, -1]], multiple_hits=False)
    assert locations.tolist() == [[0.0, 0.0, 0.0]] and rays.tolist() == [0]


def test_the_rays_of_trimesh_issue_1496_hit_once_through_vertices_and_edges():
    """trimesh #1496: rays from inside a subdivided box through its vertices and edges, which
    Embree let through; trimesh's NumPy intersector reports each crossing once per face."""
    small = trimesh.creation.box(extents=np.full(3, 40)).subdivide_to_size(20)
    big = trimesh.creation.box(extents=np.full(3, 60)).subdivide_to_size(20)
    origins, directions = np.zeros((len(big.vertices), 3)), big.vertices
    ours = RayMeshIntersector(small)
    assert ours.intersects_any(origins, directions).all()
    _, rays = ours.intersects_id(origins, directions)
    assert np.array_equal(rays, np.arange(len(origins)))  # one crossing each, once
    _, numpy_rays = ray_triangle.RayMeshIntersector(small).intersects_id(origins, directions)
    assert np.bincount(numpy_rays).min() >= 2


def test_a_crossing_through_a_shared_edge_is_reported_once():
    """trimesh #2317: trimesh's NumPy intersector reports an edge crossing once per face."""
    square = trimesh.Trimesh([[-1, -1, 0], [-1, 1, 0], [1, 1, 0], [1, -1, 0]],
                             [(0, 1, 2), (2, 3, 0)])
    origins, directions = [[0.25, 0.25, 1]], [[0, 0, -1]]  # through the diagonal
    numpy_tri, _ = ray_triangle.RayMeshIntersector(square).intersects_id(origins, directions)
    assert sorted(numpy_tri.tolist()) == [0, 1]  # the reference sees both faces
    tri, rays = RayMeshIntersector(square).intersects_id(origins, directions)
    assert rays.tolist() == [0] and tri[0] in (0, 1)


def test_no_duplicate_hits_on_a_large_mesh():
    """trimesh #2504 and #1097: at large scales Embree's restart offset vanishes in float32 and
    one crossing comes back up to max_hits times."""
    box = trimesh.creation.box(extents=[1e6, 1e6, 1e6])
    box.apply_translation([3e7, -2e7, 1e7])
    rng = np.random.default_rng(5)
    origins = box.centroid + [0, 0, 2e6] + rng.uniform(-4e5, 4e5, (200, 3)) * [1, 1, 0]
    directions = np.tile([0.0, 0.0, -1.0], (200, 1))
    tri, rays, locations = RayMeshIntersector(box).intersects_id(
        origins, directions, return_locations=True)
    assert np.array_equal(np.bincount(rays, minlength=200), np.full(200, 2))
    assert np.allclose(np.sort(locations[:, 2]).reshape(2, -1),
                       [[box.bounds[0, 2]], [box.bounds[1, 2]]], rtol=0, atol=1e-6)


def test_hit_points_far_from_the_origin_are_as_precise_as_trimeshs_float64():
    """trimesh #48 and #1919: Embree's float32 hit points lose digits far from the origin."""
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    sphere.apply_translation([1e6, -1e6, 5e5])
    origins, directions = random_rays(sphere, 300, seed=6)
    ours = RayMeshIntersector(sphere).intersects_location(origins, directions,
                                                          multiple_hits=False)
    numpy = ray_triangle.RayMeshIntersector(sphere).intersects_location(
        origins, directions, multiple_hits=False)
    by_ray = np.argsort(numpy[1])  # trimesh's NumPy intersector gives them in its own order
    assert len(ours[1]) > 100 and np.array_equal(ours[1], numpy[1][by_ray])
    assert np.abs(ours[0] - numpy[0][by_ray]).max() < 1e-8  # metres at a million metres


@pytest.mark.parametrize("name", ["spot", "fandisk"])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_rays_from_surface_points_do_not_hit_their_own_face(name, dtype):
    """trimesh #331: a ray from a sampled surface point along its normal re-hits the surface it
    starts on about half the time with Embree (always with trimesh's NumPy intersector)."""
    mesh = load(name)
    points, faces = trimesh.sample.sample_surface(mesh, 3000, seed=7)
    ours = RayMeshIntersector(mesh, dtype=dtype)
    for side in (1.0, -1.0):
        directions = side * mesh.face_normals[faces]
        assert not (ours.intersects_first(points, directions) == faces).any()
        tri, ray = ours.intersects_id(points, directions)
        assert not (tri == faces[ray]).any()


def test_contains_agrees_with_trimesh_and_answers_the_same_every_time():
    """trimesh #181 and #242: trimesh's contains re-casts disagreeing rays in random
    directions, and answers differently from call to call."""
    mesh = load("fandisk")
    rng = np.random.default_rng(8)
    lo, hi = mesh.bounds
    points = lo - 0.1 * (hi - lo) + rng.random((1500, 3)) * 1.2 * (hi - lo)
    ours = RayMeshIntersector(mesh)
    inside = ours.contains_points(points)
    assert inside.dtype == bool and 0.1 < inside.mean() < 0.9
    reference = ray_triangle.RayMeshIntersector(mesh).contains_points(points)
    assert (inside == reference).mean() >= 0.999
    assert all(np.array_equal(inside, ours.contains_points(points)) for _ in range(3))


# ---------------------------------------------------------------------------- as trimesh's object


def test_mesh_ray_in_trimesh_features():
    """With ``mesh.ray`` replaced, trimesh's own features give trimesh's answers."""
    mesh = load("fandisk")
    reference = mesh.copy()
    reference.ray = ray_triangle.RayMeshIntersector(reference)
    mesh = mesh.copy()
    mesh.ray = RayMeshIntersector(mesh)
    rng = np.random.default_rng(9)
    lo, hi = mesh.bounds
    points = lo + rng.random((400, 3)) * (hi - lo)
    assert (mesh.contains(points) == reference.contains(points)).mean() >= 0.995
    inside = points[reference.contains(points)][:50]
    directions = rng.normal(size=(len(inside), 3))
    assert np.allclose(trimesh.proximity.longest_ray(mesh, inside, directions),
                       trimesh.proximity.longest_ray(reference, inside, directions), rtol=1e-9)


def test_follows_the_mesh_when_it_changes():
    """trimesh #2324: Embree's intersector must follow ``apply_scale``; trimesh's cache keys
    tell this one when to rebuild."""
    mesh = trimesh.creation.box()
    ours = RayMeshIntersector(mesh)
    assert ours.intersects_location([[0, 0, 5]], [[0, 0, -1]], False)[0].tolist() == [
        [0, 0, 0.5]]
    mesh.apply_scale(1 / 64)
    mesh.apply_translation([0, 0, 1])
    expected = ray_triangle.RayMeshIntersector(mesh).intersects_location(
        [[0, 0, 5]], [[0, 0, -1]], multiple_hits=False)[0]
    assert np.allclose(ours.intersects_location([[0, 0, 5]], [[0, 0, -1]], False)[0], expected)
    assert np.allclose(expected, [[0, 0, 1 + 0.5 / 64]])


def test_copies_and_pickles_behave_as_trimeshs():
    mesh = load("suzanne")
    origins, directions = random_rays(mesh, 200, seed=10)
    ours, embree = RayMeshIntersector(mesh, dtype="float32"), ray_pyembree.RayMeshIntersector(
        mesh)
    before = ours.intersects_first(origins, directions)
    for make in (copy.copy, copy.deepcopy):
        # trimesh's copies share the mesh and rebuild their own scene
        assert (make(ours).mesh is mesh) == (make(embree).mesh is mesh)
        assert make(ours)._scene_options == {"dtype": "float32"}
    state = ours.__getstate__()
    assert "_cache" not in state and "_cache" not in embree.__getstate__()
    again = pickle.loads(pickle.dumps(ours))
    assert np.array_equal(again.intersects_first(origins, directions), before)
    assert again._scene.dtype == np.float32


def test_options_reach_raycore_and_bad_ones_are_refused():
    mesh = trimesh.creation.icosphere()
    for test in ("watertight", "moller", "geometric"):
        ours = RayMeshIntersector(mesh, triangle_test=test, dtype="float32")
        assert ours.intersects_any([[0, 0, 5]], [[0, 0, -1]]).tolist() == [True]
    with pytest.raises(ValueError, match="triangle_test"):
        RayMeshIntersector(mesh, triangle_test="fast")
    with pytest.raises(ValueError, match="dtype"):
        RayMeshIntersector(mesh, dtype="float16")
    with pytest.raises(ValueError, match="options"):
        RayMeshIntersector(mesh, colour="red")
    ours = RayMeshIntersector(mesh)
    with pytest.raises(ValueError, match="ray_origins"):
        ours.intersects_first([[np.nan, 0, 0]], [[0, 0, 1]])
    with pytest.raises(ValueError, match="ray_directions"):
        ours.intersects_any([[0, 0, 0]], [[0, 1]])
    with pytest.raises(ValueError, match="max_hits"):
        ours.intersects_id([[0, 0, 0]], [[0, 0, 1]], max_hits=-1)
    # were taken: True as 1 hit, and any object by its truth value (an array's is an error)
    with pytest.raises(ValueError, match="max_hits"):
        ours.intersects_id([[0, 0, 0]], [[0, 0, 1]], max_hits=True)
    for name in ("multiple_hits", "return_locations"):
        with pytest.raises(ValueError, match=f"{name} must be True or False"):
            ours.intersects_id([[0, 0, 0]], [[0, 0, 1]], **{name: np.array([True, False])})
    with pytest.raises(ValueError, match="scale_to_box must be True or False"):
        RayMeshIntersector(mesh, scale_to_box="no")
    # a zero direction hits nothing, as in trimesh
    assert ours.intersects_first([[0, 0, 5], [0, 0, 5]], [[0, 0, 0], [0, 0, -1]])[0] == -1
    tri, ray = ours.intersects_id(np.zeros((0, 3)), np.zeros((0, 3)))
    assert tri.shape == ray.shape == (0,) and tri.dtype == ray.dtype == np.int64
