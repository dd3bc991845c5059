"""Large incoherent batches are traced in a coherent order (raycore.ray_order), and every ray
still gets the answer it gets alone.

The brute-force scene's rays (every kind of object, per-ray limits, rays through shared edges
and vertices), repeated and shuffled into a batch large enough to be grouped, must get, ray for
ray, the answers of the original 2400-ray batch, which test_brute_force checks against brute
force.
"""

import numpy as np
import pytest

from raycore import queries
from raycore.ray_order import MAX_BITS, group_order
from raycore.sensors import perspective

from .brute import random_scene, scene_rays

SEED = 0


def _grouped_batches(monkeypatch, tree_bytes=0):
    """The sizes of the batches that are grouped, as they are, with scenes' trees grouped from
    ``tree_bytes`` on (the test scenes' trees are small)."""
    sizes = []
    grouping = queries.grouping

    def counted(scene, rays, threads, mode):
        grouped = grouping(scene, rays, threads, mode)
        if grouped is not None:
            sizes.append(len(grouped[0]))
        return grouped

    monkeypatch.setattr(queries, "grouping", counted)
    monkeypatch.setattr(queries, "GROUP_TREE_BYTES", tree_bytes)
    return sizes


def _large_shuffled(dtype):
    """The scene rays repeated past GROUP_FROM, in a random order: (index into the originals,
    origins, directions, tmin, tmax)."""
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    repeats = -(-queries.GROUP_FROM // len(origins)) + 1
    source = np.random.default_rng(7).permutation(np.tile(np.arange(len(origins)), repeats))
    return (source, *(np.ascontiguousarray(a[source], dtype)
                      for a in (origins, directions, tmin, tmax)))


def test_every_query_answers_each_ray_as_in_a_small_batch(dtype, monkeypatch):
    spec, _ = random_scene(SEED)
    scene = spec.scene(dtype)
    origins, directions, tmin, tmax, _ = scene_rays(SEED)
    small = [a.astype(dtype) for a in (origins, directions, tmin, tmax)]
    source, *large = _large_shuffled(dtype)
    grouped = _grouped_batches(monkeypatch)
    fields = ("uv", "normal", "point")
    alone = scene.intersect(*small, fields=fields)
    hits = scene.intersect(*large, fields=fields)
    for name in ("t", "geom_id", "prim_id", *fields):
        assert np.array_equal(getattr(hits, name), getattr(alone, name)[source],
                              equal_nan=True), name
    assert np.array_equal(scene.occluded(*large), scene.occluded(*small)[source])
    assert np.array_equal(scene.count(*large), scene.count(*small)[source])
    every, every_alone = scene.intersect_all(*large), scene.intersect_all(*small)
    assert np.array_equal(every.counts, every_alone.counts[source])
    starts = every_alone.offsets[source]
    for name in ("t", "geom_id", "prim_id"):
        expected = np.concatenate([getattr(every_alone, name)[start:start + count]
                                   for start, count in zip(starts, every.counts, strict=True)])
        assert np.array_equal(getattr(every, name), expected), name
    # intersect, occluded, count, and intersect_all once for its two passes
    assert grouped == [len(source)] * 4
    # scalar bounds are shared by every ray and stay so
    plain = scene.intersect(large[0], large[1])
    assert np.array_equal(plain.t, scene.intersect(small[0], small[1]).t[source])
    assert len(grouped) == 5


def test_contains_is_unchanged_by_grouping(monkeypatch):
    spec, _ = random_scene(SEED)
    scene = spec.scene("float64")
    points = np.random.default_rng(3).uniform(-9, 9, (queries.GROUP_FROM, 3))
    # on any tree, however small
    grouped = _grouped_batches(monkeypatch, queries.GROUP_TREE_BYTES)
    inside = scene.contains(points)
    assert grouped, "contains' rays from scattered points must be grouped"
    pieces = np.concatenate([scene.contains(part) for part in np.array_split(points, 200)])
    assert np.array_equal(inside, pieces) and 0.01 < inside.mean() < 0.99


def test_a_small_tree_keeps_the_batch_order(monkeypatch):
    spec, _ = random_scene(SEED)
    scene = spec.scene("float32")
    _, *large = _large_shuffled("float32")
    grouped = _grouped_batches(monkeypatch, queries.GROUP_TREE_BYTES)
    scene.intersect(*large)
    assert scene._record.tree_bytes < queries.GROUP_TREE_BYTES
    assert grouped == []
    monkeypatch.setattr(queries, "GROUP_TREE_BYTES", scene._record.tree_bytes)
    scene.intersect(*large)
    assert grouped == [len(large[0])]


def test_a_camera_keeps_its_order(monkeypatch):
    spec, _ = random_scene(SEED)
    scene = spec.scene("float32")
    camera = perspective([0, -30, 5], [0, 0, 0], up=[0, 0, 1], fov=50.0, width=320,
                         height=240, dtype="float32")
    grouped = _grouped_batches(monkeypatch)
    assert scene.intersect(camera.origins, camera.directions).hit.mean() > 0.1
    assert grouped == []


def _octant(directions):
    return (directions >= 0) @ np.array([1, 2, 4])


def test_the_order_is_a_permutation_grouped_by_octant_and_stable_within_a_group():
    rng = np.random.default_rng(5)
    count = 200_000
    origins = rng.uniform(-1, 1, (count, 3))
    directions = rng.normal(size=(count, 3))
    order = np.empty(count, np.int64)
    keys = np.empty(count, np.int16)
    assert group_order(origins, directions, 4, order, keys)
    assert np.array_equal(np.sort(order), np.arange(count))
    # octants first, in order; within an octant, origin cells; within a cell, the batch's order
    octants = _octant(directions[order])
    assert np.all(np.diff(octants) >= 0)
    group = keys[order].astype(np.int64)
    assert np.all(np.diff(group) >= 0)
    assert np.array_equal(group >> 3 * MAX_BITS, octants)
    same = group[1:] == group[:-1]
    assert np.all(order[1:][same] > order[:-1][same])
    # a group holds rays whose origins lie in one cell of the grid: a small part of the bounds
    for g in np.unique(group)[::97]:
        members = origins[order[group == g]]
        assert np.all(np.ptp(members, axis=0) <= 2.0 / 2**MAX_BITS * 1.25)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_origins_still_give_a_permutation(bad):
    rng = np.random.default_rng(6)
    count = 100_000
    origins = rng.uniform(-1, 1, (count, 3))
    origins[::1000, 1] = bad
    directions = rng.normal(size=(count, 3))
    order = np.empty(count, np.int64)
    group_order(origins, directions, 4, order, np.empty(count, np.int16))
    assert np.array_equal(np.sort(order), np.arange(count))


def test_a_refused_ray_in_a_grouped_batch_is_named(dtype, monkeypatch):
    spec, _ = random_scene(SEED)
    scene = spec.scene(dtype)
    _, origins, directions, tmin, tmax = _large_shuffled(dtype)
    directions[12345] = 0
    grouped = _grouped_batches(monkeypatch)
    with pytest.raises(ValueError, match="directions"):
        scene.intersect(origins, directions, tmin, tmax)
    assert grouped
