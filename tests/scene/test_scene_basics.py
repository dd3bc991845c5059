"""Scene odds and ends: empty scenes, no rays, changes after a query, result types, bounds."""

import pickle
import tracemalloc

import numba
import numpy as np
import pytest
from numba import types

from raycore import AllHits, Hits, Scene, TooManyHits, queries
from raycore.bvh.traverse import HIT_CAPACITY
from raycore.queries import LIST_ROOM

RAYS = (np.zeros((3, 3)), np.array([[0.0, 0, 1], [0, 1, 0], [1, 0, 0]]))


def test_an_empty_scene_misses_everything(dtype):
    scene = Scene(dtype=dtype)
    hits = scene.intersect(*RAYS, fields=("uv", "normal", "point"))
    assert isinstance(hits, Hits) and hits.t.dtype == np.dtype(dtype)
    assert np.all(hits.t == np.inf) and np.all(hits.geom_id == -1) and np.all(hits.prim_id == -1)
    assert np.isnan(hits.uv).all() and np.isnan(hits.normal).all() and np.isnan(hits.point).all()
    all_hits = scene.intersect_all(*RAYS)
    assert isinstance(all_hits, AllHits) and len(all_hits) == 0
    assert all_hits.counts.tolist() == [0, 0, 0]
    assert not scene.occluded(*RAYS).any() and not scene.contains(RAYS[0]).any()
    assert scene.stats()["objects"] == 0 and scene.triangle_count == 0
    # invisible prototypes alone show nothing either
    scene.add_mesh([[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 1, 2]], visible=False)
    assert np.all(scene.intersect(*RAYS).geom_id == -1)


def test_a_scene_without_shapes_hands_its_kernels_no_parameter_table(dtype):
    # so that Numba compiles the shapes' code away for it (raycore.primitives.analytic.table_hit)
    scene = Scene(dtype=dtype)
    scene.add_mesh([[0, 0, 2], [1, 0, 2], [0, 1, 2]], [[0, 1, 2]])
    origins = np.zeros((2, 3))
    directions = np.array([[0.1, 0.1, 1.0], [0.0, 0.0, -1.0]])
    meshes_only = scene.intersect(origins, directions, fields=("normal",))
    assert numba.typeof(scene._record).field_dict["params"] == types.none
    scene.add_sphere([0, 0, -3], 1.0)
    both = scene.intersect(origins, directions, fields=("normal",))
    assert isinstance(numba.typeof(scene._record).field_dict["params"], types.Array)
    assert meshes_only.geom_id.tolist() == [0, -1] and both.geom_id.tolist() == [0, 1]
    assert both.t[0] == meshes_only.t[0] == np.float32(2) and both.t[1] == pytest.approx(2)
    assert both.normal[1] == pytest.approx([0, 0, 1])


def test_scenes_whose_records_share_a_type_share_the_entry_points_found(dtype):
    # a query's first call about a record goes through Numba's dispatcher, which types every
    # argument; later calls, about that record or another of its type, call the entry found
    def triangle(z, with_sphere):
        scene = Scene(dtype=dtype)
        scene.add_mesh([[0, 0, z], [1, 0, z], [0, 1, z]], [[0, 1, 2]])
        if with_sphere:
            scene.add_sphere([0, 0, -3], 1.0)
        return scene.build()

    origins = np.zeros((2, 3))
    directions = np.array([[0.1, 0.1, 1.0], [0.0, 0.0, -1.0]])
    first = triangle(2, False)
    assert first.intersect(origins, directions).t.tolist() == [2.0, np.inf]
    same_type, other_type = triangle(4, False), triangle(4, True)
    assert same_type._record.entry_points is first._record.entry_points
    assert other_type._record.entry_points is not first._record.entry_points
    assert same_type.intersect(origins, directions).t.tolist() == [4.0, np.inf]
    hits = other_type.intersect(origins, directions)
    assert hits.geom_id.tolist() == [0, 1] and hits.t.tolist() == [4.0, pytest.approx(2.0)]


def test_no_rays_give_empty_results(dtype):
    scene = Scene(dtype=dtype)
    scene.add_sphere([0, 0, 0], 1.0)
    none = np.zeros((0, 3))
    hits = scene.intersect(none, none, fields=("uv", "normal", "point"))
    assert hits.t.shape == (0,) and hits.uv.shape == (0, 2) and hits.normal.shape == (0, 3)
    assert hits.point.shape == (0, 3)
    assert scene.intersect_all(none, none).counts.shape == (0,)
    assert scene.count(none, none).shape == (0,) and scene.occluded(none, none).shape == (0,)
    assert scene.contains(none).shape == (0,)


