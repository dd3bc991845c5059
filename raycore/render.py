"""Shading of camera-ray hits into sRGB-encoded 8-bit images.

Shadings: ``depth`` (near is bright), ``normal`` (the normal facing the camera, mapped from
[-1, 1] to [0, 255]), ``lambert`` (a directional light with hard shadows: one occlusion ray per
lit hit), ``id`` (a colour per geometry id).  Misses get the background colour.

Each ray's colour is made in linear light (lambert's albedos are linear; the other shadings'
colours, like the background, are display values, decoded from sRGB), a pixel's samples are
averaged there, weighted by their strata (:func:`raycore.camera.strata`), and the mean is
encoded to sRGB once.  Meshes are shaded smooth, from their vertex normals
(:mod:`raycore.shading`), unless asked not to be.
"""

import inspect
import math
import struct

import numpy as np
from numba import njit, prange, vectorize

from raycore._fp import like
from raycore._memory import empty_aligned
from raycore.bvh.record import tabled_arrays_of
from raycore.camera import Camera, check_size, strata
from raycore.offset import offset_constants, offset_coordinate
from raycore.primitives._common import as_unit
from raycore.queries import hit_surface
from raycore.rays import as_float_array, as_real_array, flag, real_number
from raycore.scene import check_scene
from raycore.shading import interpolated_normal

SHADINGS = ("depth", "normal", "lambert", "id")

#: Default light: from above, slightly to the right and in front (direction towards the light).
DEFAULT_LIGHT = (0.4, 1.0, 0.6)
#: Surface colour where none is given (linear RGB in [0, 1]).
DEFAULT_COLOR = (0.8, 0.8, 0.8)
#: Relative error of a hit point ``origin + t * direction`` in units of the scene's epsilon,
#: per unit of ``|origin| + |t * direction|``: the intersection tests keep t within a few
#: roundings, the point adds two more.  Shadow ray origins move at least this far off the surface.
_POINT_ERROR_EPS = 16


def render(scene, origins, directions, width, height, shading="lambert", *, samples=1,
           smooth=True, light_direction=DEFAULT_LIGHT, colors=None, background=(0, 0, 0),
           ambient=0.15, triangle_test="watertight"):
    """Trace camera rays through ``scene`` and shade the closest hits.

    Parameters
    ----------
    scene : raycore.Scene
    origins, directions : array_like, shape (height * width * samples, 3)
        Camera rays pixel by pixel in scanline order, a pixel's samples together, as
        :mod:`raycore.camera` makes them.
    width, height : int
    shading : {"depth", "normal", "lambert", "id"}
    samples : int
        Rays per pixel, averaged in linear light with the weights of their strata.
    smooth : bool
        Shade meshes with their interpolated vertex normals (``normal``, ``lambert``); their
        geometric (face) normals when False.
    light_direction : array_like, shape (3,)
        Direction towards the light (``lambert``); any length but zero.
    colors : array_like, shape (G, 3), optional
        Linear RGB in [0, 1] of each geometry id (``lambert``); grey by default.
    background : array_like, shape (3,)
        sRGB in [0, 255] of pixels whose rays missed.
    ambient : float
        Light that reaches shadowed and back-facing surfaces (``lambert``), in [0, 1].
    triangle_test : {"watertight", "moller", "geometric"}

    Returns
    -------
    ndarray of uint8, shape (height, width, 3)
        sRGB-encoded.

    Raises
    ------
    ValueError
        Naming the argument that is wrong.
    """
    check_scene(scene)
    check_size(width, height)
    _, _, weights = strata(samples)
    rays = width * height * samples
    image = f"a {width}x{height} image of {samples} samples a pixel"
    # in the scene's precision, which the shadow rays start from
    origins, directions = (_pixel_rays(value, name, rays, scene.dtype, image)
                           for name, value in (("origins", origins), ("directions", directions)))
    row = width * samples
    return _render(scene, lambda first, last, memory=None: (origins[first * row:last * row],
                                                            directions[first * row:last * row]),
                   width, height, shading, weights, smooth, light_direction, colors, background,
                   ambient, triangle_test)


