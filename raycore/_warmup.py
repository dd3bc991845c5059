"""``raycore warmup``: compile, ahead of use, every kernel that raycore's public calls reach.

Numba compiles a kernel for each combination of argument types it is called with (dtype,
dimensions, memory layout, read-only or not) and caches it on disk.  Warming up therefore goes
through the public API with small scenes and every kind of input a caller (the HTTP service
included) can give: every shape, meshes and instances; scenes with every kind of object, with
meshes only, with shapes only and with one object; each query with each triangle test, sphere
method and surface field; rays as contiguous arrays of either precision, as the (read-only,
C- or Fortran-ordered) columns of a ray table, with scalar and per-ray bounds; batches of one
ray, a few and thousands (kernels may take other paths by size); camera rays, one and several a
pixel, every shading of a render, smooth and flat, ray origins offset from hits, and a scene read
back from its file.
"""

import math
import pickle
import time

import numpy as np

from raycore.bvh.build import MIN_TASK
from raycore.camera import orthographic_rays, perspective_rays
from raycore.hits import SURFACE_FIELDS
from raycore.offset import offset_ray_origin
from raycore.primitives.analytic import SPHERE_METHODS
from raycore.primitives.triangle import TRIANGLE_TESTS
from raycore.queries import GROUP_FROM, GROUP_TREE_BYTES
from raycore.render import SHADINGS, render
from raycore.scene import Scene

DTYPES = ("float32", "float64")
#: Rays per batch: one, a few, and enough for every path that large batches take.
BATCH_SIZES = (1, 13, 4096)
#: Rays per batch large enough to be traced in a coherent order (raycore.ray_order).
GROUPED_BATCH = GROUP_FROM
#: Surface fields asked of closest hits: none, each alone, all.
FIELD_SETS = ((), *((name,) for name in SURFACE_FIELDS), SURFACE_FIELDS)


def warm_up(dtypes=DTYPES, report=print):
    """Run every public call on small scenes in each of ``dtypes``, compiling what it needs.

    Parameters
    ----------
    dtypes : iterable of {"float32", "float64"}
    report : callable
        Called with one line of progress per dtype.

    Returns
    -------
    float
        Seconds taken.
    """
    started = time.perf_counter()
    for dtype in dtypes:
        began = time.perf_counter()
        for scene in _scenes(dtype):
            _query_everything(scene)
        everything = _everything_scene(dtype)
        _ray_forms(everything)
        _renders(everything)
        # a scene without shapes has kernels of its own (raycore.primitives.analytic.table_hit)
        _renders(_meshes_scene(dtype))
        _offsets(everything)
        _loaded(everything)
        _large_build(dtype)
        report(f"raycore warmup: {dtype} kernels ready in {time.perf_counter() - began:.1f} s")
    return time.perf_counter() - started


# ----------------------------------------------------------------------------- geometry


