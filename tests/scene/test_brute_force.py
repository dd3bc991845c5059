"""Every query through the BVH equals brute force, on a seeded scene of every kind of object."""

import numpy as np
import pytest

from raycore import Scene

from .brute import (
    METHODS,
    SceneSpec,
    compare_all,
    compare_closest,
    random_affine,
    random_scene,
    reference,
    scene_rays,
)

SEED = 0

#: At most this fraction of rays may be excused as passing within rounding distance of an
#: instance's edge (where object-space and world-space tests may disagree).
MAX_EXCUSED = 0.01


def scene_for(dtype, **build):
    spec, _ = random_scene(SEED)
    return spec, spec.scene(dtype, **build)


def test_the_data_covers_the_hard_cases():
    """Warp-style: the rays must actually exercise misses, multiple hits, edges and vertices,
    every object, every kind of closest hit, and the per-ray limits."""
    spec, _ = random_scene(SEED)
    origins, directions, tmin, tmax, aimed = scene_rays(SEED)
    ref = reference(SEED, "float64", "watertight", "precise")
    first, _ = ref.closest()
    missed = first < 0
    assert 0.05 < missed.mean() < 0.6
    _, counts = ref.merged()
    assert (counts >= 3).mean() > 0.05 and counts.max() >= 6
    # every visible object is hit by some ray, and every kind is the closest hit of some ray
    visible = [i for i, o in enumerate(spec.objects) if o.visible]
    assert set(np.unique(ref.geom)) == set(visible)
    kinds = {spec.objects[g].kind for g in ref.geom[first[~missed]]}
    assert kinds == {"sphere", "plane", "disk", "box", "tbox", "cylinder", "cone", "mesh",
                     "instance"}
    # aimed rays reach edges and vertices: several hits of one mesh at one t (before merging)
    same_point = ((ref.ray[1:] == ref.ray[:-1]) & (ref.geom[1:] == ref.geom[:-1])
                  & (ref.t[1:] - ref.t[:-1] <= 1e-12 * ref.t[1:]) & (ref.key[1:, 0] >= 0))
    edge_rays = np.unique(ref.ray[1:][same_point])
    assert aimed[edge_rays].all() and len(edge_rays) > 100
    triples = same_point[1:] & same_point[:-1]
    assert triples.sum() > 10, "some aimed rays must pass through vertices shared by 3+ faces"
    # hits exactly at the target (t = 1) of an aimed ray: through an edge or a vertex
    assert np.mean(np.isin(np.flatnonzero(aimed), ref.ray[ref.t == 1.0])) > 0.5
    # the per-ray limits cut some hits: compare with unlimited rays
    limited = np.flatnonzero((tmin > 0) | (tmax < np.inf))
    assert len(limited) > 200
    free = spec.reference(origins[limited], directions[limited], dtype="float64")
    assert np.sum(free.counts > ref.counts[limited]) > 50


@pytest.mark.parametrize("test, method", METHODS)
def test_intersect_matches_brute_force(dtype, test, method):
    spec, scene = scene_for(dtype)
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    ref = reference(SEED, dtype, test, method)
    fields = ("uv", "normal", "point")
    hits = scene.intersect(origins, directions, tmin, tmax, triangle_test=test,
                           sphere_method=method, fields=fields)
    assert hits.t.dtype == np.dtype(dtype) and hits.uv.dtype == np.dtype(dtype)
    excused = compare_closest(hits, ref, spec, fields=fields)
    assert excused <= MAX_EXCUSED * len(origins)
    # scalar limits (the defaults) give the same answers as the equivalent arrays
    free = np.flatnonzero((tmin == 0) & (tmax == np.inf))
    plain = scene.intersect(origins[free], directions[free], triangle_test=test,
                            sphere_method=method)
    assert np.array_equal(plain.t, hits.t[free])
    assert np.array_equal(plain.geom_id, hits.geom_id[free])
    assert np.array_equal(plain.prim_id, hits.prim_id[free])
    assert plain.uv is None and plain.normal is None and plain.point is None


