"""The analytic shapes as one family: kind codes, compiled dispatch, and batch intersection.

Each shape module (:mod:`~raycore.primitives.sphere`, :mod:`~raycore.primitives.plane`,
:mod:`~raycore.primitives.disk`, :mod:`~raycore.primitives.box`,
:mod:`~raycore.primitives.cylinder`, :mod:`~raycore.primitives.cone`) provides ``pack`` (a
validated (PARAM_WIDTH,) float64 parameter row), ``hit``, ``surface`` and ``bounds``; the box
module also the ``*_transformed`` variants.  This module numbers the shapes, dispatches on that
number inside compiled code (:func:`analytic_hit`, :func:`analytic_surface`), and offers one
``intersect_<shape>`` function per shape for batches of rays against a single shape.

Kernel contract (for callers such as the BVH traversal):

* ``analytic_hit(kind, params, ox, oy, oz, dx, dy, dz, tmin, tmax, method) -> (t, part)``: the
  nearest root with ``tmin <= t <= tmax`` and the surface part it lies on, or ``(inf, -1)``.
  ``params`` is one row of a (P, PARAM_WIDTH) table in the scene's precision, and every argument
  is in that precision; the direction need not be unit (``t`` is in units of ``|d|``).
  ``method`` is a :data:`SPHERE_METHODS` code, ignored by other shapes.  A NaN in the ray or
  its bounds is a miss; no input gives ``t = NaN`` (rows from ``pack`` hold no NaN).
* ``analytic_surface(kind, params, ox, oy, oz, dx, dy, dz, t, part, want_uv) -> (nx, ny, nz,
  u, v)``: unit outward geometric normal (not flipped towards the ray) and the shape's
  ``(u, v)``, as documented in each shape module, or NaN unless ``want_uv``.
* Both are compiled with ``error_model="numpy"``; code that inlines a shape's ``hit`` directly
  must be too (see :data:`~raycore.primitives._common.inline_kernel`).
* ``pack_<shape>`` are the shape modules' ``pack`` functions under one roof.

Numba's on-disk cache of a function is invalidated by changes to its own file only: after editing
a shape module, delete the ``*.nbi`` / ``*.nbc`` files of this module (and of any cached caller)
from ``__pycache__``, or the old kernels keep running.
"""

import math

import numpy as np
from numba import njit, prange

from raycore._fp import like
from raycore.hits import Hits
from raycore.primitives import box, cone, cylinder, disk, plane, sphere
from raycore.primitives._common import PARAM_WIDTH
from raycore.rays import prepare_rays, resolve_dtype

__all__ = [
    "BOX",
    "CONE",
    "CYLINDER",
    "DISK",
    "PARAM_WIDTH",
    "PLANE",
    "SPHERE",
    "SPHERE_METHODS",
    "TRANSFORMED_BOX",
    "analytic_bounds",
    "analytic_hit",
    "analytic_surface",
    "intersect_box",
    "intersect_cone",
    "intersect_cylinder",
    "intersect_disk",
    "intersect_plane",
    "intersect_sphere",
    "intersect_transformed_box",
    "pack_box",
    "pack_cone",
    "pack_cylinder",
    "pack_disk",
    "pack_plane",
    "pack_sphere",
    "pack_transformed_box",
    "sphere_method_code",
]

SPHERE, PLANE, DISK, BOX, TRANSFORMED_BOX, CYLINDER, CONE = range(7)

#: Names accepted for the sphere method and the codes the kernels dispatch on.
SPHERE_METHODS = {
    "precise": sphere.PRECISE,
    "geometric": sphere.GEOMETRIC,
    "analytic": sphere.ANALYTIC,
}

pack_sphere = sphere.pack
pack_plane = plane.pack
pack_disk = disk.pack
pack_box = box.pack
pack_transformed_box = box.pack_transformed
pack_cylinder = cylinder.pack
pack_cone = cone.pack

_BOUNDS = {
    SPHERE: sphere.bounds,
    PLANE: plane.bounds,
    DISK: disk.bounds,
    BOX: box.bounds,
    TRANSFORMED_BOX: box.bounds_transformed,
    CYLINDER: cylinder.bounds,
    CONE: cone.bounds,
}


def sphere_method_code(name, argument="sphere_method"):
    """Return the code of a sphere method name.

    Parameters
    ----------
    name : str
        One of ``"precise"``, ``"geometric"``, ``"analytic"``.
    argument : str
        The caller's name for the argument, used in the error message.

    Raises
    ------
    ValueError
        Naming ``argument`` when ``name`` is not a known method.
    """
    try:
        return SPHERE_METHODS[name]
    except (KeyError, TypeError) as error:
        raise ValueError(
            f"{argument} must be one of {', '.join(map(repr, SPHERE_METHODS))}, got {name!r}"
        ) from error


def analytic_bounds(kind, params):
    """Axis-aligned bounds of a shape from its parameter row.

    Parameters
    ----------
    kind : int
        A kind code.
    params : array_like, shape (PARAM_WIDTH,)

    Returns
    -------
    lo, hi : ndarray, shape (3,), float64
        Conservative; infinite for a plane.
    """
    try:
        bounds = _BOUNDS[kind]
    except (KeyError, TypeError) as error:
        raise ValueError(f"kind must be one of {sorted(_BOUNDS)}, got {kind!r}") from error
    return bounds(params)