def test_changes_after_a_query_are_seen(dtype):
    scene = Scene(dtype=dtype)
    plane = scene.add_plane([0, 0, 5], [0, 0, 1])  # unbounded: no top-level tree yet
    assert scene.intersect(*RAYS).geom_id.tolist() == [plane, -1, -1]
    sphere = scene.add_sphere([0, 0, 2], 1.0)
    mesh = scene.add_mesh([[-1, 3, -1], [1, 3, -1], [0, 3, 1]], [[0, 1, 2]], visible=False)
    swap = np.eye(4)
    swap[:3, :3] = [[0, 1, 0], [1, 0, 0], [0, 0, 1]]  # swap x and y: the triangle lies at x = 3
    instance = scene.add_instance(mesh, swap)
    hits = scene.intersect(*RAYS)
    assert hits.geom_id.tolist() == [sphere, -1, instance]
    assert hits.t.tolist() == [1.0, np.inf, 3.0]
    assert scene.count(*RAYS).tolist() == [3, 0, 1]
    lo, hi = scene.bounds
    assert np.all(lo <= [-1, -1, -1]) and np.all(hi >= [3, 1, 3])
    assert len(scene) == 4


def test_ids_are_the_add_order_and_results_have_fixed_types(dtype):
    scene = Scene(dtype=dtype)
    ids = [scene.add_sphere([0, 0, 3], 1.0), scene.add_box([-1, -1, 6], [1, 1, 7]),
           scene.add_disk([0, 0, 9], [0, 0, 1], 1.0), scene.add_cylinder([0, 0, 11], [0, 0, 12], 1),
           scene.add_cone([0, 0, 14], [0, 0, 15], 1.0),
           scene.add_mesh([[-1, -1, 17], [1, -1, 17], [0, 1, 17]], [[0, 1, 2]]),
           scene.add_plane([0, 0, 20], [0, 0, 1])]
    assert ids == list(range(7))
    all_hits = scene.intersect_all([[0, 0, 0]], [[0, 0, 1]])
    # sphere, box, cylinder, cone: two crossings each; disk, mesh, plane: one
    assert all_hits.geom_id.tolist() == [0, 0, 1, 1, 2, 3, 3, 4, 4, 5, 6]
    assert all_hits.t.tolist() == [2, 4, 6, 7, 9, 11, 12, 14, 15, 17, 20]
    assert all_hits.prim_id.tolist()[-2] == 0 and all_hits.prim_id.dtype == np.int64
    assert all_hits.ray_index.dtype == np.int64 and all_hits.counts.dtype == np.int64
    assert all_hits.offsets.tolist() == [0, 11]
    hits = scene.intersect([[0, 0, 0]], [[0, 0, 1]], tmin=[4.5], tmax=[100.0])
    assert hits.geom_id.tolist() == [1] and hits.t.tolist() == [6.0]


def stacked_squares(dtype, layers):
    """A mesh of ``layers`` unit squares in the planes z = 0, 1, ..., each of two triangles."""
    z = np.repeat(np.arange(layers, dtype=float), 4)
    square = np.tile([[0.0, 0], [1, 0], [0, 1], [1, 1]], (layers, 1))
    vertices = np.column_stack([square, z])
    base = 4 * np.arange(layers)[:, None, None]
    faces = (base + np.array([[0, 1, 2], [1, 3, 2]])).reshape(-1, 3)
    scene = Scene(dtype)
    scene.add_mesh(vertices, faces)
    return scene


def test_a_ray_crossing_more_surfaces_than_a_thread_lists_at_first(dtype):
    # 100 parallel squares in one mesh: more crossings than HIT_CAPACITY, so that count and
    # intersect_all run again with room for them all
    layers = 100
    assert layers > HIT_CAPACITY
    scene = stacked_squares(dtype, layers)
    origins = [[0.3, 0.3, -1.0], [0.7, 0.1, 200.0], [5.0, 5.0, -1.0]]
    directions = [[0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0]]
    assert scene.count(origins, directions).tolist() == [layers, layers, 0]
    all_hits = scene.intersect_all(origins, directions)
    assert all_hits.counts.tolist() == [layers, layers, 0]
    # sorted by t, each within a few roundings of the exact distance
    close = dict(rel=4 * float(np.finfo(dtype).eps))
    assert all_hits.t[:layers].tolist() == pytest.approx(np.arange(1.0, layers + 1), **close)
    assert all_hits.t[layers:].tolist() == pytest.approx(np.arange(101.0, 201.0), **close)