@pytest.mark.parametrize("test, method", METHODS)
def test_occluded_matches_brute_force(dtype, test, method):
    spec, scene = scene_for(dtype)
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    ref = reference(SEED, dtype, test, method)
    occluded = scene.occluded(origins, directions, tmin, tmax, triangle_test=test,
                              sphere_method=method)
    assert occluded.dtype == bool and occluded.shape == (len(origins),)
    expected = ref.counts > 0
    bad = np.flatnonzero(occluded != expected)
    excused = spec.near_instance_edge(origins[bad], directions[bad], tmin[bad], tmax[bad], dtype)
    assert excused.all(), f"occluded differs from brute force on rays {bad[~excused][:10]}"
    assert len(bad) <= MAX_EXCUSED * len(origins)
    assert 0.1 < expected.mean() < 0.95


@pytest.mark.parametrize("test, method", METHODS)
def test_intersect_all_and_count_match_brute_force(dtype, test, method):
    spec, scene = scene_for(dtype)
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    ref = reference(SEED, dtype, test, method)
    all_hits = scene.intersect_all(origins, directions, tmin, tmax, triangle_test=test,
                                   sphere_method=method)
    assert all_hits.t.dtype == np.dtype(dtype)
    excused = compare_all(all_hits, ref, spec)
    assert excused <= MAX_EXCUSED * len(origins)
    counts = scene.count(origins, directions, tmin, tmax, triangle_test=test,
                         sphere_method=method)
    assert np.array_equal(counts, all_hits.counts)
    # the closest hit is the first of all hits (to a tie: a ray through a vertex gets t a few
    # ulps apart from the triangles around it, and a box may be culled against a tied t)
    hits = scene.intersect(origins, directions, tmin, tmax, triangle_test=test,
                           sphere_method=method)
    some = all_hits.counts > 0
    assert np.array_equal(some, hits.geom_id >= 0)
    first = all_hits.t[all_hits.offsets[:-1][some]].astype(np.float64)
    assert np.all(np.abs(first - hits.t[some]) <= 8 * np.finfo(dtype).eps * np.abs(first))


# ---------------------------------------------------------------------- shared edges and vertices


def _fan(center, count, radius=1.0, z=0.0):
    """A flat fan of ``count`` triangles around ``center`` (the shared vertex), at height z."""
    angles = np.arange(count) * 2 * np.pi / count
    rim = np.stack([np.cos(angles), np.sin(angles), np.zeros(count)], axis=1) * radius
    vertices = np.vstack([[0.0, 0.0, 0.0], rim]) + [center[0], center[1], z]
    faces = np.array([[0, 1 + i, 1 + (i + 1) % count] for i in range(count)])
    return vertices, faces


@pytest.mark.parametrize("test", ["watertight", "moller", "geometric"])
def test_a_ray_through_a_shared_edge_or_vertex_counts_the_surface_once(dtype, test):
    scene = Scene(dtype=dtype)
    # two triangles sharing the edge (1,0,0)-(0,1,0); the ray crosses its midpoint exactly
    quad = scene.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]])
    # a vertex shared by 6 triangles, at (5, 0, 0)
    fan = scene.add_mesh(*_fan([5.0, 0.0], 6))
    origins = [[0.5, 0.5, -1.0], [5.0, 0.0, -1.0], [0.5, 0.5, 1.0], [5.0, 0.0, 2.0]]
    directions = [[0, 0, 1], [0, 0, 1], [0, 0, -0.5], [0, 0, -1]]
    all_hits = scene.intersect_all(origins, directions, triangle_test=test)
    assert all_hits.counts.tolist() == [1, 1, 1, 1]
    assert all_hits.geom_id.tolist() == [quad, fan, quad, fan]
    close = pytest.approx([1.0, 1.0, 2.0, 2.0], rel=4 * float(np.finfo(dtype).eps))
    assert all_hits.t.tolist() == close
    assert scene.count(origins, directions, triangle_test=test).tolist() == [1, 1, 1, 1]
    hits = scene.intersect(origins, directions, triangle_test=test, fields=("uv",))
    assert hits.t.tolist() == close
    assert hits.geom_id.tolist() == [quad, fan, quad, fan]
    assert set(hits.prim_id[[0, 2]]) <= {0, 1} and set(hits.prim_id[[1, 3]]) <= set(range(6))