@njit(cache=True, error_model="numpy")
def analytic_hit(kind, params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """Nearest hit of one ray with the shape ``kind``: ``(t, part)``, ``(inf, -1)`` on a miss.

    The quadrics square the direction, which overflows (or underflows) float32 for lengths
    beyond 2**±63; such a direction is first scaled by a power of two, which is exact, and t
    scaled back.
    """
    _, exponent = math.frexp(max(abs(dx), abs(dy), abs(dz)))
    if abs(exponent) > DIRECTION_EXPONENT_LIMIT:
        t, part = _analytic_hit(kind, params, ox, oy, oz, math.ldexp(dx, -exponent),
                                math.ldexp(dy, -exponent), math.ldexp(dz, -exponent),
                                math.ldexp(tmin, exponent), math.ldexp(tmax, exponent), method)
        return (math.ldexp(t, -exponent) if part >= 0 else t), part
    return _analytic_hit(kind, params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)


#: Directions whose largest component is below 2**-limit or at least 2**limit are rescaled.
DIRECTION_EXPONENT_LIMIT = 20


@njit(cache=True, forceinline=True, error_model="numpy")
def table_hit(params, row, kind, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    """:func:`analytic_hit` of the shape in row ``row`` of a scene's parameter table ``params``
    ((P, PARAM_WIDTH)), or a miss where the scene holds no shapes (``params`` None).

    A scene of meshes alone passes None (``raycore.Scene._assemble``): Numba then compiles the
    branch below away, by the argument's type, and with it every shape's code.  That code was
    half of a first ``intersect``'s compile time (12 of 24 s: a 512-triangle mesh, 10 rays).
    """
    if params is None:
        return like(ox, np.inf), -1
    return analytic_hit(kind, params[row], ox, oy, oz, dx, dy, dz, tmin, tmax, method)


@njit(cache=True, forceinline=True, error_model="numpy")
def _analytic_hit(kind, params, ox, oy, oz, dx, dy, dz, tmin, tmax, method):
    if kind == SPHERE:
        return sphere.hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)
    if kind == PLANE:
        return plane.hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)
    if kind == DISK:
        return disk.hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)
    if kind == BOX:
        return box.hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)
    if kind == TRANSFORMED_BOX:
        return box.hit_transformed(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)
    if kind == CYLINDER:
        return cylinder.hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)
    if kind == CONE:
        return cone.hit(params, ox, oy, oz, dx, dy, dz, tmin, tmax, method)
    return like(ox, np.inf), -1


@njit(cache=True, error_model="numpy")
def analytic_surface(kind, params, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """Unit outward normal and ``(u, v)`` (NaN unless ``want_uv``) at ``o + t d`` on ``part``
    of the shape ``kind``."""
    if kind == SPHERE:
        return sphere.surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv)
    if kind == PLANE:
        return plane.surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv)
    if kind == DISK:
        return disk.surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv)
    if kind == BOX:
        return box.surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv)
    if kind == TRANSFORMED_BOX:
        return box.surface_transformed(params, ox, oy, oz, dx, dy, dz, t, part, want_uv)
    if kind == CYLINDER:
        return cylinder.surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv)
    if kind == CONE:
        return cone.surface(params, ox, oy, oz, dx, dy, dz, t, part, want_uv)
    nan = like(ox, np.nan)
    return nan, nan, nan, nan, nan


@njit(cache=True, parallel=True, error_model="numpy")
def _intersect_batch(kind, params, origins, directions, tmin, tmax, method, t_out, part_out,
                     normal_out, uv_out):
    """Fill ``t_out``/``part_out`` (N,) and, when they have N rows, ``normal_out`` (N, 3) and
    ``uv_out`` (N, 2) at the hits (their rows at misses are left as they are)."""
    count = origins.shape[0]
    want_normal = normal_out.shape[0] == count
    want_uv = uv_out.shape[0] == count
    for i in prange(count):
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        t, part = analytic_hit(kind, params, ox, oy, oz, dx, dy, dz, tmin[i], tmax[i], method)
        t_out[i] = t
        part_out[i] = part
        if part >= 0 and (want_normal or want_uv):
            nx, ny, nz, u, v = analytic_surface(kind, params, ox, oy, oz, dx, dy, dz, t, part,
                                                want_uv)
            if want_normal:
                normal_out[i, 0] = nx
                normal_out[i, 1] = ny
                normal_out[i, 2] = nz
            if want_uv:
                uv_out[i, 0] = u
                uv_out[i, 1] = v


