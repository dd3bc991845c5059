"""Shading of camera-ray hits: silhouettes, depth order, normals, shadows, ids."""

import numpy as np
import pytest

from raycore import Scene
from raycore.camera import orthographic_rays, perspective_rays
from raycore.render import DEFAULT_COLOR, render

SIZE = 96


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
    floor = np.round(np.asarray(DEFAULT_COLOR) * 255).astype(np.uint8)
    shadow = np.round(np.asarray(DEFAULT_COLOR) * 0.2 * 255).astype(np.uint8)
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
])
def test_bad_arguments_name_themselves(change, name):
    args = {"width": SIZE, "height": SIZE, "shading": "lambert", **change}
    with pytest.raises(ValueError, match=name):
        render(_sphere_scene(), *_front_view(), **args)