@pytest.mark.parametrize("test", ["watertight", "moller", "geometric"])
def test_separate_surfaces_through_one_point_count_separately(dtype, test):
    scene = Scene(dtype=dtype)
    # two meshes whose fans share the point (0, 0, 0) (equal coordinates, separate meshes)
    scene.add_mesh(*_fan([0.0, 0.0], 6))
    scene.add_mesh(*_fan([0.0, 0.0], 5, radius=2.0))
    # one mesh holding two sheets that cross the same point but share no vertex
    v1, f1 = _fan([10.0, 0.0], 4)
    sheet = np.array([[9.0, -1.0, -1.0], [11.0, -1.0, 1.0], [10.0, 1.0, 0.0]])
    one = scene.add_mesh(np.vstack([v1[1:], sheet]), np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]]))
    # two instances of one mesh at the same place are two objects
    proto = scene.add_mesh(*_fan([0.0, 0.0], 6), visible=False)
    shift = np.eye(4)
    shift[:3, 3] = [20.0, 0.0, 0.0]
    scene.add_instance(proto, shift)
    scene.add_instance(proto, shift)
    origins = [[0.0, 0.0, -1.0], [10.0, 0.0, -1.0], [20.0, 0.0, -1.0]]
    directions = [[0, 0, 1]] * 3
    all_hits = scene.intersect_all(origins, directions, triangle_test=test)
    assert all_hits.counts.tolist() == [2, 2, 2]
    assert all_hits.t.tolist() == pytest.approx([1.0] * 6, rel=4 * float(np.finfo(dtype).eps))
    assert all_hits.geom_id[2:4].tolist() == [one, one]
    assert sorted(all_hits.geom_id[:2]) == [0, 1]
    assert sorted(all_hits.geom_id[4:]) == [4, 5]


# ---------------------------------------------------------------------- build parameters

BUILDS = [
    dict(bins=2, max_leaf_size=1),
    dict(bins=64, max_leaf_size=16, traversal_cost=3.0, intersection_cost=0.5),
    dict(bins=7, max_leaf_size=255, traversal_cost=0.1, intersection_cost=4.0),
]


@pytest.mark.parametrize("build", BUILDS, ids=lambda b: "-".join(f"{k}{v}" for k, v in
                                                                   b.items()))
