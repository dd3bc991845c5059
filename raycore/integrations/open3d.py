"""Open3D's ``RaycastingScene`` calls on a :class:`raycore.Scene`.

``scene.cast_rays(rays)``, ``scene.count_intersections(rays)``, ``scene.list_intersections(rays)``
and ``scene.test_occlusions(rays)`` take rays as Open3D does, an array of shape (..., 6) of
``[ox, oy, oz, dx, dy, dz]`` (a NumPy array, or anything with a ``.numpy()`` method such as an
``open3d.core.Tensor``), and answer with Open3D's keys, dtypes, shapes and miss values, as NumPy
arrays.  :func:`create_rays_pinhole` makes Open3D's pinhole camera rays.  Each is one of
:class:`raycore.Scene`'s queries underneath; ``t_hit`` is in units of the direction's length,
as in Open3D.

Differences from Open3D: a crossing through an edge or vertex shared by several triangles of a
mesh is counted and listed once (Embree may count it once per triangle, or not at all);
``list_intersections`` lists each ray's hits nearest first; ``nthreads`` is accepted and ignored
(raycore runs on Numba's threads: ``NUMBA_NUM_THREADS``).
"""

import numpy as np

from raycore.camera import check_size, half_tan
from raycore.rays import as_float_array, as_ray_bound, real_number

#: Open3D's ``RaycastingScene.INVALID_ID``: the id of a miss.
INVALID_ID = np.iinfo(np.uint32).max


def _rays(scene, rays, nthreads):
    """(origins (N, 3), directions (N, 3), leading shape) of Open3D-style ``rays``, in the
    scene's precision: the columns of one (N, 6) table, which the query gathers in one compiled
    pass (a float64 copy of Open3D's float32 rays, converted back, took a third of a
    ``cast_rays``)."""
    rays = np.asarray(_numpy(rays))
    if rays.ndim < 2 or rays.shape[-1] != 6:
        raise ValueError(f"rays must have shape (..., 6), got {rays.shape}")
    if not isinstance(nthreads, (int, np.integer)) or nthreads < 0:
        raise ValueError(f"nthreads must be a non-negative integer, got {nthreads!r}")
    flat = as_float_array(rays.reshape(-1, 6), "rays", scene.dtype, (None, 6))
    return flat[:, :3], flat[:, 3:], rays.shape[:-1]


def _ids(ids):
    """int64 ids with -1 for misses, as Open3D's uint32 ids with INVALID_ID (-1 wraps to it)."""
    return ids.astype(np.uint32)


def cast_rays(scene, rays, nthreads=0):
    """The closest hit of each ray, as ``RaycastingScene.cast_rays``.

    Parameters
    ----------
    scene : raycore.Scene
    rays : array_like, shape (..., 6)
    nthreads : int
        Ignored (Open3D's thread count).

    Returns
    -------
    dict of ndarray
        ``t_hit`` (...,) float32, inf on a miss; ``geometry_ids`` and ``primitive_ids`` (...,)
        uint32, ``INVALID_ID`` on a miss; ``primitive_uvs`` (..., 2) float32 barycentrics and
        ``primitive_normals`` (..., 3) float32 unit geometric normals, zero on a miss.
    """
    origins, directions, shape = _rays(scene, rays, nthreads)
    # zeros for misses, as Open3D gives them, written by the surface pass itself
    hits = scene._hits(origins, directions, 0.0, np.inf, "watertight", "precise",
                       ("uv", "normal"), miss=0.0)
    return {
        "t_hit": hits.t.astype(np.float32, copy=False).reshape(shape),
        "geometry_ids": _ids(hits.geom_id).reshape(shape),
        "primitive_ids": _ids(hits.prim_id).reshape(shape),
        "primitive_uvs": hits.uv.astype(np.float32, copy=False).reshape(*shape, 2),
        "primitive_normals": hits.normal.astype(np.float32, copy=False).reshape(*shape, 3),
    }


def count_intersections(scene, rays, nthreads=0):
    """(...,) int32: surface crossings along each ray, as ``count_intersections``."""
    origins, directions, shape = _rays(scene, rays, nthreads)
    return scene.count(origins, directions).astype(np.int32).reshape(shape)


def list_intersections(scene, rays, nthreads=0):
    """Every crossing along each ray, as ``RaycastingScene.list_intersections``.

    Returns
    -------
    dict of ndarray
        ``ray_splits`` (N + 1,) uint32: ray i's crossings are ``[ray_splits[i],
        ray_splits[i + 1])``, nearest first; ``ray_ids``, ``geometry_ids``, ``primitive_ids``
        (M,) uint32; ``t_hit`` (M,) float32; ``primitive_uvs`` (M, 2) float32 (zeros: raycore's
        crossing lists carry no barycentrics; cast from ``t_hit`` when they are needed).
    """
    origins, directions, _ = _rays(scene, rays, nthreads)
    hits = scene.intersect_all(origins, directions)
    return {
        "ray_splits": hits.offsets.astype(np.uint32),
        "ray_ids": hits.ray_index.astype(np.uint32),
        "geometry_ids": hits.geom_id.astype(np.uint32),
        "primitive_ids": hits.prim_id.astype(np.uint32),
        "primitive_uvs": np.zeros((len(hits), 2), np.float32),
        "t_hit": hits.t.astype(np.float32, copy=False),
    }


