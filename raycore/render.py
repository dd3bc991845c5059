"""Shading of camera-ray hits into 8-bit RGB images.

Shadings: ``depth`` (near is bright), ``normal`` (the normal facing the camera, mapped from
[-1, 1] to [0, 255]), ``lambert`` (a directional light with hard shadows: one occlusion ray per
lit hit), ``id`` (a colour per geometry id).  Misses get the background colour.
"""

import numpy as np
from numba import njit, prange

from raycore._fp import like
from raycore.offset import offset_constants, offset_coordinate

SHADINGS = ("depth", "normal", "lambert", "id")

#: Default light: from above, slightly to the right and in front (direction towards the light).
DEFAULT_LIGHT = (0.4, 1.0, 0.6)
#: Surface colour where none is given (linear RGB in [0, 1]).
DEFAULT_COLOR = (0.8, 0.8, 0.8)
#: Relative error of a hit point ``origin + t * direction`` in units of the scene's epsilon,
#: per unit of ``|origin| + |t * direction|``: the intersection tests keep t within a few
#: roundings, the point adds two more.  Shadow ray origins move at least this far off the surface.
_POINT_ERROR_EPS = 16


def render(scene, origins, directions, width, height, shading="lambert", *,
           light_direction=DEFAULT_LIGHT, colors=None, background=(0, 0, 0), ambient=0.15,
           triangle_test="watertight"):
    """Trace camera rays through ``scene`` and shade the closest hits.

    Parameters
    ----------
    scene : raycore.Scene
    origins, directions : array_like, shape (height * width, 3)
        Camera rays in scanline order (see :mod:`raycore.camera`).
    width, height : int
    shading : {"depth", "normal", "lambert", "id"}
    light_direction : array_like, shape (3,)
        Direction towards the light (``lambert``); any length but zero.
    colors : array_like, shape (G, 3), optional
        Linear RGB in [0, 1] of each geometry id (``lambert``); grey by default.
    background : array_like, shape (3,)
        RGB in [0, 255] of pixels whose ray missed.
    ambient : float
        Light that reaches shadowed and back-facing surfaces (``lambert``), in [0, 1].
    triangle_test : {"watertight", "moller", "geometric"}

    Returns
    -------
    ndarray of uint8, shape (height, width, 3)

    Raises
    ------
    ValueError
        Naming the argument that is wrong.
    """
    if shading not in SHADINGS:
        raise ValueError(f"shading must be one of {SHADINGS}, got {shading!r}")
    if not 0 <= ambient <= 1:
        raise ValueError(f"ambient must be in [0, 1], got {ambient!r}")
    # in the scene's precision, which the shadow rays start from
    origins = np.asarray(origins, dtype=scene.dtype)
    directions = np.asarray(directions, dtype=scene.dtype)
    if origins.shape != (width * height, 3):
        raise ValueError(f"origins must have shape ({width * height}, 3) for a {width}x{height} "
                         f"image, got {origins.shape}")
    if shading == "lambert":
        light = _unit_light(light_direction)
        colors = _color_table(colors, len(scene))
    fields = ("normal",) if shading in ("normal", "lambert") else ()
    hits = scene.intersect(origins, directions, triangle_test=triangle_test, fields=fields)
    hit = hits.hit
    image = np.empty((len(hit), 3), np.uint8)
    image[:] = np.asarray(background, np.uint8)
    if shading == "depth":
        image[hit] = _depth(hits.t[hit])[:, None]
    elif shading == "id":
        image[hit] = _id_colors(hits.geom_id[hit])
    elif shading == "normal":
        facing = np.empty_like(hits.normal)
        _facing_normals(directions, hits.normal, facing)
        image[hit] = np.round((facing[hit] * 0.5 + 0.5) * 255)
    else:
        count = len(hit)
        cosine = np.empty(count)
        shadow_origins = np.empty((count, 3), scene.dtype)
        shadow_directions = np.empty_like(shadow_origins)
        shadow_tmax = np.empty(count, scene.dtype)
        error_eps = _POINT_ERROR_EPS * float(np.finfo(scene.dtype).eps)
        _shadow_rays(origins, directions, hits.t, hits.normal, light, error_eps,
                     *offset_constants(scene.dtype), cosine, shadow_origins,
                     shadow_directions, shadow_tmax)
        shadowed = scene.occluded(shadow_origins, shadow_directions, 0.0, shadow_tmax,
                                  triangle_test=triangle_test)
        _shade_lambert(colors, hits.geom_id, cosine, shadowed, float(ambient), image)
    return image.reshape(height, width, 3)