def render_camera(scene, camera, shading="lambert", *, samples=1, seed=0, **options):
    """:func:`render` of a camera's rays, which are made a band of image rows at a time as the
    render reaches them, rather than all at once.

    Parameters
    ----------
    scene : raycore.Scene
    camera : raycore.camera.Camera
        From :func:`raycore.camera.perspective_camera` or
        :func:`raycore.camera.orthographic_camera`; its size is the image's.
    shading : {"depth", "normal", "lambert", "id"}
    samples, seed : int
        Rays per pixel and their jitter (:meth:`raycore.camera.Camera.rays`).
    **options
        ``smooth``, ``light_direction``, ``colors``, ``background``, ``ambient`` and
        ``triangle_test``, as for :func:`render`.

    Returns
    -------
    ndarray of uint8, shape (camera.height, camera.width, 3)
        The image :func:`render` makes of ``camera.rays(scene.dtype, samples, seed)``.
    """
    check_scene(scene)
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a raycore.camera.Camera (perspective_camera or "
                         f"orthographic_camera), got {type(camera).__name__}")
    _, _, weights = strata(samples)
    options = {**_RENDER_DEFAULTS, **options}

    def band_rays(first, last, memory=None):
        shape = ((last - first) * camera.width * samples, 3)
        out = None if memory is None else (memory.take("origins", shape, scene.dtype),
                                           memory.take("directions", shape, scene.dtype))
        return camera.rays(scene.dtype, samples, seed, (first, last), out)

    return _render(scene, band_rays, camera.width, camera.height, shading, weights, **options)


#: :func:`render`'s options and their defaults, for :func:`render_camera`.
_RENDER_DEFAULTS = {name: parameter.default
                    for name, parameter in inspect.signature(render).parameters.items()
                    if parameter.kind is parameter.KEYWORD_ONLY and name != "samples"}


def _pixel_rays(value, name, rays, dtype, image):
    """``value`` (origins or directions, ``name``) as a (rays, 3) array of ``dtype``;
    ``ValueError`` naming it, for ``image`` (what the rays are for), otherwise."""
    array = as_real_array(value, name, dtype)
    if array.shape != (rays, 3):
        raise ValueError(f"{name} must have shape ({rays}, 3) for {image}, got {array.shape}")
    return array


def _check_shading(shading, allowed, context=""):
    """``ValueError`` unless ``shading`` is one of the names ``allowed`` (``context`` ends the
    message)."""
    if not (isinstance(shading, str) and shading in allowed):  # `in` of an array is ambiguous
        raise ValueError(f"shading must be one of {allowed}{context}, got {shading!r}")


