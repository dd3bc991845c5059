"""Ray sets for benchmarks: cameras, random rays from inside the bounds, shadow rays.

Every set is made once, before any clock starts; the caller converts it to each library's
native form.  Which fraction of the rays hit matters as much as their number (misses are cheap
for every tracer), so the benchmarks report it for every set.
"""

import numpy as np

from raycore import offset_ray_origin

#: Direction from the box's centre to the benchmark cameras' eye (any direction off the axes).
EYE_DIRECTION = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])


def pinhole_rays(eye, target, width, height, fov_degrees):
    """Pinhole camera rays from ``eye`` looking at ``target``, one per pixel.

    Parameters
    ----------
    eye, target : array_like, shape (3,)
    width, height : int
        Image size in pixels.
    fov_degrees : float
        Vertical field of view.

    Returns
    -------
    origins, directions : ndarray of float64, shape (width * height, 3)
        Scanline order; directions are unit length.
    """
    eye, target = np.asarray(eye, np.float64), np.asarray(target, np.float64)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(np.radians(fov_degrees) / 2)
    x = (np.arange(width) + 0.5) / width * 2 - 1
    y = 1 - (np.arange(height) + 0.5) / height * 2
    px, py = np.meshgrid(x * half * width / height, y * half)
    directions = forward + px.reshape(-1, 1) * right + py.reshape(-1, 1) * up
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return np.broadcast_to(eye, directions.shape).copy(), directions


def framing_eye(lo, hi, fov_degrees=40.0):
    """(eye, centre): where a camera with ``fov_degrees`` sees the whole box [lo, hi]."""
    center = (np.asarray(lo, np.float64) + hi) / 2
    radius = np.linalg.norm(np.asarray(hi, np.float64) - lo) / 2
    distance = radius / np.tan(np.radians(fov_degrees) / 2)
    return center + distance * EYE_DIRECTION, center


def camera_rays(lo, hi, width, height, fov_degrees=40.0):
    """Pinhole camera rays framing the box [lo, hi] from outside (its bounding sphere fills
    the view's height), one per pixel.  The mesh covers only part of this frame.

    Returns
    -------
    origins, directions : ndarray of float64, shape (width * height, 3)
        Scanline order; directions are unit length.
    """
    eye, center = framing_eye(lo, hi, fov_degrees)
    return pinhole_rays(eye, center, width, height, fov_degrees)


def framed_camera_rays(lo, hi, width, height, hit, min_hit_fraction=0.9, probe_size=64):
    """Camera rays whose frame is mostly mesh: the eye of :func:`camera_rays`, with its field
    of view narrowed in steps of 0.8x until ``min_hit_fraction`` of a ``probe_size``-square
    probe image's rays hit (or 20 steps pass).

    Parameters
    ----------
    lo, hi : array_like, shape (3,)
        The mesh's bounds.
    width, height : int
    hit : callable
        ``hit(origins, directions)`` -> (N,) bool, on float64 (N, 3) arrays: the probe's test.
    min_hit_fraction : float
    probe_size : int

    Returns
    -------
    origins, directions : ndarray of float64, shape (width * height, 3)
    fov_degrees : float
        The field of view chosen.
    """
    eye, center = framing_eye(lo, hi)
    fov = 40.0
    for _ in range(20):
        if np.mean(hit(*pinhole_rays(eye, center, probe_size, probe_size, fov))) \
                >= min_hit_fraction:
            break
        fov *= 0.8
    return (*pinhole_rays(eye, center, width, height, fov), fov)


def random_rays(lo, hi, count, seed=0):
    """Rays from uniform points inside [lo, hi] in uniform random directions (unit length)."""
    rng = np.random.default_rng(seed)
    origins = lo + (hi - lo) * rng.random((count, 3))
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return origins, directions


#: A direction square to :data:`EYE_DIRECTION`: the candidate lights turn towards it.
SIDE_DIRECTION = np.array([1.0, 0.5, -0.5]) / np.linalg.norm([1.0, 0.5, -0.5])
#: Radius of the spherical area light, in box diagonals: a point then sees part of the light,
#: and how much of its shadow rays are blocked changes smoothly with the light's place.
LIGHT_RADIUS = 0.5


def light_centres(lo, hi, count=13):
    """Candidate centres of the area light, one box diagonal from the centre of [lo, hi],
    turning in equal steps from the cameras' eye (0 degrees) past the side (90) to behind the
    box (180).

    Returns
    -------
    ndarray of float64, shape (count, 3)
    """
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    angles = np.linspace(0.0, np.pi, count)[:, None]
    directions = np.cos(angles) * EYE_DIRECTION + np.sin(angles) * SIDE_DIRECTION
    return (lo + hi) / 2 + np.linalg.norm(hi - lo) * directions


def light_points(centre, lo, hi, count, seed=0):
    """``count`` points on the spherical area light around ``centre`` (radius
    :data:`LIGHT_RADIUS` box diagonals), uniform over its surface: one per shadow ray.

    Returns
    -------
    ndarray of float64, shape (count, 3)
    """
    directions = np.random.default_rng(seed).normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radius = LIGHT_RADIUS * np.linalg.norm(np.asarray(hi, np.float64) - lo)
    return np.asarray(centre, np.float64) + radius * directions


def half_shadow_light(lo, hi, blocked_fraction):
    """The candidate light centre (:func:`light_centres`) whose shadow rays come closest to
    half blocked, so that the any-hit set mixes rays that stop at a first hit with rays that
    cross the tree to the light, whatever the mesh's shape.

    ``blocked_fraction(centre)`` gives the fraction of the shadow rays towards the light around
    ``centre`` that are blocked (on a sample of them).
    """
    centres = light_centres(lo, hi)
    return centres[np.argmin([abs(blocked_fraction(centre) - 0.5) for centre in centres])]


def shadow_rays(origins, directions, t, normals, lights):
    """Shadow rays from the hit points of float32 rays towards points on a light.

    Parameters
    ----------
    origins, directions : ndarray of float32, shape (N, 3)
        The rays that hit.
    t : ndarray of float32, shape (N,)
        Their hit distances.
    normals : ndarray of float32, shape (N, 3)
        Geometric normals at the hits (any orientation, any length > 0).
    lights : array_like, shape (N, 3)
        The point each shadow ray goes to.

    Returns
    -------
    origins, directions : ndarray of float32, shape (N, 3)
        Origins moved off the surface towards their light point (``raycore.offset_ray_origin``),
        so that every library traces them from tmin = 0; each direction reaches its light point
        at t = 1.
    """
    points = origins + t[:, None] * directions
    # The point carries the rounding of t (a few ulps of |t d|) and of the product and sum:
    # 8 eps of |o| + |t d| per coordinate covers them, and keeps self-hits out of the set.
    error = 8 * np.finfo(np.float32).eps * (np.abs(origins) + np.abs(t[:, None] * directions))
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    lights = np.asarray(lights, np.float32)
    shadow_origins = offset_ray_origin(points, normals, lights - points, error=error)
    return shadow_origins, np.ascontiguousarray(lights - shadow_origins)
