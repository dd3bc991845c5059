"""The dispatch and batch layer, and what every analytic shape must do alike."""

import re

import numpy as np
import pytest
from numba import njit

from raycore.primitives import analytic

TRANSFORM = np.array([[0.5, 0.25, 0.0, 1.0], [-0.25, 1.0, 0.125, 2.0], [0.0, 0.5, 1.5, -1.0],
                      [0.0, 0.0, 0.0, 1.0]])

#: name: kind, intersect function, shape arguments, a point inside (or on, for open shapes)
SHAPES = {
    "sphere": (analytic.SPHERE, analytic.intersect_sphere, ((0.5, -0.25, 1.0), 1.25),
               (0.5, -0.25, 1.0)),
    "plane": (analytic.PLANE, analytic.intersect_plane, ((0.5, 0.25, -0.75), (1, 2, -0.5)),
              (0.5, 0.25, -0.75)),
    "disk": (analytic.DISK, analytic.intersect_disk, ((0.5, 0.25, -0.75), (0.25, -1, 0.5), 1.5),
             (0.5, 0.25, -0.75)),
    "box": (analytic.BOX, analytic.intersect_box, ((-1, -0.5, 0.25), (0.75, 1.5, 2)),
            (-0.125, 0.5, 1.125)),
    "transformed_box": (analytic.TRANSFORMED_BOX, analytic.intersect_transformed_box,
                        ((-1, -0.5, 0.25), (0.75, 1.5, 2), TRANSFORM),
                        TRANSFORM[:3, :3] @ (-0.125, 0.5, 1.125) + TRANSFORM[:3, 3]),
    "cylinder": (analytic.CYLINDER, analytic.intersect_cylinder,
                 ((0.25, -0.5, 0.125), (1.5, 0.75, 2.0), 0.625), (0.875, 0.125, 1.0625)),
    "cone": (analytic.CONE, analytic.intersect_cone,
             ((-0.5, 0.25, 0.0), (1.0, 1.25, 1.75), 0.75), (-0.125, 0.5, 0.4375)),
}
PACK = {
    analytic.SPHERE: analytic.pack_sphere,
    analytic.PLANE: analytic.pack_plane,
    analytic.DISK: analytic.pack_disk,
    analytic.BOX: analytic.pack_box,
    analytic.TRANSFORMED_BOX: analytic.pack_transformed_box,
    analytic.CYLINDER: analytic.pack_cylinder,
    analytic.CONE: analytic.pack_cone,
}
OFFSET = np.array([0.3, 0.4, -0.866])  # not parallel to any shape's flat parts


def shape(name):
    kind, function, arguments, inside = SHAPES[name]
    return kind, function, arguments, np.asarray(inside, dtype=float)


def hitting_ray(name, dtype):
    """A ray from outside through the shape's inner point, as the kernels' scalar arguments."""
    *_, inside = shape(name)
    origin = inside + 5 * OFFSET
    return np.array([*origin, *-OFFSET, 0.0, np.inf], dtype=dtype)


def row(name, dtype):
    kind, _, arguments, _ = shape(name)
    return PACK[kind](*arguments).astype(dtype)


def test_codes_and_constants():
    kinds = [analytic.SPHERE, analytic.PLANE, analytic.DISK, analytic.BOX,
             analytic.TRANSFORMED_BOX, analytic.CYLINDER, analytic.CONE]
    assert kinds == list(range(7))
    assert analytic.PARAM_WIDTH == 20
    assert analytic.SPHERE_METHODS == {"precise": 0, "geometric": 1, "analytic": 2}
    assert [analytic.sphere_method_code(name) for name in analytic.SPHERE_METHODS] == [0, 1, 2]


@pytest.mark.parametrize("name", SHAPES)
def test_pack_rows(name):
    params = row(name, np.float64)
    assert params.shape == (analytic.PARAM_WIDTH,) and params.dtype == np.float64
    assert np.all(np.isfinite(params))