def _unit_light(light_direction):
    light = np.asarray(light_direction, dtype=np.float64)
    if light.shape != (3,) or not np.all(np.isfinite(light)) or not np.any(light):
        raise ValueError("light_direction must be a finite non-zero 3-vector, "
                         f"got {light_direction!r}")
    return light / np.linalg.norm(light)


def _color_table(colors, count):
    if colors is None:
        return np.tile(np.asarray(DEFAULT_COLOR), (count, 1))
    colors = np.asarray(colors, dtype=np.float64)
    if colors.ndim != 2 or colors.shape[1] != 3 or len(colors) < count:
        raise ValueError(f"colors must have shape ({count}, 3), got {colors.shape}")
    return colors


@njit(inline="always")
def _facing_side(normals, directions, i):
    """+1 or -1: the sign that turns normal ``i`` to face where ray ``i`` came from."""
    towards_ray = (normals[i, 0] * directions[i, 0] + normals[i, 1] * directions[i, 1]
                   + normals[i, 2] * directions[i, 2])
    return like(towards_ray, -1.0) if towards_ray > 0 else like(towards_ray, 1.0)


@njit(cache=True, parallel=True)
def _facing_normals(directions, normals, facing):
    """Normals of hits turned to face the camera (NaN rows of misses stay NaN)."""
    for i in prange(len(normals)):
        side = _facing_side(normals, directions, i)
        for k in range(3):
            facing[i, k] = side * normals[i, k]


@njit(cache=True, parallel=True, error_model="numpy")
def _shadow_rays(origins, directions, t, normals, light, error_eps, near, float_scale,
                 int_scale, cosine, shadow_origins, shadow_directions, shadow_tmax):
    """Per camera ray, in one pass: the cosine of its hit's normal (facing the camera) to the
    light, and its shadow ray towards the light.

    The shadow ray starts at the hit point moved off the surface, to the lit side, first by the
    point's error bound along the normal (the point ``origin + t * direction`` is off by a few
    epsilons of ``|origin| + |t * direction|``), then as :func:`raycore.offset_ray_origin` does.
    Its tmax is inf where the light reaches the front of the surface, and -1 where it does not
    and for misses: an empty interval, so that those rays cost nothing and nothing is gathered.
    """
    for i in prange(len(t)):
        distance = t[i]  # read once, as in _shade_lambert
        side, lit, reach = like(distance, 1.0), 0.0, 0.0
        if distance < np.inf:
            side = _facing_side(normals, directions, i)
            for k in range(3):
                normal = side * normals[i, k]
                lit += normal * light[k]
                reach += abs(normal) * error_eps * (abs(origins[i, k])
                                                    + abs(distance * directions[i, k]))
        cosine[i] = lit
        shadow_tmax[i] = np.inf if lit > 0 else -1.0
        for k in range(3):
            shadow_directions[i, k] = light[k]
            if lit > 0:
                normal = side * normals[i, k]
                point = origins[i, k] + distance * directions[i, k]
                shadow_origins[i, k] = offset_coordinate(like(near, point + reach * normal),
                                                         normal, near, float_scale, int_scale)
            else:
                shadow_origins[i, k] = 0.0


@njit(cache=True, parallel=True)
def _shade_lambert(colors, geom_id, cosine, shadowed, ambient, image):
    """Colours of hits (misses are left alone): albedo * (ambient + direct light)."""
    for i in prange(len(geom_id)):
        # read once: the compiler cannot tell that the image does not overlap geom_id, and
        # reloading it for every channel made this loop 2.5x slower
        geometry = geom_id[i]
        if geometry < 0:
            continue
        lit = cosine[i] > 0 and not shadowed[i]
        intensity = ambient + (1.0 - ambient) * (cosine[i] if lit else 0.0)
        for k in range(3):
            value = min(max(colors[geometry, k] * intensity, 0.0), 1.0)
            # rounded to nearest: value is not negative, so truncation is floor (and twice as
            # fast as np.floor here)
            image[i, k] = np.uint8(int(value * 255.0 + 0.5))


def _depth(t):
    """Grey levels of hit distances: 255 at the nearest hit, 51 at the farthest."""
    near, far = t.min(initial=np.inf), t.max(initial=-np.inf)
    scale = (t - near) / (far - near) if far > near else np.zeros_like(t)
    return np.round(255 * (1 - 0.8 * scale)).astype(np.uint8)


def _id_colors(geom_id):
    """(N, 3) uint8: a bright colour per id, far apart for neighbouring ids (Knuth's hash)."""
    hashed = ((geom_id.astype(np.uint64) + np.uint64(1)) * np.uint64(2654435761)) & np.uint64(
        0xFFFFFF)
    channels = np.stack([(hashed >> np.uint64(shift)) & np.uint64(0xFF) for shift in (16, 8, 0)],
                        axis=1)
    return (64 + channels * 3 // 4).astype(np.uint8)
