"""raycore.dask on a real distributed.LocalCluster of two worker processes: the Scene's
answers, chunk by chunk, with the scene in the graph once."""

import dask
import dask.array as da
import numpy as np
import pytest
from distributed import Client, LocalCluster, get_task_stream

import raycore.dask
from raycore import Scene, TooManyHits

from .conftest import load, random_rays


@pytest.fixture(scope="module")
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        yield client


@pytest.fixture(scope="module", params=["float32", "float64"])
def scene_and_rays(request):
    mesh = load("stanford-bunny")
    scene = Scene(request.param)
    bunny = scene.add_mesh(mesh.vertices, mesh.faces)
    moved = np.eye(4)
    moved[:3, 3] = [0.05, 0.0, 0.02]
    scene.add_instance(bunny, moved)
    scene.add_sphere(mesh.centroid, 0.03)
    origins, directions = random_rays(mesh, 6000, seed=4)
    tmax = np.random.default_rng(5).uniform(0.3, 1.2, len(origins))
    return scene, origins, directions, tmax


def chunked(array):
    return da.from_array(array, chunks=(1700,) + array.shape[1:])  # 4 chunks, the last shorter


def test_answers_equal_the_scenes(client, scene_and_rays):
    scene, origins, directions, tmax = scene_and_rays
    o, d = chunked(origins), chunked(directions)
    hits = raycore.dask.intersect(scene, o, d, fields=("uv", "normal", "point"))
    shadowed = raycore.dask.occluded(scene, o, d, 0.0, chunked(tmax))
    counts = raycore.dask.count(scene, o, d)
    every = raycore.dask.intersect_all(scene, o, d, tmax=chunked(tmax))
    got = dask.compute(hits, shadowed, counts, every, scheduler=client.get)

    expected = scene.intersect(origins, directions, fields=("uv", "normal", "point"))
    assert {-1, 0, 1, 2} <= set(expected.geom_id.tolist())  # misses, mesh, instance, sphere
    for name in ("t", "geom_id", "prim_id", "uv", "normal", "point"):
        assert got[0][name].dtype == getattr(expected, name).dtype
        np.testing.assert_array_equal(got[0][name], getattr(expected, name), err_msg=name)
    occluded = scene.occluded(origins, directions, 0.0, tmax)
    assert 0 < occluded.sum() < len(occluded)
    np.testing.assert_array_equal(got[1], occluded)
    np.testing.assert_array_equal(got[2], scene.count(origins, directions))
    all_hits = scene.intersect_all(origins, directions, tmax=tmax)
    assert all_hits.counts.max() >= 2
    for name in ("ray_index", "t", "geom_id", "prim_id", "counts"):
        np.testing.assert_array_equal(got[3][name], getattr(all_hits, name), err_msg=name)


def scene_keys(collection):
    """Keys of the collection's graph that hold a Scene object."""
    return [key for key, value in dict(collection.__dask_graph__()).items()
            if isinstance(getattr(value, "value", value), Scene)]


def test_the_scene_is_in_the_graph_once_and_goes_to_each_worker_once(client, scene_and_rays):
    scene, origins, directions, _ = scene_and_rays
    hits = raycore.dask.intersect(scene, chunked(origins), chunked(directions))
    assert hits["t"].npartitions == 4
    [key] = scene_keys(hits["t"])
    with get_task_stream(client) as stream:
        t = hits["t"].compute()
    np.testing.assert_array_equal(t, scene.intersect(origins, directions).t)
    # the chunks ran on both workers; the scene's task on one, fetched once by the other
    assert len({task["worker"] for task in stream.data}) == 2
    assert [task["key"] for task in stream.data].count(key) == 1
    fetched = client.run(lambda dask_worker: [
        keys for entry in dask_worker.transfer_incoming_log for keys in entry["keys"]])
    assert sorted(keys.count(key) for keys in fetched.values()) == [0, 1]


def test_bad_rays_name_the_argument(scene_and_rays):
    scene, origins, directions, _ = scene_and_rays
    with pytest.raises(ValueError, match="origins"):
        raycore.dask.intersect(scene, chunked(origins[:, :2]), chunked(directions))
    with pytest.raises(ValueError, match="tmax"):
        raycore.dask.count(scene, chunked(origins), chunked(directions), tmax=np.ones(3))
    with pytest.raises(ValueError, match="fields"):
        raycore.dask.intersect(scene, chunked(origins), chunked(directions), fields=("colour",))


def test_max_hits_bounds_each_chunk_and_its_error_reaches_the_client(client, scene_and_rays):
    scene, origins, directions, tmax = scene_and_rays
    o, d = chunked(origins), chunked(directions)
    counts = scene.count(origins, directions, tmax=tmax)
    per_chunk = [int(counts[i:i + 1700].sum()) for i in range(0, len(counts), 1700)]
    enough = raycore.dask.intersect_all(scene, o, d, tmax=chunked(tmax), max_hits=max(per_chunk))
    got = dask.compute(enough, scheduler=client.get)[0]
    np.testing.assert_array_equal(got["t"], scene.intersect_all(origins, directions,
                                                                tmax=tmax).t)
    # one crossing fewer than the fullest chunk's: that chunk's worker refuses it, and the
    # client gets the library's error (it pickles with its numbers)
    short = raycore.dask.intersect_all(scene, o, d, tmax=chunked(tmax),
                                       max_hits=max(per_chunk) - 1)
    with pytest.raises(TooManyHits) as refused:
        dask.compute(short, scheduler=client.get)
    assert (refused.value.crossings, refused.value.max_hits) == (max(per_chunk),
                                                                  max(per_chunk) - 1)


@pytest.mark.parametrize("query", raycore.dask.__all__)
def test_what_is_not_a_scene_is_refused_before_any_task_runs(query):
    with pytest.raises(ValueError, match="scene must be a raycore.Scene, got dict"):
        getattr(raycore.dask, query)({}, np.zeros((4, 3)), np.ones((4, 3)))


@pytest.mark.parametrize("max_hits", [-1, 2.5, True])
def test_a_bad_max_hits_is_refused_before_any_task_runs(max_hits):
    scene = Scene()
    scene.add_sphere([0, 0, 0], 1)
    with pytest.raises(ValueError, match="max_hits"):
        raycore.dask.intersect_all(scene, np.zeros((4, 3)), np.ones((4, 3)), max_hits=max_hits)