@pytest.mark.parametrize("name", SHAPES)
@pytest.mark.parametrize("slot", range(8))
def test_nan_in_a_ray_or_its_bounds_is_a_miss(name, slot, dtype):
    kind = shape(name)[0]
    ray = hitting_ray(name, dtype)
    assert np.isfinite(analytic.analytic_hit(kind, row(name, dtype), *ray, 0)[0])
    ray[slot] = np.nan
    for method in range(3):
        assert analytic.analytic_hit(kind, row(name, dtype), *ray, method) == (np.inf, -1)


@pytest.mark.parametrize("name", SHAPES)
@pytest.mark.parametrize("value", [np.inf, -np.inf, 1e38])
def test_huge_or_infinite_rays_never_give_nan(name, value, dtype):
    kind = shape(name)[0]
    for slot in range(6):
        ray = hitting_ray(name, dtype)
        ray[slot] = value
        t, part = analytic.analytic_hit(kind, row(name, dtype), *ray, 0)
        assert t == np.inf and part == -1 or (0 <= t < np.inf and part >= 0)


@pytest.mark.parametrize("name", SHAPES)
def test_nan_in_parameters_never_gives_nan(name, dtype):
    kind = shape(name)[0]
    ray = hitting_ray(name, dtype)
    for slot in range(analytic.PARAM_WIDTH):
        params = row(name, dtype)
        params[slot] = np.nan
        t, part = analytic.analytic_hit(kind, params, *ray, 0)
        assert not np.isnan(t) and (t == np.inf) == (part == -1)


def test_unknown_kind():
    ray = hitting_ray("sphere", np.float64)
    assert analytic.analytic_hit(99, row("sphere", np.float64), *ray, 0) == (np.inf, -1)
    surface = analytic.analytic_surface(99, row("sphere", np.float64), *ray[:6], 1.0, 0, True)
    assert np.all(np.isnan(surface))
    with pytest.raises(ValueError, match="kind"):
        analytic.analytic_bounds(99, row("sphere", np.float64))


def _core_llvm(dispatcher):
    """The LLVM IR of a dispatcher's compiled functions, without the Python wrappers (which box
    and unbox through double)."""
    blocks = re.split(r"^(?=define )", "\n".join(dispatcher.inspect_llvm().values()), flags=re.M)
    return "\n".join(b for b in blocks if b.startswith("define") and "cpython" not in
                     b.split("(")[0] and "cfunc" not in b.split("(")[0])


def test_float32_kernels_compute_in_float32_only():
    """No double anywhere in the float32 code of every shape: a bare literal (float64 in
    Numba) or an int64 * float32 would show up as an ``fpext`` to double."""

    def promoting(x):
        return x * 0.5

    control = njit(promoting)
    control(np.float32(1))
    assert "double" in _core_llvm(control)  # the check can fail

    # fresh, uncached copies: Numba does not keep the IR of cached code
    hit = njit(error_model="numpy")(analytic.analytic_hit.py_func)
    surface = njit(error_model="numpy")(analytic.analytic_surface.py_func)
    ray = hitting_ray("sphere", np.float32)
    hit(0, row("sphere", np.float32), *ray, 0)
    surface(0, row("sphere", np.float32), *ray[:6], np.float32(1), 0, True)
    assert "double" not in _core_llvm(hit)
    assert "double" not in _core_llvm(surface)


@pytest.mark.parametrize("name", SHAPES)
def test_batch_agrees_with_the_scalar_kernel_and_fills_hits(name, dtype):
    kind, function, arguments, inside = shape(name)
    rng = np.random.default_rng(5)
    origins = inside + rng.uniform(-4, 4, size=(500, 3))
    directions = inside + rng.uniform(-1, 1, size=(500, 3)) - origins
    hits = function(origins, directions, *arguments, normal=True, uv=True, dtype=dtype)
    assert 0.2 < hits.hit.mean() < 1
    assert hits.t.dtype == hits.normal.dtype == hits.uv.dtype == np.dtype(dtype)
    assert hits.geom_id.dtype == hits.prim_id.dtype == np.int64
    np.testing.assert_array_equal(hits.geom_id, np.where(hits.hit, 0, -1))
    np.testing.assert_array_equal(hits.prim_id, hits.geom_id)
    assert np.all(np.isinf(hits.t[~hits.hit]))
    assert np.all(np.isnan(hits.normal[~hits.hit])) and np.all(np.isnan(hits.uv[~hits.hit]))
    params = row(name, dtype)
    o, d = origins.astype(dtype), directions.astype(dtype)
    zero, inf = np.array([0.0, np.inf], dtype=dtype)
    for i in range(0, 500, 25):
        t, part = analytic.analytic_hit(kind, params, *o[i], *d[i], zero, inf, 0)
        assert t == hits.t[i]
        if part >= 0:
            # a float32 t comes back from Numba as a Python float: restore its precision
            surface = analytic.analytic_surface(kind, params, *o[i], *d[i], o.dtype.type(t), part,
                                                True)
            np.testing.assert_array_equal(surface, [*hits.normal[i], *hits.uv[i]])
    plain = function(origins, directions, *arguments, dtype=dtype)
    assert plain.normal is None and plain.uv is None
    np.testing.assert_array_equal(plain.t, hits.t)