def _box_mesh(lo, hi):
    """A closed box as 8 vertices and 12 outward-facing triangles: (8, 3) float64, (12, 3)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    vertices = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], float)
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return vertices, faces


def _grid_mesh(size=8):
    """An open, wavy square of 2 * size**2 triangles around the origin, in the z = -3 plane."""
    u, v = np.meshgrid(np.linspace(-3, 3, size + 1), np.linspace(-3, 3, size + 1))
    vertices = np.column_stack([u.ravel(), v.ravel(), -3 + 0.2 * np.sin(u.ravel() * v.ravel())])
    corner = (np.arange(size)[:, None] * (size + 1) + np.arange(size)).ravel()
    faces = np.concatenate([np.column_stack([corner, corner + 1, corner + size + 2]),
                            np.column_stack([corner, corner + size + 2, corner + size + 1])])
    return vertices, faces.astype(np.int32)


def _add_shapes(scene):
    scene.add_sphere([0.0, 0.0, 0.0], 1.0)
    scene.add_plane([0.0, -2.0, 0.0], [0.0, 1.0, 0.0])
    scene.add_disk([2.5, 0.0, 0.0], [1.0, 0.2, 0.0], 0.7)
    scene.add_box([-2.8, -0.5, -0.5], [-1.8, 0.5, 0.5])
    turn = np.array([[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 1.5], [0.0, 0.0, 1.0, 2.0],
                     [0.0, 0.0, 0.0, 1.0]])
    scene.add_box([-0.4, -0.4, -0.4], [0.4, 0.4, 0.4], turn)
    scene.add_cylinder([0.0, 1.5, -1.0], [0.0, 2.5, -1.0], 0.4)
    scene.add_cone([1.5, 1.5, 0.0], [1.5, 2.5, 0.3], 0.5)


def _add_meshes(scene):
    box = scene.add_mesh(*_box_mesh([1.2, -1.8, -0.6], [2.2, -0.8, 0.4]))
    scene.add_mesh(*_grid_mesh())
    prototype = scene.add_mesh(*_box_mesh([-0.3, -0.3, -0.3], [0.3, 0.3, 0.3]), visible=False)
    shift = np.eye(4)
    shift[:3, 3] = [-1.5, 1.8, 0.5]
    scene.add_instance(prototype, shift)
    turned = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, -1.2], [-1.0, 0.0, 0.0, -1.5],
                       [0.0, 0.0, 0.0, 1.0]])
    scene.add_instance(box, turned)


def _meshes_scene(dtype):
    scene = Scene(dtype=dtype)
    _add_meshes(scene)
    return scene


def _everything_scene(dtype):
    scene = Scene(dtype=dtype)
    _add_shapes(scene)
    _add_meshes(scene)
    return scene


def _large_build(dtype):
    """Build a mesh large enough for every path of the parallel build (its top levels are
    split on all cores, more than MIN_TASK triangles, and its subtrees are built and collapsed
    as tasks) and for batches traced in a coherent order (a tree of GROUP_TREE_BYTES or more),
    and query it with such batches.  Small meshes reach none of those kernels, and an upload of a
    large one would compile them in the service.  (Of the kernels a scene without shapes has of
    its own, the grouped batches reach none that 4,096 rays do not: their traversal is
    ``_trace_in_parallel``'s.)"""
    # a full leaf block holds eight float32 or four float64 triangles in 288 bytes: 36 bytes
    # a triangle, and the wide rows come on top
    triangles = max(MIN_TASK, GROUP_TREE_BYTES // 36)
    size = math.isqrt(triangles // 2) + 1  # 2 * size**2 triangles
    scene = Scene(dtype=dtype)
    scene.add_mesh(*_grid_mesh(size))
    _query_everything(scene, (GROUPED_BATCH,))


def _scenes(dtype):
    """Scenes of every composition: all kinds, meshes only, shapes only, one mesh, one shape.
    The first is queried before it is built (a query builds it), the others after."""
    yield _everything_scene(dtype)
    meshes = _meshes_scene(dtype)
    shapes = Scene(dtype=dtype)
    _add_shapes(shapes)
    one_mesh = Scene(dtype=dtype)
    one_mesh.add_mesh(*_box_mesh([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]))
    one_shape = Scene(dtype=dtype)
    one_shape.add_sphere([0.0, 0.0, 0.0], 1.5)
    for scene in (meshes, shapes, one_mesh, one_shape):
        yield scene.build()


# ----------------------------------------------------------------------------- rays and calls


def _rays(count, dtype, seed=0):
    """``count`` rays from a sphere of radius 8 towards the scenes' middle, some missing."""
    rng = np.random.default_rng(seed)
    origins = rng.normal(size=(count, 3))
    origins *= 8 / np.linalg.norm(origins, axis=1, keepdims=True)
    directions = rng.uniform(-2.5, 2.5, (count, 3)) - origins
    return origins.astype(dtype), directions.astype(dtype)


def _bounds(count, dtype):
    """(tmin, tmax) as scalars, and per ray (some rays bounded short of everything)."""
    tmax = np.full(count, np.inf, dtype)
    tmax[::3] = 0.5
    return (0.0, np.inf), (np.zeros(count, dtype), tmax)


def _query_everything(scene, counts=BATCH_SIZES):
    """Every query, triangle test, sphere method and set of fields, with scalar and per-ray
    bounds, on batches of ``counts`` rays."""
    for count in counts:
        origins, directions = _rays(count, scene.dtype)
        # a grouped batch takes the others' kernels, and its own for the reordering, which the
        # triangle test and sphere method do not change
        tests = TRIANGLE_TESTS if count in BATCH_SIZES else ["watertight"]
        methods = SPHERE_METHODS if count in BATCH_SIZES else ["precise"]
        for tmin, tmax in _bounds(count, scene.dtype):
            rays = (origins, directions, tmin, tmax)
            for test in tests:
                for method in methods:
                    options = {"triangle_test": test, "sphere_method": method}
                    for fields in FIELD_SETS:
                        scene.intersect(*rays, fields=fields, **options)
                    scene.occluded(*rays, **options)
                    scene.intersect_all(*rays, **options)
                    scene.count(*rays, **options)
        scene.contains(origins / 4)


def _ray_forms(scene):
    """Rays in every form a caller may hand over, for each query: arrays of either precision,
    and the columns of (N, 6) and (N, 8) ray tables (with their own bounds), C- or
    Fortran-ordered, writable or read-only (as NumPy arrays over received bytes are)."""
    for count in BATCH_SIZES:
        for dtype in DTYPES:
            origins, directions = _rays(count, dtype, seed=1)
            tmin, tmax = _bounds(count, dtype)[1]
            forms = [(origins, directions, 0.0, np.inf)]
            for order in ("C", "F"):
                for columns in (6, 8):
                    table = np.zeros((count, columns), dtype, order=order)
                    table[:, :3], table[:, 3:6] = origins, directions
                    if columns == 8:
                        table[:, 6], table[:, 7] = tmin, tmax
                    for writable in (True, False):
                        view = table.copy(order=order)
                        view.flags.writeable = writable
                        bounds = (view[:, 6], view[:, 7]) if columns == 8 else (0.0, np.inf)
                        forms.append((view[:, :3], view[:, 3:6], *bounds))
            for rays in forms:
                for fields in FIELD_SETS:
                    scene.intersect(*rays, fields=fields)
                scene.occluded(*rays)
                scene.intersect_all(*rays)
                scene.count(*rays)
            scene.contains(origins / 4)


def _renders(scene):
    """Camera rays in either precision, one and several per pixel (jittered: a kernel of their
    own), and every shading (lambert with each triangle test), smooth and not."""
    view = ([6.0, 4.0, -8.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    for dtype in DTYPES:
        for width, height in ((1, 1), (64, 48)):
            for samples in (1, 4):
                cameras = (perspective_rays(*view, 45.0, width, height, dtype, samples),
                           orthographic_rays(*view, 7.0, width, height, dtype, samples))
                for origins, directions in cameras:
                    _render_every_shading(scene, origins, directions, width, height, samples)


def _render_every_shading(scene, origins, directions, width, height, samples):
    for shading in SHADINGS:
        tests = TRIANGLE_TESTS if shading == "lambert" else ("watertight",)
        for test in tests:
            for smooth in (True, False):
                render(scene, origins, directions, width, height, shading, samples=samples,
                       smooth=smooth, triangle_test=test)
    colors = np.linspace(0, 1, 3 * len(scene)).reshape(-1, 3)
    render(scene, origins, directions, width, height, colors=colors, samples=samples,
           background=np.array([10, 20, 30]))


def _loaded(scene):
    """A scene read back from its file (the service's data directory, Dask's workers): the
    checks of its trees.  Its arrays have the built scene's types: its queries compile nothing
    more."""
    pickle.loads(pickle.dumps(scene))


def _offsets(scene):
    """Secondary ray origins from hits, in either precision, with and without error bounds."""
    origins, directions = _rays(BATCH_SIZES[-1], scene.dtype, seed=2)
    hits = scene.intersect(origins, directions, fields=("normal", "point"))
    point, normal = hits.point[hits.hit], hits.normal[hits.hit]
    for dtype in DTYPES:
        points = point.astype(dtype)
        offset_ray_origin(points, normal, normal)
        offset_ray_origin(points, normal, -normal, error=np.full(len(points), 1e-4))
        offset_ray_origin(points, normal, normal, error=np.full(points.shape, 1e-4))
