"""Open3D's RaycastingScene calls on raycore.Scene, against Open3D's own answers."""

import numpy as np
import pytest

import raycore
from raycore.integrations.open3d import INVALID_ID

from .conftest import load, random_rays

o3d = pytest.importorskip("open3d", reason="Open3D (the bench extra; no wheel for Python 3.13)")

MESHES = ("suzanne", "fandisk", "stanford-bunny", "nefertiti")


def both(name):
    """(raycore Scene, Open3D RaycastingScene) of one shared mesh."""
    mesh = load(name)
    ours = raycore.Scene()
    ours.add_mesh(mesh.vertices, mesh.faces)
    theirs = o3d.t.geometry.RaycastingScene()
    theirs.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                         o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    return mesh, ours, theirs


def numpy(answer):
    return {key: value.numpy() for key, value in answer.items()}


@pytest.mark.parametrize("name", MESHES)
def test_cast_rays_agrees_with_open3d(name):
    mesh, ours, theirs = both(name)
    rays = np.hstack(random_rays(mesh, 30000, seed=11)).astype(np.float32)
    got, want = ours.cast_rays(rays), numpy(theirs.cast_rays(o3d.core.Tensor(rays)))
    assert set(got) == set(want)
    for key in want:
        assert (got[key].dtype, got[key].shape) == (want[key].dtype, want[key].shape), key
    hit = want["primitive_ids"] != INVALID_ID
    assert 0.3 < hit.mean() < 0.9
    same = got["primitive_ids"] == want["primitive_ids"]
    assert same.mean() >= 0.9999  # the bar
    assert np.array_equal(got["geometry_ids"] == INVALID_ID, ~hit | ~same & (
        got["primitive_ids"] == INVALID_ID))
    both_hit = same & hit
    assert np.allclose(got["t_hit"][both_hit], want["t_hit"][both_hit], rtol=1e-5)
    assert np.isinf(got["t_hit"][~hit & same]).all()
    assert np.allclose(got["primitive_uvs"][same], want["primitive_uvs"][same], atol=1e-2)
    assert np.allclose(got["primitive_normals"][same], want["primitive_normals"][same],
                       atol=1e-3)  # same orientation, zeros on a miss


@pytest.mark.parametrize("name", ["suzanne", "fandisk"])
def test_counts_lists_and_occlusions_agree_with_open3d(name):
    mesh, ours, theirs = both(name)
    origins, directions = random_rays(mesh, 10000, seed=12)
    rays = np.hstack([origins, directions]).astype(np.float32).reshape(100, 100, 6)
    tensor = o3d.core.Tensor(rays)
    count = ours.count_intersections(rays)
    want = theirs.count_intersections(tensor).numpy()
    assert count.dtype == want.dtype and count.shape == (100, 100)
    assert want.max() >= 4
    # Embree may count a crossing of a shared edge once per triangle; raycore counts it once
    assert (count == want).mean() >= 0.995
    occluded = ours.test_occlusions(rays, tnear=0.0, tfar=0.9)
    assert occluded.dtype == bool and occluded.shape == (100, 100)
    assert np.array_equal(occluded, theirs.test_occlusions(tensor, tnear=0.0, tfar=0.9).numpy())
    assert 0 < occluded.mean() < ours.test_occlusions(rays).mean()

    listed = ours.list_intersections(rays)
    theirs_listed = numpy(theirs.list_intersections(tensor))
    assert set(listed) == set(theirs_listed)
    for key in theirs_listed:
        assert listed[key].dtype == theirs_listed[key].dtype, key
    splits, their_splits = listed["ray_splits"], theirs_listed["ray_splits"]
    assert np.array_equal(np.diff(splits.astype(np.int64)), count.ravel())
    agree = np.flatnonzero(count.ravel() == want.ravel())
    for ray in agree[::10]:
        mine = slice(splits[ray], splits[ray + 1])
        theirs_ray = slice(their_splits[ray], their_splits[ray + 1])
        assert (listed["ray_ids"][mine] == ray).all()
        assert np.allclose(listed["t_hit"][mine], np.sort(theirs_listed["t_hit"][theirs_ray]),
                           rtol=1e-5)


