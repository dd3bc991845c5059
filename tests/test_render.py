"""Shading of camera-ray hits: silhouettes, depth order, normals, shadows, ids."""

import numpy as np
import pytest

from raycore import Scene
from raycore import render as render_module
from raycore.camera import orthographic_camera, orthographic_rays, perspective_rays
from raycore.render import DEFAULT_COLOR, render, render_arrays, render_camera

SIZE = 96


def _srgb8(linear):
    """8-bit sRGB of linear values, by IEC 61966-2-1's formula."""
    linear = np.clip(np.asarray(linear, np.float64), 0, 1)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear,
                       1.055 * linear ** (1 / 2.4) - 0.055)
    return np.floor(encoded * 255 + 0.5).astype(np.uint8)


def _sphere_scene(dtype="float32"):
    scene = Scene(dtype=dtype)
    scene.add_sphere([0.0, 0.0, 0.0], 1.0)
    return scene


def _front_view(fov=40.0, distance=4.0):
    return perspective_rays([0.0, 0.0, -distance], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], fov,
                            SIZE, SIZE)


@pytest.mark.parametrize("shading", ["depth", "normal", "lambert", "id"])
def test_sphere_silhouette_covers_its_projected_area(shading):
    fov, distance = 40.0, 4.0
    image = render(_sphere_scene(), *_front_view(fov, distance), SIZE, SIZE, shading,
                   light_direction=[0.0, 0.0, -1.0])
    covered = np.any(image != 0, axis=2)
    # a sphere seen from its axis projects to a disk of angular radius asin(r / d)
    radius = np.tan(np.arcsin(1 / distance)) / np.tan(np.radians(fov) / 2) * SIZE / 2
    assert covered.sum() == pytest.approx(np.pi * radius**2, rel=0.03)
    rows, cols = np.nonzero(covered)
    assert rows.mean() == pytest.approx((SIZE - 1) / 2) and cols.mean() == pytest.approx(
        (SIZE - 1) / 2)