def _intersect(kind, params, origins, directions, tmin, tmax, method, normal, uv, dtype):
    """Validate a batch, run it against one shape's parameter row, and wrap the result."""
    dtype = resolve_dtype(dtype)
    origins, directions, tmin, tmax = prepare_rays(origins, directions, tmin, tmax, dtype)
    with np.errstate(over="ignore"):
        row = params.astype(dtype)
    if not np.all(np.isfinite(row)):
        raise ValueError(f"the shape's parameters overflow {dtype.__name__}")
    count = len(origins)
    t = np.empty(count, dtype)
    part = np.empty(count, np.int64)
    normals = np.full((count if normal else 0, 3), np.nan, dtype)
    uvs = np.full((count if uv else 0, 2), np.nan, dtype)
    _intersect_batch(kind, row, origins, directions, tmin, tmax, method, t, part, normals, uvs)
    ids = np.where(part >= 0, 0, -1).astype(np.int64)
    return Hits(
        t=t,
        geom_id=ids,
        prim_id=ids.copy(),
        uv=uvs if uv else None,
        normal=normals if normal else None,
    )


_BATCH_DOC = """
    Parameters
    ----------
    origins, directions : array_like, shape (N, 3)
        Rays ``origin + t * direction``; directions need not be unit, but must be non-zero.
    {shape}
    tmin, tmax : float or array_like of shape (N,)
        The hit must satisfy ``tmin <= t <= tmax``.
    normal, uv : bool
        Also return unit outward normals (N, 3) and surface parameters (N, 2); NaN at misses.
    dtype : {{"float64", "float32"}}
        Precision of the computation and of the results.

    Returns
    -------
    Hits
        ``t`` (inf at misses), ``geom_id`` and ``prim_id`` (0 at hits, -1 at misses), and
        ``normal`` / ``uv`` when asked.

    Raises
    ------
    ValueError
        Naming the offending argument.
"""


def _document(shape):
    def decorate(function):
        function.__doc__ += "\n" + _BATCH_DOC.format(shape=shape.strip())
        return function

    return decorate


@_document("""
    center : array_like, shape (3,)
    radius : float
    method : {"precise", "geometric", "analytic"}
        How the roots are computed (see :mod:`raycore.primitives.sphere`).""")
def intersect_sphere(origins, directions, center, radius, *, tmin=0.0, tmax=np.inf,
                     method="precise", normal=False, uv=False, dtype="float64"):
    """Intersect rays with a sphere."""
    return _intersect(SPHERE, sphere.pack(center, radius), origins, directions, tmin, tmax,
                      sphere_method_code(method, "method"), normal, uv, dtype)


@_document("""
    point, normal_vector : array_like, shape (3,)
        A point of the plane and its normal (any non-zero length).""")
def intersect_plane(origins, directions, point, normal_vector, *, tmin=0.0, tmax=np.inf,
                    normal=False, uv=False, dtype="float64"):
    """Intersect rays with an infinite plane."""
    return _intersect(PLANE, plane.pack(point, normal_vector), origins, directions, tmin, tmax,
                      0, normal, uv, dtype)


@_document("""
    center, normal_vector : array_like, shape (3,)
        The disk's centre and normal (any non-zero length).
    radius : float""")
def intersect_disk(origins, directions, center, normal_vector, radius, *, tmin=0.0,
                   tmax=np.inf, normal=False, uv=False, dtype="float64"):
    """Intersect rays with a disk."""
    return _intersect(DISK, disk.pack(center, normal_vector, radius), origins, directions, tmin,
                      tmax, 0, normal, uv, dtype)


@_document("""
    lo, hi : array_like, shape (3,)
        Corners, ``lo < hi`` on every axis.""")
def intersect_box(origins, directions, lo, hi, *, tmin=0.0, tmax=np.inf, normal=False,
                  uv=False, dtype="float64"):
    """Intersect rays with an axis-aligned box."""
    return _intersect(BOX, box.pack(lo, hi), origins, directions, tmin, tmax, 0, normal, uv,
                      dtype)


@_document("""
    lo, hi : array_like, shape (3,)
        Corners in the box's local frame, ``lo < hi`` on every axis.
    transform : array_like, shape (4, 4)
        Affine local -> world transform.""")
def intersect_transformed_box(origins, directions, lo, hi, transform, *, tmin=0.0,
                              tmax=np.inf, normal=False, uv=False, dtype="float64"):
    """Intersect rays with a box under an affine transform."""
    return _intersect(TRANSFORMED_BOX, box.pack_transformed(lo, hi, transform), origins,
                      directions, tmin, tmax, 0, normal, uv, dtype)


@_document("""
    p0, p1 : array_like, shape (3,)
        Centres of the two caps.
    radius : float""")
def intersect_cylinder(origins, directions, p0, p1, radius, *, tmin=0.0, tmax=np.inf,
                       normal=False, uv=False, dtype="float64"):
    """Intersect rays with a capped cylinder."""
    return _intersect(CYLINDER, cylinder.pack(p0, p1, radius), origins, directions, tmin, tmax,
                      0, normal, uv, dtype)


@_document("""
    base_center, apex : array_like, shape (3,)
    radius : float
        Radius of the base.""")
def intersect_cone(origins, directions, base_center, apex, radius, *, tmin=0.0, tmax=np.inf,
                   normal=False, uv=False, dtype="float64"):
    """Intersect rays with a cone capped at its base."""
    return _intersect(CONE, cone.pack(base_center, apex, radius), origins, directions, tmin,
                      tmax, 0, normal, uv, dtype)
