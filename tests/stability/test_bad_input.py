"""NaN, inf and zero-length directions, and directions whose squares leave the float range.

Invalid rays are refused at the edge, for every query, method and precision: a ``ValueError``
that names the argument, never a hit with t = NaN.  Valid but extreme direction lengths are
measured; the quadrics square the direction, so the kernels rescale directions whose square
would overflow or underflow float32 (once a bug: wrong answers beyond 2**±63).
"""

import functools

import numpy as np
import pytest

from raycore import Scene
from raycore.primitives import analytic
from raycore.primitives.triangle import intersect_triangles
from raycore.sensors import lidar
from tests.primitives.triangle_reference import tessellated_box
from tests.stability.catalogue import DTYPES, METHODS, QUADRIC, compare, f32
from tests.stability.exact import mesh_closest, quadric_closest

BAD = {
    "NaN origin": ("origins", [np.nan, 0, 0], [0, 0, 1]),
    "inf origin": ("origins", [np.inf, 0, 0], [0, 0, 1]),
    "NaN direction": ("directions", [0, 0, -5], [0, np.nan, 1]),
    "inf direction": ("directions", [0, 0, -5], [0, 0, -np.inf]),
    "zero direction": ("directions", [0, 0, -5], [0, 0, 0]),
    "direction zero once rounded to float32": ("directions", [0, 0, -5], [0, 1e-50, 0]),
}
QUERIES = ("intersect", "occluded", "intersect_all", "count")


@functools.cache
def every_shape(dtype):
    scene = Scene(dtype=dtype)
    vertices, faces = tessellated_box(2)
    scene.add_mesh(vertices + [4, 0, 0], faces)
    scene.add_instance(0, np.diag([1.0, 2.0, 1.0, 1.0]))
    scene.add_sphere([0, 0, 0], 1.0)
    scene.add_cylinder([-4, 0, 0], [-4, 0, 2], 1.0)
    scene.add_cone([0, 4, 0], [0, 4, 1], 1.0)
    scene.add_box([0, -4, 0], [1, -3, 1])
    scene.add_plane([0, 0, -10], [0, 0, 1])
    scene.add_disk([0, 0, 10], [0, 0, 1], 1.0)
    return scene


def _rays(origin, direction):
    good_o, good_d = [0.0, 0.0, -5.0], [0.0, 0.0, 1.0]
    return np.array([good_o, origin, good_o]), np.array([good_d, direction, good_d])


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("bad", BAD)
@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.label)
@pytest.mark.parametrize("query", QUERIES)
def test_invalid_rays_raise_naming_the_argument(query, method, bad, dtype):
    name, origin, direction = BAD[bad]
    if bad.endswith("float32") and dtype == "float64":
        name = None  # 1e-50 is a fine float64
    origins, directions = _rays(origin, direction)
    call = functools.partial(getattr(every_shape(dtype), query), origins, directions,
                             **method.options)
    if name is None:
        call()
        return
    with pytest.raises(ValueError, match=name):
        call()


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("bound", ["tmin", "tmax"])
def test_nan_bounds_raise_and_inf_tmax_is_no_limit(bound, dtype):
    scene = every_shape(dtype)
    origins, directions = _rays([0, 0, -5], [0, 0, 1])
    with pytest.raises(ValueError, match=bound):
        scene.intersect(origins, directions, **{bound: np.nan})
    hits = scene.intersect(origins, directions, tmax=np.inf)
    assert np.all(hits.t == 4.0)


@pytest.mark.parametrize("bad", [10**400, np.array([4.5 + 1j]), "5", [None]])
@pytest.mark.parametrize("bound", ["tmin", "tmax"])
def test_bounds_that_are_not_real_numbers_raise(bound, bad):
    # an int past a float's range, a complex number (whose imaginary part a cast drops), a
    # string, an object: refused by the scene's queries and the batch kernels alike
    scene = every_shape("float64")
    origins, directions = _rays([0, 0, -5], [0, 0, 1])
    for call in (scene.intersect, scene.count,
                 functools.partial(analytic.intersect_sphere, center=[0, 0, 0], radius=1.0)):
        with pytest.raises(ValueError, match=bound):
            call(origins, directions, **{bound: bad})
    # an int a float holds is a bound like any other
    assert scene.intersect(origins, directions, tmax=10**20).t[0] == 4.0
    assert analytic.intersect_sphere(origins, directions, [0, 0, 0], 1.0, tmax=10**20).t[0] == 4


@pytest.mark.parametrize("dtype", DTYPES)
def test_batch_kernels_refuse_invalid_rays_too(dtype):
    origins, directions = _rays([0, 0, -5], [0, 0, 0])
    with pytest.raises(ValueError, match="directions"):
        analytic.intersect_sphere(origins, directions, [0, 0, 0], 1.0, dtype=dtype)
    with pytest.raises(ValueError, match="directions"):
        intersect_triangles(origins, directions, [0, 0, 0], [1, 0, 0], [0, 1, 0], dtype=dtype)
    origins, directions = _rays([np.nan, 0, 0], [0, 0, 1])
    with pytest.raises(ValueError, match="origins"):
        analytic.intersect_cone(origins, directions, [0, 0, 0], [0, 0, 1], 1.0, dtype=dtype)