@pytest.mark.parametrize("form", ["look_at", "matrices"])
def test_pinhole_rays_are_open3ds(form):
    Scene = o3d.t.geometry.RaycastingScene
    if form == "look_at":
        args = (50.0, [0.1, 0.2, 0.0], [2.0, 1.0, 5.0], [0.0, 1.0, 0.2], 32, 24)
        want = Scene.create_rays_pinhole(*args).numpy()
    else:
        intrinsic = np.array([[40.0, 0, 15.5], [0, 38.0, 12.0], [0, 0, 1]])
        extrinsic = np.eye(4)
        angle = 0.3
        extrinsic[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                             [-np.sin(angle), 0, np.cos(angle)]]
        extrinsic[:3, 3] = [0.5, -1.0, 4.0]
        args = (intrinsic, extrinsic, 32, 24)
        want = Scene.create_rays_pinhole(o3d.core.Tensor(intrinsic),
                                         o3d.core.Tensor(extrinsic), 32, 24).numpy()
    got = raycore.Scene.create_rays_pinhole(*args)
    assert got.dtype == want.dtype == np.float32 and got.shape == want.shape == (24, 32, 6)
    assert np.allclose(got, want, atol=1e-5)


def test_bad_rays_are_refused_naming_the_argument():
    scene = raycore.Scene()
    scene.add_sphere([0, 0, 0], 1.0)
    with pytest.raises(ValueError, match="rays"):
        scene.cast_rays(np.zeros((4, 5)))
    with pytest.raises(ValueError, match="rays"):
        scene.count_intersections([[0, 0, np.nan, 0, 0, 1]])
    with pytest.raises(ValueError, match="nthreads"):
        scene.test_occlusions(np.ones((1, 6)), nthreads=-1)
    with pytest.raises(ValueError, match="fov_deg"):
        scene.create_rays_pinhole(180.0, [0, 0, 0], [0, 0, 1], [0, 1, 0], 4, 4)
    with pytest.raises(ValueError, match="width_px"):
        scene.create_rays_pinhole(np.eye(3), np.eye(4), 0, 4)
    # Open3D's names for the bounds, not the Scene's (tmin, tmax)
    with pytest.raises(ValueError, match="tnear"):
        scene.test_occlusions(np.ones((1, 6)), tnear=np.nan)
    with pytest.raises(ValueError, match="tfar"):
        scene.test_occlusions(np.ones((2, 6)), tfar=[1.0, np.nan])
    with pytest.raises(ValueError, match="tfar"):
        scene.test_occlusions(np.ones((2, 6)), tfar="far")
    # were TypeErrors: a comparison with None, and width_px used before it was checked
    with pytest.raises(ValueError, match="fov_deg"):
        scene.create_rays_pinhole(None, [0, 0, 0], [0, 0, 1], [0, 1, 0], 4, 4)
    with pytest.raises(ValueError, match="width_px"):
        scene.create_rays_pinhole(60.0, [0, 0, 0], [0, 0, 1], [0, 1, 0], "4", 4)
    with pytest.raises(ValueError, match="height_px"):
        scene.create_rays_pinhole(60.0, [0, 0, 0], [0, 0, 1], [0, 1, 0], 4, True)


def test_occlusion_bounds_as_numbers_and_arrays_answer_alike():
    scene = raycore.Scene()
    scene.add_sphere([0, 0, 0], 1.0)
    rays = np.tile([0.0, 0.0, 5.0, 0.0, 0.0, -1.0], (3, 1))  # the sphere from 4 to 6
    np.testing.assert_array_equal(scene.test_occlusions(rays, tfar=np.float32(3.5)), [False] * 3)
    np.testing.assert_array_equal(scene.test_occlusions(rays, tnear=2**70, tfar=np.inf),
                                  [False] * 3)
    np.testing.assert_array_equal(scene.test_occlusions(rays, tfar=[3.5, 4.5, np.inf]),
                                  [False, True, True])