@pytest.mark.parametrize("name", SHAPES)
def test_hits_lie_in_the_bounds_and_normals_are_unit(name):
    kind, function, arguments, inside = shape(name)
    rng = np.random.default_rng(11)
    origins = inside + rng.uniform(-4, 4, size=(4000, 3))
    directions = inside + rng.uniform(-1, 1, size=(4000, 3)) - origins
    hits = function(origins, directions, *arguments, normal=True, uv=True)
    assert hits.hit.sum() > 1000
    points = origins[hits.hit] + hits.t[hits.hit, None] * directions[hits.hit]
    lo, hi = analytic.analytic_bounds(kind, row(name, np.float64))
    # the points themselves carry the rounding of o + t d
    assert np.all((lo - 1e-12 <= points) & (points <= hi + 1e-12))
    np.testing.assert_allclose(np.linalg.norm(hits.normal[hits.hit], axis=1), 1, atol=1e-14)
    if name != "plane":  # plane coordinates are unbounded
        uv = hits.uv[hits.hit]
        assert np.all((uv >= 0) & (uv <= 1))


@pytest.mark.parametrize("name", SHAPES)
@pytest.mark.parametrize(
    ("change", "argument"),
    [
        ({"origins": np.zeros((2, 2))}, "origins"),
        ({"origins": [[0, 0, np.nan]]}, "origins"),
        ({"origins": [[0, 0, np.inf]]}, "origins"),
        ({"origins": [["a", "b", "c"]]}, "origins"),
        ({"directions": np.zeros((1, 3))}, "directions"),
        ({"directions": [[1, 0, 0], [0, 1, 0]]}, "directions"),
        ({"directions": [[np.nan, 0, 1]]}, "directions"),
        ({"tmin": np.nan}, "tmin"),
        ({"tmax": [1.0, 2.0]}, "tmax"),
        ({"dtype": "float16"}, "dtype"),
        ({"dtype": "int32"}, "dtype"),
    ],
)
def test_bad_rays_raise_naming_the_argument(name, change, argument):
    _, function, arguments, _ = shape(name)
    call = {"origins": [[0.0, 0.0, 5.0]], "directions": [[0.0, 0.0, -1.0]]} | change
    origins, directions = call.pop("origins"), call.pop("directions")
    with pytest.raises(ValueError, match=argument):
        function(origins, directions, *arguments, **call)


def test_parameters_that_overflow_float32_raise():
    with pytest.raises(ValueError, match="float32"):
        analytic.intersect_sphere([[0, 0, 0]], [[1, 0, 0]], (0, 0, 0), 1e30, dtype="float32")
    hits = analytic.intersect_sphere([[0, 0, 0]], [[1, 0, 0]], (0, 0, 0), 1e30)
    assert hits.t[0] == pytest.approx(1e30, rel=1e-15)


def test_per_ray_bounds():
    hits = analytic.intersect_sphere([[0, 0, -5]] * 3, [[0, 0, 1]] * 3, (0, 0, 0), 1.0,
                                     tmin=[0.0, 4.5, 0.0], tmax=[np.inf, np.inf, 3.0])
    np.testing.assert_array_equal(hits.t, [4.0, 6.0, np.inf])