# ----------------------------------------------------------------------------- extreme lengths

EXTREME = (-100, 64, 100)  # float32: d·d underflows (2**-200) or overflows (2**128, 2**200)


def _extreme_rays(seed=83, count=1500):
    rng = np.random.default_rng(seed)
    o = f32(3 * rng.normal(size=(count, 3)) / np.sqrt(3))
    d = f32(0.8 * rng.normal(size=(count, 3)) / np.sqrt(3)) - o
    return o, d


def _outcomes(dtype, exponent):
    """(label, Outcome) of every method on rays with directions scaled by 2**exponent, against
    the exact answer (which scaling by a power of two does not change)."""
    from tests.stability.catalogue import Rays

    o, d = _extreme_rays()
    d = d * 2.0**exponent
    count = len(o)
    tmin, tmax = np.zeros(count), np.full(count, np.inf)
    vertices, faces = tessellated_box(4)
    shapes = {
        "sphere": (([0.0, 0, 0], 1.0), "add_sphere"),
        "cylinder": (([0.0, 0, -1], [0.0, 0, 1], 1.0), "add_cylinder"),
        "cone": (([0.0, 0, -1], [0.0, 0, 1], 1.0), "add_cone"),
    }
    out = {}
    for method in METHODS + (QUADRIC,):
        targets = (["mesh"] if method.family == "triangle" else ["sphere"]
                   if method.family == "sphere" else ["cylinder", "cone"])
        for target in targets:
            scene = Scene(dtype=dtype)
            if target == "mesh":
                scene.add_mesh(vertices, faces)
                truth = mesh_closest(o, d, vertices, faces)
            else:
                params, add = shapes[target]
                getattr(scene, add)(*params)
                truth = quadric_closest(target, o, d, params, tmin, tmax)
            rays = Rays(o, d, tmin, tmax, truth, np.ones(count, bool))
            label = target if method is QUADRIC else method.label
            out[label] = compare(scene.intersect(o, d, **method.options).t, rays)
    return out


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("exponent", EXTREME)
def test_extreme_direction_lengths_measured(exponent, dtype):
    """Lengths 2**-100 ... 2**100: no NaN anywhere; the triangles, and in float32 too the
    precise sphere, cylinder and cone, as right as at unit length."""
    outcomes = _outcomes(dtype, exponent)
    print(f"\ndirection lengths 2^{exponent} [{dtype}]:")
    for label, outcome in outcomes.items():
        print(f"  {label:20s} {outcome.describe()}")
        assert outcome.nan == 0, label
        if dtype == "float64" or label.startswith(("triangle", "sphere precise", "cylinder",
                                                     "cone")):
            assert outcome.wrong == 0, label


def _scene_with_a_sphere():
    scene = Scene()
    scene.add_sphere([0, 0, 0], 1.0)
    return scene


@pytest.mark.parametrize(("call", "name"), [
    (lambda: _scene_with_a_sphere().intersect([[0, 0, -5]], [[0, 0, 1]], fields=5), "fields"),
    (lambda: _scene_with_a_sphere().intersect([[0, 0, -5]], [[0, 0, 1]], fields=[None]),
     "fields"),
    (lambda: Scene(dtype=None), "dtype"),
    (lambda: Scene().add_mesh(np.eye(3), [[0, 1, 2], [0, 1]]), "faces"),
    (lambda: lidar([0, 0, 0], preset=["velodyne-vlp16"]), "preset"),
])
def test_other_arguments_of_the_wrong_kind_name_themselves(call, name):
    # each raised TypeError, or NumPy's message without the argument's name, before
    with pytest.raises(ValueError, match=name):
        call()


def test_rays_and_instances_beyond_float32s_range_answer_without_crashing():
    # float64 rays whose origins lie beyond float32's range and whose directions' reciprocals
    # underflow it, in world space or in the object space of an instance scaled by 1e-100:
    # the float32 box test made NaN slab distances of them, which entered a row's unused slots
    # (references to the root) until the traversal's stack overflowed and the process died
    scene = Scene("float64")
    triangle = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    mesh = scene.add_mesh(triangle, [[0, 1, 2]])
    scene.add_mesh(np.add(triangle, [0.0, 0.0, 1.0]), [[0, 1, 2]])
    scene.add_instance(mesh, np.diag([1e-100, 1e-100, 1e-100, 1.0]))
    origins = np.array([[1e39, 1e39, -1e39], [3.0, 2.0, -5.0], [0.3, 0.2, -1.0]])
    directions = np.array([[-1e46, -1e46, 1e46], [-3.0, -2.0, 5.0], [0.0, 0.0, 1.0]])
    hits = scene.intersect(origins, directions)
    assert hits.t[2] == 1.0  # an ordinary ray beside them is answered as ever
    assert scene.occluded(origins, directions)[2]
    assert scene.count(origins, directions)[2] == 2
    assert len(scene.intersect_all(origins, directions).t) >= 2