def test_depth_is_brighter_nearer():
    image = render(_sphere_scene(), *_front_view(), SIZE, SIZE, "depth")
    centre, rim = image[SIZE // 2, SIZE // 2, 0], image[SIZE // 2, SIZE // 2 + 12, 0]
    assert centre == 255 and 51 <= rim < centre
    assert np.all(image[..., 0] == image[..., 1])


def test_normal_shading_maps_the_facing_normal():
    image = render(_sphere_scene(), *_front_view(), SIZE, SIZE, "normal")
    # the sphere's centre faces the camera: normal (0, 0, -1), half a pixel off the image centre
    np.testing.assert_allclose(image[SIZE // 2, SIZE // 2], [128, 128, 0], atol=3)
    # seen from inside, normals still face the camera
    inside = render(_sphere_scene(), *perspective_rays([0, 0, 0], [0, 0, 1], [0, 1, 0], 40.0, 9, 9),
                    9, 9, "normal")
    np.testing.assert_array_equal(inside[4, 4], [128, 128, 0])


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_lambert_shadow_of_a_sphere_on_a_plane_without_acne(dtype, offset):
    scene = Scene(dtype=dtype)
    shift = np.array([offset, offset, offset])
    scene.add_plane(shift, [0.0, 1.0, 0.0])
    scene.add_sphere(shift + [0.0, 1.5, 0.0], 1.0)
    # looking straight down at the plane, light straight from above
    origins, directions = orthographic_rays(shift + [0.0, 10.0, 0.0], shift, [0.0, 0.0, 1.0],
                                            8.0, SIZE, SIZE)
    image = render(scene, origins, directions, SIZE, SIZE, "lambert", light_direction=[0, 1, 0],
                   ambient=0.2)
    floor = _srgb8(DEFAULT_COLOR)
    shadow = _srgb8(np.asarray(DEFAULT_COLOR) * 0.2)
    # the sphere hides its own shadow from this camera: look past it, along the plane
    radial = np.hypot(*np.meshgrid(np.arange(SIZE) - (SIZE - 1) / 2,
                                   np.arange(SIZE) - (SIZE - 1) / 2))
    outside = radial > 1.1 * SIZE / 8
    np.testing.assert_array_equal(image[outside], np.broadcast_to(floor, image[outside].shape))
    # the top of the sphere faces the light and is not shadowed by itself
    np.testing.assert_allclose(image[SIZE // 2, SIZE // 2], floor, atol=1)
    # from the side, the plane under the sphere is in its shadow
    side = perspective_rays(shift + [6.0, 0.5, 0.0], shift, [0.0, 1.0, 0.0], 60.0, SIZE, SIZE)
    beside = render(scene, *side, SIZE, SIZE, "lambert", light_direction=[0, 1, 0], ambient=0.2)
    assert np.any(np.all(beside == shadow, axis=2))


def test_lambert_uses_colors_per_geometry():
    scene = Scene()
    scene.add_sphere([-1.5, 0.0, 0.0], 1.0)
    scene.add_sphere([1.5, 0.0, 0.0], 1.0)
    colors = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    image = render(scene, *_front_view(fov=70.0), SIZE, SIZE, "lambert", colors=colors,
                   light_direction=[0.0, 0.0, -1.0], ambient=0.0)
    left, right = image[SIZE // 2, SIZE // 4], image[SIZE // 2, 3 * SIZE // 4]
    # camera right is -x looking down +z: the second sphere is on the image's left
    assert left[2] > 0 and left[0] == left[1] == 0
    assert right[0] > 0 and right[1] == right[2] == 0


def test_id_shading_tells_geometries_apart_and_shows_background():
    scene = Scene()
    scene.add_sphere([-1.5, 0.0, 0.0], 1.0)
    scene.add_sphere([1.5, 0.0, 0.0], 1.0)
    image = render(scene, *_front_view(fov=70.0), SIZE, SIZE, "id", background=(1, 2, 3))
    colors = {tuple(pixel) for pixel in image.reshape(-1, 3)}
    assert len(colors) == 3 and (1, 2, 3) in colors


@pytest.mark.parametrize(("change", "name"), [
    ({"shading": "phong"}, "shading"),
    ({"ambient": 2.0}, "ambient"),
    ({"light_direction": [0, 0, 0]}, "light_direction"),
    ({"colors": [[1.0, 0.0, 0.0, 1.0]]}, "colors"),
    ({"width": SIZE + 1}, "origins"),
    ({"width": 0}, "width"),
    ({"height": 2.5}, "height"),
    ({"ambient": None}, "ambient"),
    ({"background": [5]}, "background"),
    ({"background": [0, 300, 0]}, "background"),
    ({"background": None}, "background"),
    ({"colors": [[0.5, np.nan, 0.5]]}, "colors"),
    ({"colors": [[0.5, 2.0, 0.5]]}, "colors"),
    ({"light_direction": [1, np.inf, 0]}, "light_direction"),
    # each was another exception, or a ValueError naming something else
    ({"width": True}, "width"),
    ({"samples": True}, "samples"),
    ({"shading": np.array(["depth", "id"])}, "shading"),
    ({"origins": "x"}, "origins"),
    ({"directions": 1.0}, "directions"),
    ({"directions": np.ones((5, 3))}, "directions"),
    ({"directions": {"a": 1}}, "directions"),
    ({"smooth": "no"}, "smooth"),  # was taken as True
])
def test_bad_arguments_name_themselves(change, name):
    origins, directions = _front_view()
    args = {"origins": origins, "directions": directions, "width": SIZE, "height": SIZE,
            "shading": "lambert", **change}
    with pytest.raises(ValueError, match=name):
        render(_sphere_scene(), **args)


@pytest.mark.parametrize("camera", [None, "perspective", _front_view])
def test_render_camera_refuses_what_is_not_a_camera(camera):
    with pytest.raises(ValueError, match="camera must be a raycore.camera.Camera"):
        render_camera(_sphere_scene(), camera)


@pytest.mark.parametrize("call", ["render", "render_camera", "render_arrays"])
def test_what_is_not_a_scene_is_refused(call):
    camera = orthographic_camera([0, 0, -5], [0, 0, 0], [0, 1, 0], 2.0, SIZE, SIZE)
    args = {"render": (*_front_view(), SIZE, SIZE), "render_camera": (camera,),
            "render_arrays": (*_front_view(), SIZE, SIZE, "depth")}[call]
    with pytest.raises(ValueError, match="scene must be a raycore.Scene, got str"):
        getattr(render_module, call)("scene.json", *args)


def test_render_arrays_refuses_a_shading_that_is_not_a_name():
    with pytest.raises(ValueError, match="shading"):
        render_arrays(_sphere_scene(), *_front_view(), SIZE, SIZE, np.array(["depth", "id"]))


def test_a_light_direction_of_any_finite_size_shades_alike():
    # its squares overflow (1e300) or vanish (1e-300) unless it is scaled before its length
    images = [render(_sphere_scene(), *_front_view(), SIZE, SIZE, "lambert",
                     light_direction=np.multiply(scale, [1.0, 1.0, -1.0]))
              for scale in (1.0, 1e300, 1e-300)]
    assert len(np.unique(images[0])) > 10
    np.testing.assert_array_equal(images[1], images[0])
    np.testing.assert_array_equal(images[2], images[0])


def test_lambert_is_srgb_encoded():
    """Squares facing the camera and the light, of albedos across the range (the formula's
    linear segment included): each pixel is the albedo encoded to sRGB."""
    albedos = [0.002, 0.01, 0.05, 0.2, 0.5, 0.9]
    scene = Scene()
    for i in range(len(albedos)):
        scene.add_box([i, 0.0, 0.0], [i + 1.0, 1.0, 1.0])
    colors = np.repeat(np.asarray(albedos)[:, None], 3, axis=1)
    width, height = 8 * len(albedos), 8
    rays = orthographic_rays([len(albedos) / 2, 0.5, -5.0], [len(albedos) / 2, 0.5, 0.0],
                             [0.0, 1.0, 0.0], 1.0, width, height)
    image = render(scene, *rays, width, height, "lambert", colors=colors,
                   light_direction=[0.0, 0.0, -1.0], ambient=0.0)
    # camera right is -x looking down +z: the first box is on the right
    for i, albedo in enumerate(albedos):
        column = width - 1 - (8 * i + 4)
        np.testing.assert_array_equal(image[4, column], _srgb8([albedo] * 3))


def _half_plane_scene():
    """A triangle covering the view where x < 0.3 + 0.4 y (an oblique edge)."""
    scene = Scene(dtype="float64")
    scene.add_mesh([[-10.0, -10.0, 0.0], [-3.7, -10.0, 0.0], [4.3, 10.0, 0.0]], [[0, 1, 2]])
    return scene


def _edge_coverage(width, height, view, fine=64):
    """Each pixel's exact-enough covered fraction of ``_half_plane_scene``'s triangle, from a
    fine grid of points per pixel (independent of the camera's jitter)."""
    offsets = (np.arange(fine) + 0.5) / fine
    x = (np.arange(width)[:, None] + offsets[None, :]) / width * view - view / 2
    y = view / 2 - (np.arange(height)[:, None] + offsets[None, :]) / height * view
    # the view looks down +z from -z with up +y: image x grows towards -x
    world_x = -x
    edge_x = 0.3 + 0.4 * y
    inside = world_x[None, None, :, :] < edge_x[:, :, None, None]
    return inside.mean(axis=(1, 3))


def test_samples_reduce_edge_aliasing_averaged_in_linear_light():
    size, view = 32, 2.0
    scene = _half_plane_scene()
    expected = _srgb8(_edge_coverage(size, size, view))
    errors = {}
    for samples in (1, 16):
        rays = orthographic_rays([0.0, 0.0, -5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], view, size,
                                 size, samples=samples)
        image = render(scene, *rays, size, size, "lambert", samples=samples,
                       colors=[[1.0, 1.0, 1.0]], ambient=1.0)
        errors[samples] = np.abs(image[..., 0].astype(float) - expected).mean()
        again = render(scene, *rays, size, size, "lambert", samples=samples,
                       colors=[[1.0, 1.0, 1.0]], ambient=1.0)
        np.testing.assert_array_equal(image, again)  # deterministic
    edge = (expected > 0) & (expected < 255)
    assert edge.sum() >= size  # the edge crosses every row
    assert errors[16] < errors[1] / 3
    # averaged in linear light: a pixel k of whose 16 samples hit is sRGB of k / 16 (a half-
    # covered one 188), not the mean of the samples' sRGB values (a display mean, 128); which
    # samples hit is found from their origins, on the triangle's side of its edge
    origins, directions = orthographic_rays([0.0, 0.0, -5.0], [0.0, 0.0, 0.0],
                                            [0.0, 1.0, 0.0], view, size, size, samples=16)
    image = render(scene, origins, directions, size, size, "lambert", samples=16,
                   colors=[[1.0, 1.0, 1.0]], ambient=1.0)
    inside = origins[:, 0] < 0.3 + 0.4 * origins[:, 1]
    hit_fraction = inside.reshape(size, size, 16).mean(axis=2)
    assert ((hit_fraction > 0) & (hit_fraction < 1)).sum() >= size
    np.testing.assert_array_equal(image[..., 0], _srgb8(hit_fraction))


def test_camera_samples_are_stratified_and_seeded():
    rays = perspective_rays([0, 0, -4], [0, 0, 0], [0, 1, 0], 40.0, 3, 2, samples=5)
    assert rays[0].shape == (30, 3)
    other = perspective_rays([0, 0, -4], [0, 0, 0], [0, 1, 0], 40.0, 3, 2, samples=5, seed=1)
    assert not np.array_equal(rays[1], other[1])
    # orthographic: the origins of one pixel's samples, each in its own stratum
    origins, _ = orthographic_rays([0, 0, 0], [0, 0, 1], [0, 1, 0], 2.0, 1, 1, samples=9)
    # camera right is -x looking down +z; image y is +y
    x, y = (1 - origins[:, 0]) / 2, (1 - origins[:, 1]) / 2
    cells = np.floor(x * 3).astype(int) + 3 * np.floor(y * 3).astype(int)
    np.testing.assert_array_equal(np.sort(cells), np.arange(9))


def test_camera_jitter_is_uniform_and_its_axes_independent():
    # each sample's offset within its stratum, across and down, over 64x64 pixels of 4
    # samples: uniform in [0, 1) and uncorrelated between the axes and between seeds (one
    # hash for both axes, or the same keys, would make them equal); 16,384 offsets, so a
    # correlation's standard deviation is about 0.008
    def offsets(seed):
        origins, _ = orthographic_rays([0, 0, 0], [0, 0, 1], [0, 1, 0], 2.0, 64, 64,
                                       samples=4, seed=seed)
        # camera right is -x looking down +z; a 2x2 stratum is half a pixel of 1/32
        return ((1 - origins[:, 0]) * 64) % 1, ((1 - origins[:, 1]) * 64) % 1

    across, down = offsets(0)
    for offset in (across, down):
        assert abs(offset.mean() - 0.5) < 0.01 and abs(offset.var() - 1 / 12) < 0.005
        counts, _ = np.histogram(offset, 8, (0, 1))
        assert counts.min() > 0.9 * len(offset) / 8
    assert abs(np.corrcoef(across, down)[0, 1]) < 0.05
    assert abs(np.corrcoef(across, offsets(1)[0])[0, 1]) < 0.05


@pytest.mark.parametrize("shading", ["lambert", "depth"])
def test_a_camera_renders_as_its_rays_do(monkeypatch, shading):
    # a lambert render goes a band of rows at a time (TILE_RAYS): bands of 2 rows (the last of
    # 1) give the image that the camera's rays give in one band, and the camera's render, which
    # makes each band's rays as it reaches it, gives the same
    vertices, faces = _icosphere()
    scene = Scene("float32")
    scene.add_mesh(vertices, faces)
    scene.add_box([-3.0, -1.0, -1.0], [-1.5, 1.0, 1.0])
    camera = orthographic_camera([0.0, 1.0, -5.0], [-0.5, 0.0, 0.0], [0.0, 1.0, 0.0], 5.0, 12, 9)
    rays = camera.rays(scene.dtype, samples=4, seed=2)
    options = {"samples": 4, "colors": [[0.9, 0.2, 0.2], [0.2, 0.9, 0.2]]}
    whole = render(scene, *rays, 12, 9, shading, **options)
    assert len(np.unique(whole.reshape(-1, 3), axis=0)) > 3  # something to compare
    monkeypatch.setattr(render_module, "TILE_RAYS", 2 * 12 * 4)
    np.testing.assert_array_equal(render(scene, *rays, 12, 9, shading, **options), whole)
    np.testing.assert_array_equal(render_camera(scene, camera, shading, seed=2, **options),
                                  whole)


def _icosphere():
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=1)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def test_shading_normal_interpolates_vertex_normals():
    vertices, faces = _icosphere()
    scene = Scene(dtype="float64")
    mesh = scene.add_mesh(vertices, faces)
    placed = np.array([[2.0, 0.0, 0.0, 4.0], [0.0, 1.0, 0.5, 0.0], [0.0, 0.0, 1.0, 0.0],
                       [0.0, 0.0, 0.0, 1.0]])
    instance = scene.add_instance(mesh, placed)
    sphere = scene.add_sphere([-3.0, 0.0, 0.0], 1.0)
    rays = perspective_rays([0.5, 0.3, -9.0], [0.5, 0.0, 0.0], [0, 1, 0], 50.0, 80, 40)
    hits = scene.intersect(*rays, fields=("uv", "normal", "shading_normal"))
    assert {mesh, instance, sphere} <= set(hits.geom_id.tolist()) and -1 in hits.geom_id
    # area-weighted vertex normals, computed here
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], cross)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    on_mesh = (hits.geom_id == mesh) | (hits.geom_id == instance)
    u, v = hits.uv[on_mesh, 0:1], hits.uv[on_mesh, 1:2]
    face = faces[hits.prim_id[on_mesh]]
    expected = (1 - u - v) * normals[face[:, 0]] + u * normals[face[:, 1]] + v * normals[
        face[:, 2]]
    inverse_transpose = np.linalg.inv(placed[:3, :3]).T
    placed_rows = hits.geom_id[on_mesh] == instance
    expected[placed_rows] = expected[placed_rows] @ inverse_transpose.T
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(hits.shading_normal[on_mesh], expected, atol=1e-12)
    # not the face normals: smooth
    assert np.abs(hits.shading_normal[on_mesh] - hits.normal[on_mesh]).max() > 0.05
    # the same asked alone (no uv field made)
    alone = scene.intersect(*rays, fields=("shading_normal",))
    np.testing.assert_array_equal(alone.shading_normal, hits.shading_normal)
    elsewhere = ~on_mesh
    np.testing.assert_array_equal(hits.shading_normal[elsewhere], hits.normal[elsewhere])


def test_smooth_shading_hides_the_facets():
    """Lambert of a coarse sphere mesh, smooth: neighbouring pixels differ as little as on the
    analytic sphere; flat: the facets' edges show as steps."""
    vertices, faces = _icosphere()
    rays = _front_view()
    steps = {}
    for name in ("smooth", "flat", "analytic"):
        scene = Scene()
        if name == "analytic":
            scene.add_sphere([0.0, 0.0, 0.0], 1.0)
        else:
            scene.add_mesh(vertices, faces)
        image = render(scene, *rays, SIZE, SIZE, "lambert", smooth=name != "flat",
                       light_direction=[0.5, 0.4, -1.0]).astype(int)[..., 0]
        centre = image[SIZE // 2 - 12:SIZE // 2 + 12, SIZE // 2 - 12:SIZE // 2 + 12]
        steps[name] = max(np.abs(np.diff(centre, axis=0)).max(),
                          np.abs(np.diff(centre, axis=1)).max())
    assert steps["smooth"] <= steps["analytic"] + 2
    assert steps["flat"] > 3 * steps["smooth"]


@pytest.mark.parametrize("shading", ["depth", "normal", "id"])
@pytest.mark.parametrize("smooth", [True, False])
def test_render_arrays_are_intersect_answers(shading, smooth):
    vertices, faces = _icosphere()
    scene = Scene()
    scene.add_mesh(vertices, faces)
    scene.add_plane([0.0, -1.0, 0.0], [0.0, 1.0, 0.0])
    rays = perspective_rays([0.0, 1.0, -4.0], [0.0, 0.0, 0.0], [0, 1, 0], 50.0, 24, 16,
                            "float32")
    data = render_arrays(scene, *rays, 24, 16, shading, smooth=smooth)
    hits = scene.intersect(*rays, fields=("normal", "shading_normal"))
    expected = {"depth": hits.t.reshape(16, 24),
                "id": hits.geom_id.reshape(16, 24),
                "normal": (hits.shading_normal if smooth else hits.normal).reshape(16, 24, 3)}
    np.testing.assert_array_equal(data, expected[shading])
    assert data.dtype == (np.int32 if shading == "id" else np.float32)