def test_more_crossings_than_max_hits_are_refused_before_they_are_listed(dtype):
    layers, rays = 100, 20_000
    scene = stacked_squares(dtype, layers)
    origins, directions = np.tile([0.3, 0.3, -1.0], (rays, 1)), np.tile([0, 0, 1.0], (rays, 1))
    crossings = layers * rays
    assert len(scene.intersect_all(origins[:3], directions[:3], max_hits=3 * layers)) == \
        3 * layers
    with pytest.raises(TooManyHits, match=f"{crossings} times, more than max_hits"):
        scene.intersect_all(origins, directions, max_hits=crossings - 1)  # compiled, if not yet
    tracemalloc.start()
    try:
        with pytest.raises(TooManyHits) as refused:
            scene.intersect_all(origins, directions, max_hits=crossings - 1)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert (refused.value.crossings, refused.value.max_hits) == (crossings, crossings - 1)
    # as a Dask worker or a child process sends it back
    returned = pickle.loads(pickle.dumps(refused.value))
    assert (type(returned), str(returned)) == (TooManyHits, str(refused.value))
    assert (returned.crossings, returned.max_hits) == (crossings, crossings - 1)
    # the answer's arrays (t, geom_id, prim_id) would take this much: none of it was taken
    assert peak < crossings * (np.dtype(dtype).itemsize + 16) / 4, peak
    for bad in (-1, 1.5, True, "30"):
        with pytest.raises(ValueError, match="max_hits"):
            scene.intersect_all(origins, directions, max_hits=bad)


def test_rays_listing_more_crossings_than_their_batch_has_room_for(dtype, monkeypatch):
    # intersect_all lists LIST_ROOM crossings a ray in one pass, shared within a work item; a
    # ray through 20 squares takes the room of ten, so that in a large (grouped, parallel)
    # batch where one ray in six goes through, some work items overflow and their rays are
    # traced again into their places, beside rays listed in the pass.  The squares' tree is
    # small: grouped only with the size threshold lifted.
    monkeypatch.setattr(queries, "GROUP_TREE_BYTES", 0)
    layers = 20
    assert layers > 2 * LIST_ROOM
    scene = stacked_squares(dtype, layers)
    rng = np.random.default_rng(11)
    n = 80_000
    origins = np.column_stack([rng.uniform(-2.0, 1.5, n), rng.uniform(-0.5, 1.5, n),
                               np.full(n, -1.0)])
    directions = np.tile([0.0, 0.0, 1.0], (n, 1))
    directions[::2, :2] = rng.normal(scale=0.01, size=(n // 2, 2))
    all_hits = scene.intersect_all(origins, directions)
    through = all_hits.counts == layers
    assert set(np.unique(all_hits.counts)) <= set(range(layers + 1))
    assert 0.1 < through.mean() < 0.3 and (all_hits.counts == 0).mean() > 0.5
    np.testing.assert_array_equal(all_hits.counts, scene.count(origins, directions))
    # each crossing at its plane, in order, on its ray
    ray = all_hits.ray_index
    layer = np.round(origins[ray, 2] + all_hits.t * directions[ray, 2]).astype(int)
    starts = np.repeat(all_hits.offsets[:-1], all_hits.counts)
    first = np.round(origins[ray, 2] + all_hits.t[starts] * directions[ray, 2]).astype(int)
    np.testing.assert_array_equal(layer - first, np.arange(len(ray)) - starts)
    point = origins[ray] + all_hits.t[:, None] * directions[ray]
    assert np.all((point[:, :2] >= -1e-4) & (point[:, :2] <= 1 + 1e-4))
    # the same answers as rays asked a few at a time (listed without running out of room)
    pick = np.flatnonzero(through)[::997]
    for i in pick:
        alone = scene.intersect_all(origins[i:i + 1], directions[i:i + 1])
        np.testing.assert_array_equal(alone.t, all_hits.t[all_hits.ray_index == i])
        np.testing.assert_array_equal(alone.prim_id, all_hits.prim_id[all_hits.ray_index == i])


def test_a_ray_starting_on_a_surface_hits_it_at_plus_zero(dtype):
    # a plane's and a triangle's distance is a zero numerator over a signed denominator: -0
    # for rays heading into the surface, which JSON and print showed as a negative distance
    scene = Scene(dtype=dtype)
    scene.add_plane([0, 0, 0], [0, 1, 0])
    scene.add_mesh([[0, 1, 0], [1, 1, 0], [0, 1, 1]], [[0, 1, 2]])
    scene.add_disk([0, 3, 0], [0, 1, 0], 1.0)
    origins = np.array([[0.5, 0, 0.5], [0.25, 1, 0.25], [0.1, 3, 0.1]] * 2)
    directions = np.array([[0, 1, 0]] * 3 + [[0, -1, 0]] * 3)
    hits = scene.intersect(origins, directions)
    assert hits.hit.all() and (hits.t == 0).all()
    assert not np.signbit(hits.t).any()
    crossings = scene.intersect_all(origins, directions)
    assert (crossings.t == 0).sum() == 6
    assert not np.signbit(crossings.t).any()