def _render(scene, band_rays, width, height, shading, weights, smooth, light_direction,
            colors, background, ambient, triangle_test):
    """:func:`render` of the rays that ``band_rays(first_row, last_row, memory)`` gives, as
    ``(origins, directions)`` in the scene's precision, for image rows ``first_row`` to
    ``last_row - 1``; a pixel's ``len(weights)`` samples together.  ``memory``
    (:class:`_BandMemory`, or None for the whole image at once) holds arrays it may reuse."""
    _check_shading(shading, SHADINGS)
    smooth = flag(smooth, "smooth")
    if not 0 <= real_number(ambient, "ambient") <= 1:
        raise ValueError(f"ambient must be a number in [0, 1], got {ambient!r}")
    background = as_float_array(background, "background", np.float64, (3,))
    if np.any(background < 0) or np.any(background > 255):
        raise ValueError(f"background must be sRGB values in [0, 255], got {background}")
    samples = len(weights)
    background = srgb_to_linear(background / 255).astype(np.float32)
    image = np.empty((height, width, 3), np.uint8)
    if shading == "lambert":
        light, colors = _unit_light(light_direction), _color_table(colors, len(scene))
        rows = max(1, TILE_RAYS // (width * samples))
        memory = _BandMemory()
        for first in range(0, height, rows):
            last = min(height, first + rows)
            _lambert(scene, *band_rays(first, last, memory), smooth, light, colors,
                     float(ambient), background, weights, triangle_test,
                     image[first:last].reshape(-1, 3), memory)
        return image
    origins, directions = band_rays(0, height)
    fields = ()
    if shading == "normal":
        fields = ("normal", "shading_normal") if smooth else ("normal",)
    hits = scene.intersect(origins, directions, triangle_test=triangle_test, fields=fields)
    linear = np.empty((len(origins), 3), np.float32)
    linear[:] = background
    hit = hits.hit
    if shading == "depth":
        linear[hit] = srgb_to_linear(_depth(hits.t[hit]))[:, None]
    elif shading == "id":
        linear[hit] = srgb_to_linear(_id_colors(hits.geom_id[hit]) / 255)
    else:
        _normal_colors(directions, hits.normal, hits.shading_normal if smooth else hits.normal,
                       linear)
    _resolve(linear, weights, _LEVELS, _GUESSES, image.reshape(-1, 3))
    return image


#: What :func:`render_arrays` gives for each shading but lambert.
ARRAY_SHADINGS = ("depth", "normal", "id")


def render_arrays(scene, origins, directions, width, height, shading, *, smooth=True,
                  triangle_test="watertight"):
    """The data behind a ``depth``, ``normal`` or ``id`` picture, one value per pixel.

    Parameters
    ----------
    scene : raycore.Scene
    origins, directions : array_like, shape (height * width, 3)
        One ray per pixel (through its centre), in scanline order.
    width, height : int
    shading : {"depth", "normal", "id"}
    smooth : bool
        ``normal``: the shading normal (see :class:`raycore.hits.Hits`) rather than the
        geometric one.
    triangle_test : {"watertight", "moller", "geometric"}

    Returns
    -------
    ndarray
        ``depth``: (height, width) hit t (the distance along unit directions), inf for misses;
        ``normal``: (height, width, 3) unit normals as intersect gives them (not turned to the
        camera), NaN for misses; ``id``: (height, width) int32 geometry ids, -1 for misses.
    """
    check_scene(scene)
    _check_shading(shading, ARRAY_SHADINGS, " for arrays")
    smooth = flag(smooth, "smooth")
    check_size(width, height)
    origins, directions = (_pixel_rays(value, name, width * height, scene.dtype,
                                       f"a {width}x{height} image")
                           for name, value in (("origins", origins), ("directions", directions)))
    field = "shading_normal" if smooth else "normal"
    hits = scene.intersect(origins, directions, triangle_test=triangle_test,
                           fields=(field,) if shading == "normal" else ())
    if shading == "depth":
        return hits.t.reshape(height, width)
    if shading == "id":
        return hits.geom_id.astype(np.int32).reshape(height, width)
    return getattr(hits, field).reshape(height, width, 3)


@vectorize(["float64(float64)"], cache=True)
def srgb_to_linear(encoded):
    """Linear light of sRGB values (IEC 61966-2-1), both in [0, 1], any shape."""
    if encoded <= 0.04045:
        return encoded / 12.92
    return ((encoded + 0.055) / 1.055) ** 2.4


def _encode(linear):
    """sRGB value in [0, 1] of a linear one, clamped to [0, 1] (IEC 61966-2-1)."""
    linear = min(max(linear, 0.0), 1.0)
    if linear <= 0.0031308:
        return 12.92 * linear
    return 1.055 * linear ** (1 / 2.4) - 0.055


def _srgb_byte(linear):
    """8-bit sRGB of a linear value: :func:`_encode` rounded to the nearest level (the value is
    not negative, so truncation is floor)."""
    return int(_encode(linear) * 255.0 + 0.5)


def _level_thresholds():
    """(256,) float64: entry ``b`` (from 1) is the least linear value whose :func:`_srgb_byte`
    is at least ``b``, entry 0 is -inf.

    Found by bisection over the bit patterns of [0, 1] (positive floats order as their bits),
    with the very formula and libm's ``pow``, as compiled code calls it: :func:`_srgb_level`
    then gives the formula's byte exactly (checked over dense sweeps and every threshold's
    neighbours).
    """
    def bits(x):
        return struct.unpack("<q", struct.pack("<d", x))[0]

    def value(b):
        return struct.unpack("<d", struct.pack("<q", b))[0]

    thresholds = [-math.inf]
    for level in range(1, 256):
        lo, hi = bits(0.0), bits(1.0)  # _srgb_byte(value(lo)) < level <= _srgb_byte(value(hi))
        while hi - lo > 1:
            middle = (lo + hi) // 2
            if _srgb_byte(value(middle)) >= level:
                hi = middle
            else:
                lo = middle
        thresholds.append(value(hi))
    return np.array(thresholds)


#: :func:`_level_thresholds`, for :func:`_srgb_level`.
_LEVELS = _level_thresholds()
#: Square roots of linear values in [0, 1] cut into this many cells, for :data:`_GUESSES`.
_CELLS = 1024
#: (_CELLS + 1,) uint8: the level of ``(j / _CELLS) ** 2``, where :func:`_srgb_level` starts.
#: A cell spans at most 0.37 of a level (the encoding rises at most 369 levels per unit of square
#: root, where its linear part meets the power), so that the start is the level or next to it.
_GUESSES = (np.searchsorted(_LEVELS, (np.arange(_CELLS + 1) / _CELLS) ** 2, side="right")
            - 1).astype(np.uint8)


@njit(inline="always")
def _srgb_level(linear, thresholds, guesses):
    """8-bit sRGB of a linear value, as :func:`_srgb_byte`: the last of the 256 ``thresholds``
    (:data:`_LEVELS`) that it reaches, looked for from the level of its square root's cell
    (``guesses``, :data:`_GUESSES`).  pow per channel made the pixel mean and encoding 6.8 ms
    of a 512x512 render; a binary search of the thresholds took 14.3 ms for 786,432 random
    values (mispredicted branches), this 2.5 ms."""
    clamped = min(linear, 1.0) if linear > 0.0 else 0.0  # NaN too: no index out of the table
    level = np.int64(guesses[int(np.sqrt(clamped) * _CELLS)])
    while level < 255 and thresholds[level + 1] <= linear:
        level += 1
    while thresholds[level] > linear:  # thresholds[0] is -inf
        level -= 1
    return np.uint8(level)


@njit(cache=True, parallel=True, _nrt=False)
def _resolve(linear, weights, thresholds, guesses, image):
    """Each pixel's samples (rows of ``linear``, (P * S, 3)), weighted, averaged and encoded
    to 8-bit sRGB in ``image`` (P, 3) (tables: :func:`_srgb_level`)."""
    samples = len(weights)
    for p in prange(len(image)):
        for k in range(3):
            total = 0.0
            for s in range(samples):
                total += weights[s] * linear[p * samples + s, k]
            image[p, k] = _srgb_level(total, thresholds, guesses)


def _unit_light(light_direction):
    light = as_float_array(light_direction, "light_direction", np.float64, (3,))
    return as_unit(light, "light_direction", "must not be zero")[0]


def _color_table(colors, count):
    if colors is None:
        return np.tile(np.asarray(DEFAULT_COLOR), (count, 1))
    colors = as_float_array(colors, "colors", np.float64)
    if colors.ndim != 2 or colors.shape[1] != 3 or len(colors) < count:
        raise ValueError(f"colors must have shape ({count}, 3), got {colors.shape}")
    if np.any(colors < 0) or np.any(colors > 1):
        raise ValueError("colors must be linear RGB values in [0, 1]")
    return colors


@njit(inline="always")
def _facing_side(nx, ny, nz, directions, i):
    """+1 or -1, of the normal's precision: the sign that turns the unit normal ``(nx, ny, nz)``
    of ray ``i``'s hit to face where the ray came from."""
    towards_ray = nx * directions[i, 0] + ny * directions[i, 1] + nz * directions[i, 2]
    return like(towards_ray, -1.0) if towards_ray > 0 else like(towards_ray, 1.0)


@njit(cache=True, parallel=True)
def _normal_colors(directions, normals, shading, linear):
    """Linear colours of hits' shading normals turned to face the camera (the side of their
    geometric ``normals``), mapped from [-1, 1] to sRGB [0, 1]; misses are left alone."""
    for i in prange(len(normals)):
        if not normals[i, 0] == normals[i, 0]:  # NaN: a miss
            continue
        side = _facing_side(normals[i, 0], normals[i, 1], normals[i, 2], directions, i)
        for k in range(3):
            linear[i, k] = srgb_to_linear(min(max(side * shading[i, k] * 0.5 + 0.5, 0.0),
                                              1.0))


#: Camera rays a lambert render traces and shades at a time (whole image rows, at least one).
#: Each band's passes (closest hits, shadow rays, pixels) write and read some 100 bytes a ray,
#: which stay in the cache for the next pass when the band is small, and every band writes
#: into the first band's arrays (:class:`_BandMemory`) rather than pages faulted in for the
#: whole image.  A 512x512, 4-sample render, rays given, 2 cores: one band 92.7 ms (demo) and
#: 75.8 (stanford-bunny), bands of 262,144 rays 85.9 / 73.2, of 65,536 80.8 / 70.5, of 16,384
#: 87.9 / 77.1; the same images.  With the arrays reused, from the camera (Zen 4): bands of
#: 8,192 to 262,144 rays 49.0-54.6 ms (demo) and 47.1-52.8 (stanford-bunny), 65,536 among the
#: fastest of both.
TILE_RAYS = 65536


class _BandMemory:
    """The arrays that each band of a render writes, made for its first band and reused by the
    others (a smaller last band takes their first rows).

    Made afresh for each band, they cost their pages afresh: glibc maps an array of 128 KiB or
    more from the kernel and gives it back when it is freed, so that each band faulted its 7 MB
    in again, 4 KiB at a time: 24,900 faults a 512x512, 4-sample demo render, which took 88 ms
    in a fresh process (2 cores) against 50 once glibc had raised that threshold (it does when
    a larger array is freed, as after a query of a million rays).
    """

    def __init__(self):
        self._arrays = {}

    def take(self, name, shape, dtype, fill=None):
        """Array ``name`` with ``shape`` (its rows first) and ``dtype``: the first rows of the
        one made before, or a new one if that is too short, with ``fill`` (if given: a value
        the same for every band) written into every row once, when it is made."""
        array = self._arrays.get(name)
        if array is None or len(array) < shape[0]:
            array = self._arrays[name] = empty_aligned(shape, dtype)
            if fill is not None:
                array[:] = fill
        return array[:shape[0]]


#: Pixels per work item of the lambert passes.  A work item numbers its lit hits' shadow rays
#: in order from where its own start (:func:`_shadow_rays`), so that the shading pass, over
#: the same items, finds each hit's answer without an index per ray.
CHUNK_PIXELS = 256


def _lambert(scene, origins, directions, smooth, light, colors, ambient, background, weights,
             triangle_test, image, memory):
    """Fill ``image`` ((P, 3) uint8) with the lambert shading of the camera rays (P * S): their
    closest hits, one shadow ray per lit hit, then the pixels (:func:`_lambert_image`); the
    arrays in between come from ``memory`` (:class:`_BandMemory`)."""
    n, dtype = len(origins), origins.dtype
    hit_arrays = [memory.take(name, (n,), kind) for name, kind in (
        ("t", dtype), ("geom_id", np.int64), ("prim_id", np.int64), ("u", dtype), ("v", dtype),
        ("slot", np.int64))]
    hits = scene._surface_hits(origins, directions, triangle_test, smooth, hit_arrays)
    cosine, starts, shadow_origins, shadow_directions = _shadow_rays(
        hits, smooth, light, CHUNK_PIXELS * len(weights), memory)
    shadowed = scene.occluded(shadow_origins, shadow_directions, triangle_test=triangle_test)
    _lambert_image(colors, hits.geom_id, cosine, shadowed, starts, CHUNK_PIXELS, ambient,
                   background, weights, _LEVELS, _GUESSES, image)


def _shadow_rays(hits, smooth, light, chunk, memory):
    """The cosines of closest hits' shading normals to the light, and a shadow ray per hit that
    the light reaches the front of (its cosine is positive: a lit hit).

    Parameters
    ----------
    hits : raycore.hits.SurfaceHits
        Of N rays.
    smooth : bool
        Shading normals interpolated from the vertex normals (``hits.tables``), or the
        geometric ones.
    light : ndarray of float64, shape (3,)
        Unit direction towards the light.
    chunk : int
        Rays per work item: the lit hits of rays ``[c * chunk, (c + 1) * chunk)`` have shadow
        rays ``starts[c]`` on, in their order.
    memory : _BandMemory
        Where the arrays come from.

    Returns
    -------
    cosine : ndarray of float64, shape (N,)
        Set at hits only.
    starts : ndarray of int64, shape (ceil(N / chunk),)
    origins, directions : ndarray, shape (L, 3)
        The L lit hits' shadow rays, of the rays' precision, for ``tmin = 0`` and
        ``tmax = inf``.
    """
    n, dtype = len(hits.t), hits.t.dtype
    cosine = memory.take("cosine", (n,), np.float64)
    # each work item's shadow ray origins, from the item's first ray's row on
    lit_origins = memory.take("lit_origins", (n, 3), dtype)
    counts = np.empty(-(-n // chunk), np.int64)
    error_eps = _POINT_ERROR_EPS * float(np.finfo(dtype).eps)
    _light_pass(*hits, smooth, light, error_eps, *offset_constants(dtype.type), chunk, cosine,
                lit_origins, counts)
    starts = np.cumsum(counts) - counts
    lit = int(counts.sum())
    # room for every ray's, so that the first band's arrays serve the others; every shadow
    # ray goes towards the light, written once for the whole render
    origins = memory.take("shadow_origins", (n, 3), dtype)[:lit]
    directions = memory.take("shadow_directions", (n, 3), dtype, fill=light)[:lit]
    _gather_shadow_rays(lit_origins, counts, starts, chunk, origins)
    return cosine, starts, origins, directions


@njit(cache=True)
def _light_pass(record, tables, origins, directions, t, geom_id, prim_id, u, v, slot, smooth,
                light, error_eps, near, float_scale, int_scale, chunk, cosine, lit_origins,
                counts):
    """:func:`_light_items` on a scene record's arrays."""
    _light_items(tabled_arrays_of(record), tables, origins, directions, t, geom_id, prim_id, u,
                 v, slot, smooth, light, error_eps, near, float_scale, int_scale, chunk, cosine,
                 lit_origins, counts)


@njit(cache=True, parallel=True, error_model="numpy", _nrt=False)
def _light_items(scene, tables, origins, directions, t, geom_id, prim_id, u, v, slot, smooth,
                 light, error_eps, near, float_scale, int_scale, chunk, cosine, lit_origins,
                 counts):
    """Per work item of ``chunk`` rays, in one pass over its hits: each hit's geometric and
    shading normals, the cosine of the shading normal (turned to the camera as the geometric
    one is) to the light, and the shadow ray origin of each lit hit, in ``lit_origins`` from
    the item's first row on; ``counts``: the item's lit hits.

    The normals stay in registers: written out as the hits' fields and read back, they and the
    shadow rays of every ray (unlit ones given an empty interval, which the occlusion query
    still paid for) took 19.5 of 79 ms of a 512x512, 4-sample demo render.  This pass and the
    gather take about as long as those passes on the demo and less on stanford-bunny, and the
    lit hits' shadow rays alone trace 20 % (demo) and 40 % (bunny) faster.
    """
    light_x, light_y, light_z = light[0], light[1], light[2]
    n = len(t)
    for item in prange(len(counts)):
        lit_row = item * chunk
        for i in range(item * chunk, min(n, (item + 1) * chunk)):
            # read once: the compiler cannot tell that the outputs do not overlap t
            distance = t[i]
            if not distance < np.inf:  # a miss
                continue
            nx, ny, nz, _, _ = hit_surface(scene, origins, directions, t, geom_id, slot, u, v,
                                           i, True, False)
            sx, sy, sz = nx, ny, nz
            if smooth:
                sx, sy, sz = interpolated_normal(tables, geom_id[i], prim_id[i], u[i], v[i],
                                                 nx, ny, nz)
            side = _facing_side(nx, ny, nz, directions, i)
            lit = 0.0
            lit += side * sx * light_x
            lit += side * sy * light_y
            lit += side * sz * light_z
            cosine[i] = lit
            if lit > 0:
                lit_origins[lit_row, 0], lit_origins[lit_row, 1], lit_origins[lit_row, 2] = \
                    _shadow_origin(origins, directions, i, distance, side * nx, side * ny,
                                   side * nz, error_eps, near, float_scale, int_scale)
                lit_row += 1
        counts[item] = lit_row - item * chunk


@njit(inline="always")
def _shadow_origin(origins, directions, i, distance, normal_x, normal_y, normal_z, error_eps,
                   near, float_scale, int_scale):
    """The origin of the shadow ray from ray ``i``'s hit, at ``distance`` along it, whose unit
    geometric normal turned to the camera is ``normal``: the hit point moved off the surface,
    to the lit side, first by the point's error bound along the normal (the point ``origin + t
    * direction`` is off by a few epsilons of ``|origin| + |t * direction|``), then as
    :func:`raycore.offset_ray_origin` does."""
    origin_x, origin_y, origin_z = origins[i, 0], origins[i, 1], origins[i, 2]
    along_x = distance * directions[i, 0]
    along_y = distance * directions[i, 1]
    along_z = distance * directions[i, 2]
    reach = 0.0
    reach += abs(normal_x) * error_eps * (abs(origin_x) + abs(along_x))
    reach += abs(normal_y) * error_eps * (abs(origin_y) + abs(along_y))
    reach += abs(normal_z) * error_eps * (abs(origin_z) + abs(along_z))
    return (_offset_coordinate(origin_x + along_x, reach, normal_x, near, float_scale, int_scale),
            _offset_coordinate(origin_y + along_y, reach, normal_y, near, float_scale, int_scale),
            _offset_coordinate(origin_z + along_z, reach, normal_z, near, float_scale, int_scale))


@njit(inline="always")
def _offset_coordinate(point, reach, normal, near, float_scale, int_scale):
    """A coordinate of a shadow ray's origin: the hit point's, moved ``reach`` along the
    normal's coordinate, then off the surface by :func:`raycore.offset.offset_coordinate`."""
    return offset_coordinate(like(near, point + reach * normal), normal, near, float_scale,
                             int_scale)


@njit(cache=True, parallel=True, _nrt=False)
def _gather_shadow_rays(lit_origins, counts, starts, chunk, origins):
    """The shadow ray origins of :func:`_light_items`' work items end to end: item ``c``'s
    ``counts[c]`` origins, from row ``c * chunk`` of ``lit_origins``, to rows ``starts[c]`` on
    of ``origins``."""
    for item in prange(len(counts)):
        for k in range(counts[item]):
            row = starts[item] + k
            origins[row, 0] = lit_origins[item * chunk + k, 0]
            origins[row, 1] = lit_origins[item * chunk + k, 1]
            origins[row, 2] = lit_origins[item * chunk + k, 2]


@njit(cache=True, parallel=True, _nrt=False)
def _lambert_image(colors, geom_id, cosine, shadowed, starts, chunk_pixels, ambient, background,
                   weights, thresholds, guesses, image):
    """8-bit sRGB pixels (``image``, (P, 3)) of lambert-shaded samples (P * S rays), in one
    pass: each ray's linear colour, albedo * (ambient + direct light) for hits and
    ``background`` ((3,) float32) for misses, rounded to float32 as a linear image would hold
    it, weighted, summed and encoded as :func:`_resolve` does.  Writing that image, filling it
    with the background first and reading it back cost 4-5 ms of a 512x512, 4-sample render.

    Direct light is the ``cosine`` of lit hits (:func:`_shadow_rays`) whose shadow ray found
    nothing: work items of ``chunk_pixels`` pixels, as there, count their lit hits from
    ``starts`` on to find them in ``shadowed``.
    """
    samples = len(weights)
    pixels = len(image)
    for item in prange(len(starts)):
        shadow_ray = starts[item]
        for p in range(item * chunk_pixels, min(pixels, (item + 1) * chunk_pixels)):
            red, green, blue = 0.0, 0.0, 0.0
            for s in range(samples):
                i = p * samples + s
                # read once: the compiler cannot tell that the image does not overlap geom_id
                geometry = geom_id[i]
                if geometry < 0:
                    r, g, b = background[0], background[1], background[2]
                else:
                    lit = cosine[i] > 0
                    if lit:
                        lit = not shadowed[shadow_ray]
                        shadow_ray += 1
                    intensity = ambient + (1.0 - ambient) * (cosine[i] if lit else 0.0)
                    r = np.float32(colors[geometry, 0] * intensity)
                    g = np.float32(colors[geometry, 1] * intensity)
                    b = np.float32(colors[geometry, 2] * intensity)
                red += weights[s] * r
                green += weights[s] * g
                blue += weights[s] * b
            image[p, 0] = _srgb_level(red, thresholds, guesses)
            image[p, 1] = _srgb_level(green, thresholds, guesses)
            image[p, 2] = _srgb_level(blue, thresholds, guesses)


def _depth(t):
    """sRGB grey levels in [0, 1] of hit distances: 1 at the nearest hit, 0.2 at the
    farthest."""
    near, far = t.min(initial=np.inf), t.max(initial=-np.inf)
    scale = (t - near) / (far - near) if far > near else np.zeros_like(t)
    return 1 - 0.8 * scale


def _id_colors(geom_id):
    """(N, 3) uint8: a bright colour per id, far apart for neighbouring ids (Knuth's hash)."""
    hashed = ((geom_id.astype(np.uint64) + np.uint64(1)) * np.uint64(2654435761)) & np.uint64(
        0xFFFFFF)
    channels = np.stack([(hashed >> np.uint64(shift)) & np.uint64(0xFF) for shift in (16, 8, 0)],
                        axis=1)
    return (64 + channels * 3 // 4).astype(np.uint8)
