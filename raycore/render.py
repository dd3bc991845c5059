"""Shading of camera-ray hits into 8-bit RGB images.

Shadings: ``depth`` (near is bright), ``normal`` (the normal facing the camera, mapped from
[-1, 1] to [0, 255]), ``lambert`` (a directional light with hard shadows: one occlusion ray per
lit hit), ``id`` (a colour per geometry id).  Misses get the background colour.
"""

import numpy as np

from raycore.offset import offset_ray_origin

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
    origins = np.asarray(origins, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    if origins.shape != (width * height, 3):
        raise ValueError(f"origins must have shape ({width * height}, 3) for a {width}x{height} "
                         f"image, got {origins.shape}")
    fields = ("normal",) if shading in ("normal", "lambert") else ()
    hits = scene.intersect(origins, directions, triangle_test=triangle_test, fields=fields)
    hit = hits.hit
    image = np.empty((len(hit), 3), np.uint8)
    image[~hit] = np.asarray(background, np.uint8)
    if shading == "depth":
        image[hit] = _depth(hits.t[hit])[:, None]
    elif shading == "id":
        image[hit] = _id_colors(hits.geom_id[hit])
    else:
        # the side of the surface the camera sees
        normal = hits.normal[hit].astype(np.float64)
        facing = np.where(np.sum(normal * directions[hit], axis=1, keepdims=True) > 0,
                          -normal, normal)
        if shading == "normal":
            image[hit] = np.round((facing * 0.5 + 0.5) * 255)
        else:
            rays = (origins[hit], directions[hit], hits.t[hit])
            image[hit] = _lambert(scene, rays, hits.geom_id[hit], facing, light_direction,
                                  colors, ambient, triangle_test)
    return image.reshape(height, width, 3)


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


def _lambert(scene, rays, geom_id, facing, light_direction, colors, ambient, triangle_test):
    """(N, 3) uint8 colours of hits under a directional light, shadowed by the scene."""
    origins, directions, t = rays
    light = np.asarray(light_direction, dtype=np.float64)
    if light.shape != (3,) or not np.all(np.isfinite(light)) or not np.any(light):
        raise ValueError("light_direction must be a finite non-zero 3-vector, "
                         f"got {light_direction!r}")
    light = light / np.linalg.norm(light)
    if colors is None:
        albedo = np.broadcast_to(DEFAULT_COLOR, (len(geom_id), 3))
    else:
        colors = np.asarray(colors, dtype=np.float64)
        if colors.ndim != 2 or colors.shape[1] != 3 or len(colors) < len(scene):
            raise ValueError(f"colors must have shape ({len(scene)}, 3), got {colors.shape}")
        albedo = colors[geom_id]
    cosine = facing @ light
    lit = cosine > 0
    if np.any(lit):
        dtype = scene.dtype
        step = t[lit, None] * directions[lit]
        points = (origins[lit] + step).astype(dtype)
        error = _POINT_ERROR_EPS * np.finfo(dtype).eps * (np.abs(origins[lit]) + np.abs(step))
        toward = np.broadcast_to(light, points.shape)
        shadow_origins = offset_ray_origin(points, facing[lit], toward, error=error)
        shadowed = scene.occluded(shadow_origins, toward, triangle_test=triangle_test)
        lit[np.flatnonzero(lit)[shadowed]] = False
    intensity = ambient + (1 - ambient) * np.where(lit, cosine, 0.0)
    return np.round(np.clip(albedo * intensity[:, None], 0, 1) * 255).astype(np.uint8)