def test_build_parameters_change_the_tree_not_the_answers(dtype, build):
    spec, scene = scene_for(dtype, **build)
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    ref = reference(SEED, dtype, "watertight", "precise")
    compare_closest(scene.intersect(origins, directions, tmin, tmax), ref, spec)
    compare_all(scene.intersect_all(origins, directions, tmin, tmax), ref, spec)
    occluded = scene.occluded(origins, directions, tmin, tmax)
    bad = np.flatnonzero(occluded != (ref.counts > 0))
    assert spec.near_instance_edge(origins[bad], directions[bad], tmin[bad], tmax[bad],
                                   dtype).all()
    # the trees differ from the default build's, and say so
    stats = scene.stats()
    default = scene_for(dtype)[1].stats()
    assert stats["meshes"] != default["meshes"]
    for tree, triangles in [(stats["top"], None)] + [(m, m["triangles"]) for m in
                                                       stats["meshes"]]:
        assert {"sah_cost", "depth", "nodes", "leaves"} <= set(tree)
        assert np.isfinite(tree["sah_cost"]) and tree["sah_cost"] > 0
        assert tree["nodes"] == 2 * tree["leaves"] - 1
        assert 0 <= tree["depth"] < tree["nodes"]
        if triangles is not None:
            assert tree["leaves"] >= -(-triangles // build["max_leaf_size"])
            if build["max_leaf_size"] == 1:
                assert tree["leaves"] == triangles


def test_stats_report_tree_quality():
    spec, scene = scene_for("float32")
    stats = scene.stats()
    meshes = [o for o in spec.objects if o.kind == "mesh"]
    assert stats["objects"] == len(spec.objects)
    assert [m["triangles"] for m in stats["meshes"]] == [len(o.faces) for o in meshes]
    for tree in [stats["top"], *stats["meshes"]]:
        assert tree["sah_cost"] > 0 and tree["depth"] >= 1 and tree["bytes"] > 0
        assert tree["nodes"] == 2 * tree["leaves"] - 1
    # scaling both costs keeps every split decision, so the tree, and scales its cost (the
    # costs are the meshes' trees'; the top level over objects keeps the default ones)
    costs = scene.build_params
    double = spec.scene("float32", traversal_cost=2 * costs.traversal_cost,
                        intersection_cost=2 * costs.intersection_cost).stats()
    assert double["top"] == stats["top"]
    for tree, twice in zip(stats["meshes"], double["meshes"], strict=True):
        assert (twice["nodes"], twice["leaves"], twice["depth"]) == (
            tree["nodes"], tree["leaves"], tree["depth"])
        assert twice["sah_cost"] == pytest.approx(2 * tree["sah_cost"], rel=1e-12)


def test_the_comparisons_catch_wrong_answers():
    """The checks above can fail: small corruptions of correct answers are all caught."""
    from dataclasses import replace

    spec, scene = scene_for("float32")
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    ref = reference(SEED, "float32", "watertight", "precise")
    hits = scene.intersect(origins, directions, tmin, tmax)
    all_hits = scene.intersect_all(origins, directions, tmin, tmax)
    compare_closest(hits, ref, spec)
    compare_all(all_hits, ref, spec)
    # a ray whose hits are all on meshes and analytic shapes (no instance), clearly separated
    first, _ = ref.closest()
    no_instance = np.bincount(ref.ray[ref.instance], minlength=ref.n) == 0
    r = np.flatnonzero(no_instance & (first >= 0) & ~ref.ties() & (ref.counts >= 2))[0]

    def corrupt(array, value):
        array = array.copy()
        array[r] = value
        return array

    wrong = [
        replace(hits, t=corrupt(hits.t, np.inf), geom_id=corrupt(hits.geom_id, -1),
                prim_id=corrupt(hits.prim_id, -1)),  # a hit lost
        replace(hits, t=corrupt(hits.t, hits.t[r] * (1 + 1e-5))),  # t off by 1e-5
        replace(hits, prim_id=corrupt(hits.prim_id, hits.prim_id[r] + 1)),  # another primitive
        replace(hits, geom_id=corrupt(hits.geom_id, (hits.geom_id[r] + 1) % len(spec.objects))),
    ]
    for bad in wrong:
        with pytest.raises(AssertionError):
            compare_closest(bad, ref, spec)
    offsets = all_hits.offsets
    keep = np.ones(len(all_hits.t), bool)
    keep[offsets[r]] = False  # a crossing lost
    counts = all_hits.counts.copy()
    counts[r] -= 1
    lost = replace(all_hits, ray_index=all_hits.ray_index[keep], t=all_hits.t[keep],
                   geom_id=all_hits.geom_id[keep], prim_id=all_hits.prim_id[keep], counts=counts)
    shifted = replace(all_hits, t=all_hits.t.copy())
    shifted.t[offsets[r] + 1] *= 1 + 1e-5
    for bad in (lost, shifted):
        with pytest.raises(AssertionError):
            compare_all(bad, ref, spec)


def test_near_instance_edge_finds_rays_through_instance_edges():
    spec = SceneSpec()
    proto = spec.mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], visible=False)
    spec.instance(proto, random_affine(np.random.default_rng(0)))
    corners = spec.world_vertices(1)
    targets = np.array([corners[0], (corners[0] + corners[1]) / 2, corners.mean(axis=0),
                        corners.mean(axis=0) + 10 * (corners[2] - corners.mean(axis=0))])
    origins = targets + [0.0, 0.0, -50.0]
    near = spec.near_instance_edge(origins, targets - origins, 0.0, np.inf, "float32")
    assert near.tolist() == [True, True, False, False]
    # ... and rays whose hit sits at their tmax
    assert spec.near_instance_edge(origins[2:3], (targets - origins)[2:3], 0.0, 1.0,
                                   "float32").tolist() == [True]


@pytest.mark.parametrize("seed", [1, 2])
def test_other_random_scenes_match_brute_force(dtype, seed):
    spec, _ = random_scene(seed)
    scene = spec.scene(dtype)
    origins, directions, tmin, tmax, _ = scene_rays(seed)
    ref = reference(seed, dtype, "watertight", "precise")
    assert 0.05 < (ref.counts == 0).mean() < 0.6 and (ref.merged()[1] >= 3).mean() > 0.05
    excused = compare_closest(scene.intersect(origins, directions, tmin, tmax,
                                              fields=("uv", "normal", "point")), ref, spec,
                              fields=("uv", "normal", "point"))
    excused += compare_all(scene.intersect_all(origins, directions, tmin, tmax), ref, spec)
    assert excused <= 2 * MAX_EXCUSED * len(origins)
