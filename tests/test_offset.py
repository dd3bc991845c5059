"""offset_ray_origin: rays spawned from hit points do not re-hit the surface they leave."""

import numpy as np
import pytest
import trimesh

from raycore import Scene, offset_ray_origin

RAYS = 4000


def _random_units(rng, count):
    vectors = rng.normal(size=(count, 3))
    return vectors / np.linalg.norm(vectors, axis=1, keepdims=True)


def _sphere_scene(dtype, center, radius, kind):
    scene = Scene(dtype=dtype)
    if kind == "sphere":
        scene.add_sphere(center, radius)
    else:
        ball = trimesh.creation.icosphere(subdivisions=3, radius=radius)
        scene.add_mesh(ball.vertices + center, ball.faces)
    return scene


def _hit_points(scene, center, radius, rng):
    """Hit points, normals and ray origins of rays from 3 radii away aimed at the object."""
    origins = center + 3 * radius * _random_units(rng, RAYS)
    targets = center + 0.9 * radius * _random_units(rng, RAYS)
    hits = scene.intersect(origins, targets - origins, fields=("normal", "point"))
    assert hits.hit.all()
    return hits.point, hits.normal, origins, hits.t[:, None] * (targets - origins)


def _spawn(rng, normals, outward, lean=0.0):
    """Random directions on the hemisphere outside (or inside) of the unit normals.

    ``lean`` > 0 tilts them towards the normal: the cosine to it is then at least lean / (1 + lean).
    """
    directions = _random_units(rng, len(normals))
    side = np.sign(np.sum(directions * normals, axis=1, keepdims=True)) * (1 if outward else -1)
    directions = directions * side + lean * normals * (1 if outward else -1)
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


# (center, radius): about the origin (the absolute offset) and far from it (the ulp offset)
PLACES = [((0.0, 0.0, 0.0), 1.0), ((1e4, -1e4, 1e4), 100.0), ((1e5, 1e5, -1e5), 1e3),
          ((-1e6, 1e6, 1e6), 1e4)]


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("kind", ["sphere", "mesh"])
@pytest.mark.parametrize(("center", "radius"), PLACES)
def test_spawned_rays_do_not_rehit_their_surface(dtype, kind, center, radius):
    rng = np.random.default_rng(7)
    center = np.asarray(center)
    scene = _sphere_scene(dtype, center, radius, kind)
    points, normals, _, _ = _hit_points(scene, center, radius, rng)
    leaving = _spawn(rng, normals, outward=True)
    # not grazing, so that the chord to the far side is at least a fifth of the radius
    entering = _spawn(rng, normals, outward=False, lean=0.2)

    # a convex object: rays leaving it miss; rays entering it cross its inside first
    out = offset_ray_origin(points, normals, leaving)
    assert out.dtype == points.dtype
    assert not scene.intersect(out, leaving).hit.any()
    inside = scene.intersect(offset_ray_origin(points, normals, entering), entering)
    assert inside.hit.all()
    assert inside.t.min() > 0.1 * radius


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_the_data_has_self_hits_without_an_offset(dtype):
    """Spawning from the raw hit points re-hits the surface: the test above can fail."""
    rng = np.random.default_rng(7)
    center, radius = np.array([1e4, -1e4, 1e4]), 100.0
    scene = _sphere_scene(dtype, center, radius, "mesh")
    points, normals, _, _ = _hit_points(scene, center, radius, rng)
    leaving = _spawn(rng, normals, outward=True)
    assert scene.intersect(points, leaving).hit.mean() > 0.05


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_error_bound_covers_points_from_far_away_rays(dtype):
    """A point computed from a ray that came from 1e4 radii away is off by more than its ulps."""
    rng = np.random.default_rng(3)
    center, radius = np.zeros(3), 1.0
    scene = _sphere_scene(dtype, center, radius, "sphere")
    origins = 1e4 * _random_units(rng, RAYS)
    hits = scene.intersect(origins, center - origins, fields=("normal", "point"))
    leaving = _spawn(rng, hits.normal, outward=True)
    step = hits.t[:, None] * (center - origins)
    error = 16 * np.finfo(dtype).eps * (np.abs(origins) + np.abs(step))
    spawned = offset_ray_origin(hits.point, hits.normal, leaving, error=error)
    assert not scene.intersect(spawned, leaving).hit.any()


def test_offset_moves_along_the_normal_by_ulps_far_away_and_absolutely_near_zero():
    points = np.array([[1e6, -1e6, 0.001]], np.float32)
    normal = np.array([[0.0, 0.0, 1.0]], np.float32)
    moved = offset_ray_origin(points, normal, normal)
    assert moved[0, 0] == points[0, 0] and moved[0, 1] == points[0, 1]
    assert moved[0, 2] == np.float32(0.001) + np.float32(2.0**-16)
    # 256 ulps of 1e6 (0.0625 each) towards zero
    far = np.array([[0.0, 0.0, -1e6]], np.float32)
    assert offset_ray_origin(far, normal, normal)[0, 2] == np.float32(-1e6 + 16)


def test_offset_goes_to_the_side_of_the_new_direction():
    points = np.array([[5.0, 5.0, 5.0]])
    normal = np.array([[0.0, 1.0, 0.0]])
    assert offset_ray_origin(points, normal, [[0.0, -1.0, 0.0]])[0, 1] < 5.0
    assert offset_ray_origin(points, normal, [[0.0, 1.0, 0.0]])[0, 1] > 5.0
    assert offset_ray_origin(points, -normal, [[0.0, 1.0, 0.0]])[0, 1] > 5.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_normals_of_any_length_offset_as_unit_ones(dtype):
    # the offset steps int_scale * n units in the last place: a long normal overflowed them
    points = np.array([[1.0, 2.0, 3.0], [1e6, -1e6, 5e5]], dtype)
    unit = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]], dtype)
    want = offset_ray_origin(points, unit, unit)
    for scale in (1e-30, 1e8, 1e17 if dtype == np.float32 else 1e300):
        normals = (unit.astype(np.float64) * scale).astype(dtype)
        np.testing.assert_array_equal(offset_ray_origin(points, normals, unit), want)


@pytest.mark.parametrize("bad", [
    {"points": [[np.nan, 0, 0]]},
    {"normals": [[0, 0]]},
    {"normals": [[0, 0, 0]]},
    {"directions": [[0, 0, 1], [0, 0, 1]]},
    {"error": [-1.0]},
])
def test_bad_input_is_a_value_error_naming_the_argument(bad):
    args = {"points": [[0.0, 0, 0]], "normals": [[0.0, 0, 1]], "directions": [[0.0, 0, 1]]}
    error = bad.pop("error", None)
    args.update(bad)
    name = next(iter(bad), "error")
    with pytest.raises(ValueError, match=name):
        offset_ray_origin(**args, error=error)