def test_occlusions(scene, rays, tnear=0.0, tfar=np.inf, nthreads=0):
    """(...,) bool: whether anything lies on each ray within [tnear, tfar], as
    ``RaycastingScene.test_occlusions``."""
    origins, directions, shape = _rays(scene, rays, nthreads)
    tnear, tfar = (_bound(value, name, len(origins), scene.dtype)
                   for value, name in ((tnear, "tnear"), (tfar, "tfar")))
    return scene.occluded(origins, directions, tnear, tfar).reshape(shape)


def _bound(value, name, count, dtype):
    """A ray bound, checked here so that an error names it as Open3D does (the Scene's query
    calls it tmin or tmax): a number as a float, an array as :func:`raycore.rays.as_ray_bound`
    makes it, which the query then takes as it is."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        value = real_number(value, name)
        if value != value:
            raise ValueError(f"{name} must not be NaN")
        return value
    return as_ray_bound(value, name, count, dtype)


test_occlusions.__test__ = False  # a query, not a test, for pytest collecting its importers


def create_rays_pinhole(*args, **kwargs):
    """Open3D's pinhole camera rays: (height_px, width_px, 6) float32.

    Either ``create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px)``, with the
    horizontal field of view in degrees, or ``create_rays_pinhole(intrinsic_matrix,
    extrinsic_matrix, width_px, height_px)`` with a (3, 3) intrinsic and a (4, 4) world-to-camera
    matrix.  Rays start at the eye; pixel (row, column) looks through its centre; directions
    are not normalised (their component along the view axis is 1), as in Open3D.
    """
    if len(args) + len(kwargs) == 6:
        return _pinhole_look_at(*args, **kwargs)
    return _pinhole(*args, **kwargs)


def _pinhole_look_at(fov_deg, center, eye, up, width_px, height_px):
    check_size(width_px, height_px, _PIXELS)  # before the focal length is made of width_px
    if not 0 < real_number(fov_deg, "fov_deg") < 180:
        raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg!r}")
    center, eye, up = (as_float_array(v, name, np.float64, (3,))
                       for v, name in ((center, "center"), (eye, "eye"), (up, "up")))
    forward = center - eye
    right = np.cross(up, forward)
    if np.linalg.norm(forward) == 0 or np.linalg.norm(right) == 0:
        raise ValueError("eye, center and up must make a camera: center != eye, up not along "
                         "the view direction")
    forward /= np.linalg.norm(forward)
    right /= np.linalg.norm(right)
    rotation = np.array([right, np.cross(forward, right), forward])  # world -> camera rows
    extrinsic = np.eye(4)
    extrinsic[:3, :3], extrinsic[:3, 3] = rotation, -rotation @ eye
    focal = 0.5 * width_px / half_tan(fov_deg)
    intrinsic = [[focal, 0, width_px / 2], [0, focal, height_px / 2], [0, 0, 1]]
    return _pinhole(intrinsic, extrinsic, width_px, height_px)


#: Open3D's names for an image's width and height.
_PIXELS = ("width_px", "height_px")


def _pinhole(intrinsic_matrix, extrinsic_matrix, width_px, height_px):
    check_size(width_px, height_px, _PIXELS)
    intrinsic = as_float_array(_numpy(intrinsic_matrix), "intrinsic_matrix", np.float64, (3, 3))
    extrinsic = as_float_array(_numpy(extrinsic_matrix), "extrinsic_matrix", np.float64, (4, 4))
    rotation, translation = extrinsic[:3, :3], extrinsic[:3, 3]
    column, row = np.meshgrid(np.arange(width_px) + 0.5, np.arange(height_px) + 0.5)
    pixels = np.stack([column, row, np.ones_like(row)], axis=-1)
    camera = pixels @ np.linalg.inv(intrinsic).T  # (H, W, 3), z = 1
    rays = np.empty((height_px, width_px, 6), np.float32)
    rays[..., :3] = -rotation.T @ translation
    rays[..., 3:] = camera @ rotation  # camera -> world: R^T d, row by row
    return rays


def _numpy(value):
    """``value`` as NumPy sees it (an ``open3d.core.Tensor`` through its ``.numpy()``)."""
    return value.numpy() if hasattr(value, "numpy") and not isinstance(value, np.ndarray) \
        else value
