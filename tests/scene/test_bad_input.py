"""Bad input raises ValueError naming the argument; odd but valid input never yields NaN hits."""

import numpy as np
import pytest

from raycore import Scene

QUERIES = ("intersect", "occluded", "intersect_all", "count")

O = np.zeros((2, 3))
D = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])

BAD_RAYS = {
    "origins-shape": ("origins", dict(origins=np.zeros((2, 2)))),
    "origins-1d": ("origins", dict(origins=np.zeros(3), directions=np.array([0.0, 0, 1]))),
    "origins-strings": ("origins", dict(origins=[["a", "b", "c"]] * 2)),
    "origins-complex": ("origins", dict(origins=O.astype(complex))),
    "origins-objects": ("origins", dict(origins=np.array([[None, 1, 2]] * 2, dtype=object))),
    "origins-nan": ("origins", dict(origins=[[np.nan, 0, 0], [0, 0, 0]])),
    "origins-inf": ("origins", dict(origins=[[0, -np.inf, 0], [0, 0, 0]])),
    "directions-shape": ("directions", dict(directions=np.ones((3, 3)))),
    "directions-nan": ("directions", dict(directions=[[0, 0, np.nan], [0, 0, 1]])),
    "directions-inf": ("directions", dict(directions=[[0, 0, np.inf], [0, 0, 1]])),
    "directions-zero": ("directions", dict(directions=[[0, 0, 1], [0, 0, 0]])),
    "directions-negative-zero": ("directions", dict(directions=[[-0.0, 0, -0.0], [0, 0, 1]])),
    "tmin-nan": ("tmin", dict(tmin=np.nan)),
    "tmin-nan-array": ("tmin", dict(tmin=[0.0, np.nan])),
    "tmin-shape": ("tmin", dict(tmin=np.zeros(3))),
    "tmin-string": ("tmin", dict(tmin="x")),
    "tmax-nan": ("tmax", dict(tmax=np.nan)),
    "tmax-shape": ("tmax", dict(tmax=np.ones((2, 1)))),
    "triangle_test": ("triangle_test", dict(triangle_test="woop")),
    "triangle_test-none": ("triangle_test", dict(triangle_test=None)),
    "sphere_method": ("sphere_method", dict(sphere_method="exact")),
}


def small_scene(dtype):
    scene = Scene(dtype=dtype)
    scene.add_sphere([0, 0, 5], 1.0)
    scene.add_mesh([[-1, -1, 2], [1, -1, 2], [0, 1, 2]], [[0, 1, 2]])
    return scene


@pytest.mark.parametrize("query", QUERIES)
@pytest.mark.parametrize("case", BAD_RAYS, ids=list(BAD_RAYS))
def test_bad_rays_raise_value_errors_naming_the_argument(dtype, query, case):
    name, change = BAD_RAYS[case]
    arguments = dict(origins=O, directions=D, tmin=0.0, tmax=np.inf,
                     triangle_test="watertight", sphere_method="precise")
    arguments.update(change)
    with pytest.raises(ValueError, match=name):
        getattr(small_scene(dtype), query)(**arguments)


@pytest.mark.parametrize("problem", ["origins-nan", "directions-inf", "directions-zero"])
def test_strided_rays_answer_and_fail_like_contiguous_ones(dtype, problem):
    # the columns of an (N, 6) table in the scene's precision take the compiled gather; other
    # arrays are converted by NumPy
    rng = np.random.default_rng(3)
    table = np.hstack([rng.normal(size=(50, 3)), rng.normal(size=(50, 3))]).astype(dtype)
    scene = small_scene(dtype)
    strided = scene.intersect(table[:, :3], table[:, 3:], fields=("normal",))
    contiguous = scene.intersect(table[:, :3].copy(), table[:, 3:].copy(), fields=("normal",))
    for name in ("t", "geom_id", "prim_id", "normal"):
        np.testing.assert_array_equal(getattr(strided, name), getattr(contiguous, name))
    column, value = {"origins-nan": (0, np.nan), "directions-inf": (4, np.inf),
                     "directions-zero": (slice(3, 6), 0.0)}[problem]
    table[[7, 30], column] = value
    with pytest.raises(ValueError) as expected:
        scene.intersect(table[:, :3].copy(), table[:, 3:].copy())
    with pytest.raises(ValueError, match="2 bad ray\\(s\\), first at index 7") as raised:
        scene.intersect(table[:, :3], table[:, 3:])
    assert str(raised.value) == str(expected.value)


def _unaligned(array):
    """A copy of ``array`` one byte past an aligned address: NumPy allows it, and Numba types
    it apart from aligned arrays."""
    buffer = np.zeros(array.nbytes + 1, np.uint8)
    copy = np.frombuffer(buffer.data, array.dtype, array.size, offset=1).reshape(array.shape)
    copy[...] = array
    return copy


LAYOUTS = {
    "list": lambda a: a.tolist(),
    "long-double": lambda a: a.astype(np.longdouble),  # the same values, converted back
    "read-only": lambda a: np.lib.stride_tricks.as_strided(a, writeable=False),
    "fortran": np.asfortranarray,
    "reversed": lambda a: a[::-1].copy()[::-1],
    "unaligned": _unaligned,
    "big-endian": lambda a: a.astype(a.dtype.newbyteorder(">")),
}


@pytest.mark.parametrize("count", [1, 700])  # on the calling thread, and in parallel
@pytest.mark.parametrize("layout", LAYOUTS)
def test_rays_in_any_layout_answer_like_contiguous_ones(dtype, layout, count):
    # every query calls one compiled version per precision, without Numba's dispatch, so the
    # rays must reach it in that one layout whatever the caller hands over
    rng = np.random.default_rng(5)
    origins = rng.normal(size=(count, 3)).astype(dtype)
    directions = (np.array([0.0, 0.0, 3.0]) - origins).astype(dtype)
    tmax = rng.uniform(2.0, 9.0, count).astype(dtype)
    scene = small_scene(dtype)
    assert np.any(scene.occluded(origins, directions, 0.0, tmax))
    change = LAYOUTS[layout]
    for query in QUERIES:
        want = getattr(scene, query)(origins, directions, 0.0, tmax)
        got = getattr(scene, query)(change(origins), change(directions), 0.0, change(tmax))
        if query == "intersect":
            want, got = (want.t, want.geom_id, want.prim_id), (got.t, got.geom_id, got.prim_id)
        elif query == "intersect_all":
            want, got = (want.t, want.ray_index), (got.t, got.ray_index)
        np.testing.assert_array_equal(got, want, err_msg=query)


# an array of numbers: its truth value was asked first, which NumPy refuses unnamed
@pytest.mark.parametrize("fields", [("colour",), ("uv", "depth"), "normals", (1,),
                                    np.zeros((2, 2))])
def test_unknown_fields_raise(dtype, fields):
    with pytest.raises(ValueError, match="fields"):
        small_scene(dtype).intersect(O, D, fields=fields)


def test_origins_that_overflow_float32_are_refused():
    with pytest.raises(ValueError, match="origins"):
        small_scene("float32").intersect([[1e39, 0, 0], [0, 0, 0]], D)
    with pytest.raises(ValueError, match="directions"):
        small_scene("float32").intersect(O, [[0, 0, 1e39], [0, 0, 1]])


TRIANGLE = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]

BAD_MESHES = {
    "faces-out-of-range": ("faces", TRIANGLE, [[0, 1, 3]]),
    "faces-negative": ("faces", TRIANGLE, [[0, 1, -1]]),
    "faces-fractional": ("faces", TRIANGLE, [[0, 1, 1.5]]),
    "faces-nan": ("faces", TRIANGLE, [[0, 1, np.nan]]),
    "faces-strings": ("faces", TRIANGLE, [["0", "1", "2"]]),
    "faces-shape": ("faces", TRIANGLE, [[0, 1, 2, 0]]),
    "faces-1d": ("faces", TRIANGLE, [0, 1, 2]),
    "faces-empty": ("faces", TRIANGLE, np.zeros((0, 3), int)),
    "vertices-nan": ("vertices", [[np.nan, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]),
    "vertices-inf": ("vertices", [[np.inf, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]),
    "vertices-shape": ("vertices", np.zeros((3, 2)), [[0, 1, 2]]),
    "vertices-strings": ("vertices", [["a"] * 3] * 3, [[0, 1, 2]]),
}


@pytest.mark.parametrize("case", BAD_MESHES, ids=list(BAD_MESHES))
def test_bad_meshes_raise_value_errors_naming_the_argument(dtype, case):
    name, vertices, faces = BAD_MESHES[case]
    scene = Scene(dtype=dtype)
    with pytest.raises(ValueError, match=name):
        scene.add_mesh(vertices, faces)
    assert len(scene) == 0  # nothing half-added


# bool() took any of these: "no" made a visible mesh, an array raised NumPy's error
@pytest.mark.parametrize("visible", ["no", None, 1, np.array([True, False])])
def test_visible_must_be_a_bool(visible):
    scene = Scene()
    with pytest.raises(ValueError, match="visible must be True or False"):
        scene.add_mesh(TRIANGLE, [[0, 1, 2]], visible=visible)
    assert len(scene) == 0
    scene.add_mesh(TRIANGLE, [[0, 1, 2]], visible=np.bool_(False))  # NumPy's bool is one


def _translation(x, y, z):
    m = np.eye(4)
    m[:3, 3] = [x, y, z]
    return m


BAD_INSTANCES = {
    "geom_id-sphere": ("geom_id", "sphere", np.eye(4)),
    "geom_id-out-of-range": ("geom_id", 99, np.eye(4)),
    "geom_id-negative": ("geom_id", -1, np.eye(4)),
    "geom_id-float": ("geom_id", 1.0, np.eye(4)),
    "geom_id-string": ("geom_id", "1", np.eye(4)),
    "geom_id-none": ("geom_id", None, np.eye(4)),
    "geom_id-bool": ("geom_id", True, np.eye(4)),  # was taken as 1, the mesh
    "transform-singular": ("transform", "mesh", np.diag([1.0, 1.0, 0.0, 1.0])),
    "transform-nearly-singular": ("transform", "mesh", np.diag([1.0, 1.0, 1e-14, 1.0])),
    "transform-rank-2": ("transform", "mesh", np.array([[1.0, 1, 0, 0], [1, 1, 0, 0],
                                                         [0, 0, 1, 0], [0, 0, 0, 1]])),
    "transform-projective": ("transform", "mesh", np.array([[1.0, 0, 0, 0], [0, 1, 0, 0],
                                                             [0, 0, 1, 0], [0, 0, 1, 1]])),
    "transform-shape": ("transform", "mesh", np.eye(3)),
    "transform-nan": ("transform", "mesh", np.full((4, 4), np.nan)),
    "transform-inf": ("transform", "mesh", _translation(np.inf, 0, 0)),
    "transform-strings": ("transform", "mesh", [["1"] * 4] * 4),
}


@pytest.mark.parametrize("case", BAD_INSTANCES, ids=list(BAD_INSTANCES))
def test_bad_instances_raise_value_errors_naming_the_argument(dtype, case):
    name, target, transform = BAD_INSTANCES[case]
    scene = Scene(dtype=dtype)
    ids = {"sphere": scene.add_sphere([0, 0, 0], 1.0),
           "mesh": scene.add_mesh(TRIANGLE, [[0, 1, 2]], visible=False)}
    with pytest.raises(ValueError, match=name):
        geom_id = ids[target] if target in ("sphere", "mesh") else target
        scene.add_instance(geom_id, transform)
    assert len(scene) == 2


@pytest.mark.parametrize("transform", [np.diag([1.0, 0.0, 1.0, 1.0]), np.full((4, 4), np.nan),
                                       np.eye(3)], ids=["singular", "nan", "shape"])
def test_transformed_boxes_refuse_bad_transforms(transform):
    with pytest.raises(ValueError, match="transform"):
        Scene().add_box([0, 0, 0], [1, 1, 1], transform)


@pytest.mark.parametrize("method, args, name", [
    ("add_sphere", ([0, 0, 0], -1.0), "radius"),
    ("add_sphere", ([np.nan, 0, 0], 1.0), "center"),
    ("add_plane", ([0, 0, 0], [0, 0, 0]), "normal"),
    ("add_disk", ([0, 0, 0], [0, 0, 1], 0.0), "radius"),
    ("add_box", ([0, 0, 0], [1, -1, 1]), "hi"),
    ("add_cylinder", ([0, 0, 0], [0, 0, 0], 1.0), "p1"),
    ("add_cone", ([0, 0, 0], [0, 0, 0], 1.0), "apex"),
])
def test_bad_analytic_shapes_raise_value_errors_naming_the_argument(method, args, name):
    scene = Scene()
    with pytest.raises(ValueError, match=name):
        getattr(scene, method)(*args)
    assert len(scene) == 0


@pytest.mark.parametrize("kwargs, name", [
    (dict(dtype="float16"), "dtype"),
    (dict(dtype="int32"), "dtype"),
    (dict(dtype="double precision"), "dtype"),
    (dict(bins=1), "bins"),
    (dict(bins=100000), "bins"),
    (dict(max_leaf_size=0), "max_leaf_size"),
    (dict(traversal_cost=-1.0), "traversal_cost"),
    (dict(traversal_cost=np.inf), "traversal_cost"),
    (dict(intersection_cost=np.nan), "intersection_cost"),
    (dict(intersection_cost=0.0), "intersection_cost"),
])
def test_bad_scene_parameters_raise_value_errors_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Scene(**kwargs)


@pytest.mark.parametrize("kwargs, name", [
    (dict(bins="x"), "bins"),
    (dict(bins=2.5), "bins"),
    (dict(max_leaf_size="4"), "max_leaf_size"),
    (dict(traversal_cost="1"), "traversal_cost"),
])
def test_non_numeric_build_parameters_are_named(kwargs, name):
    """Regression: BuildParams converted with int() before validating, so Scene(bins='x')
    raised "invalid literal for int()" without naming bins."""
    with pytest.raises(ValueError, match=name):
        Scene(**kwargs)


@pytest.mark.parametrize("points", [np.zeros((2, 2)), np.zeros(3), [[np.nan, 0, 0]],
                                    [[0, np.inf, 0]], [["a", "b", "c"]]],
                         ids=["shape", "1d", "nan", "inf", "strings"])
def test_contains_refuses_bad_points(dtype, points):
    with pytest.raises(ValueError, match="points"):
        small_scene(dtype).contains(points)


def test_from_trimesh_and_from_file_refuse_what_they_cannot_read(tmp_path):
    with pytest.raises(ValueError, match="mesh_or_scene"):
        Scene.from_trimesh(42)
    with pytest.raises(ValueError, match="path .*missing.obj.*could not read"):
        Scene.from_file(tmp_path / "missing.obj")
    garbage = tmp_path / "garbage.obj"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(ValueError, match="path .*garbage.obj"):
        Scene.from_file(garbage)
    for not_a_path in (None, 3, b"mesh.obj"):
        with pytest.raises(ValueError, match="path must be a file path"):
            Scene.from_file(not_a_path)


# ---------------------------------------------------------------------- no NaN hits


def awkward_scene(dtype):
    """Degenerate and extreme, but valid, geometry (a triangle of 1e30, whose edge functions
    overflow float32, has a test of its own below)."""
    scene = Scene(dtype=dtype)
    scene.add_mesh([[0, 0, 0], [1, 0, 0], [2, 0, 0],  # collinear
                    [0, 1, 0], [0, 1, 0], [1, 1, 1],  # repeated vertex
                    [5, 5, 5], [5 + 1e-30, 5, 5], [5, 5 + 1e-30, 5],  # vanishing area
                    [-1e15, -1e15, 10], [1e15, -1e15, 10], [0, 1e15, 10]],  # huge
                   np.arange(12).reshape(4, 3))
    scene.add_sphere([0, 0, 0], 1e-30)
    scene.add_sphere([3, 0, 0], 1e-3)
    scene.add_box([0, -1, -1], [1e-30, 1, 1])
    scene.add_disk([0, 0, -3], [0, 0, 1], 1e-20)
    scene.add_cylinder([0, 0, 0], [0, 0, 1e-20], 2.0)
    scene.add_cone([7, 7, 0], [7, 7, 1e-6], 1.0)
    scene.add_plane([0, 0, -1e30], [1e-20, 0, 1])
    proto = scene.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], visible=False)
    scene.add_instance(proto, np.diag([1e-6, 1e6, 1.0, 1.0]))
    return scene


def awkward_rays(rng, count=3000):
    origins = rng.normal(size=(count, 3)) * rng.choice([1e-30, 1e-3, 1.0, 1e3, 1e30],
                                                         size=(count, 1))
    directions = rng.normal(size=(count, 3)) * rng.choice([1e-30, 1e-10, 1.0, 1e10, 1e30],
                                                            size=(count, 1))
    # axis-aligned directions, and components flushed to signed zeros
    axis = rng.random(count) < 0.3
    directions[axis] = np.eye(3)[rng.integers(0, 3, axis.sum())] * rng.choice([-1, 1], (
        axis.sum(), 1))
    directions[rng.random((count, 3)) < 0.1] = -0.0
    directions[~np.any(directions != 0, axis=1)] = [0, 0, 1]
    # aimed at the objects too
    targets = np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0], [0, 0, -3], [5, 5, 5], [0, 0, 10]])
    aim = rng.random(count) < 0.3
    directions[aim] = targets[rng.integers(0, len(targets), aim.sum())] - origins[aim]
    directions[~np.any(directions != 0, axis=1)] = [0, 0, 1]
    return origins, directions


@pytest.mark.parametrize("test", ["watertight", "moller", "geometric"])
def test_nan_never_comes_back_as_a_hit(dtype, test):
    rng = np.random.default_rng(9)
    scene = awkward_scene(dtype)
    origins, directions = awkward_rays(rng)
    if dtype == "float32":
        keep = np.all(np.isfinite(origins.astype(np.float32)) & np.isfinite(
            directions.astype(np.float32)), axis=1) & np.any(
            directions.astype(np.float32) != 0, axis=1)
        origins, directions = origins[keep], directions[keep]
    bounds = [(0.0, np.inf), (-np.inf, np.inf), (1e-3, 1e30), (np.inf, np.inf)]
    for method in ("precise", "geometric", "analytic"):
        for tmin, tmax in bounds:
            kw = dict(triangle_test=test, sphere_method=method)
            hits = scene.intersect(origins, directions, tmin, tmax, **kw)
            hit = hits.geom_id >= 0
            assert not np.isnan(hits.t).any()
            assert np.all(hits.t[~hit] == np.inf) and np.all(hits.prim_id[~hit] == -1)
            assert np.all((hits.t[hit] >= tmin) & (hits.t[hit] <= tmax))
            all_hits = scene.intersect_all(origins, directions, tmin, tmax, **kw)
            assert not np.isnan(all_hits.t).any()
            assert np.all((all_hits.t >= tmin) & (all_hits.t <= tmax))
            occluded = scene.occluded(origins, directions, tmin, tmax, **kw)
            assert np.array_equal(occluded, all_hits.counts > 0)
            assert np.array_equal(hit, all_hits.counts > 0)
        assert not np.isnan(scene.contains(origins[np.abs(origins).max(axis=1) < 1e6])).any()


# ---------------------------------------------------------------------- regressions and bugs


def test_an_instance_of_an_instance_composes_or_is_refused(dtype):
    """Regression: add_instance accepted the id of an instance and ignored that instance's
    transform (the copy landed at ``transform``, not ``transform @`` the instance's)."""
    scene = Scene(dtype=dtype)
    mesh = scene.add_mesh([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], [[0, 1, 2]], visible=False)
    first = scene.add_instance(mesh, _translation(10, 0, 0))
    try:
        second = scene.add_instance(first, _translation(0, 10, 0))
    except ValueError as error:
        assert "geom_id" in str(error)
        return
    hits = scene.intersect([[10, 10, -1], [0, 10, -1]], [[0, 0, 1], [0, 0, 1]])
    # composed: the second copy sits at (10, 10); nothing at (0, 10)
    assert hits.geom_id.tolist() == [second, -1]


@pytest.mark.parametrize("add, name", [
    (lambda s: s.add_mesh([[1e39, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]), "vertices"),
    (lambda s: s.add_sphere([1e39, 0, 0], 1.0), "center"),
    (lambda s: s.add_sphere([0, 0, 0], 1e20), "radius"),
], ids=["mesh-vertices", "sphere-center", "sphere-radius-squared"])
def test_geometry_that_overflows_float32_is_refused(add, name):
    """Regression: a float32 Scene stored vertices or sphere parameters beyond 3.4e38 as inf,
    and the object silently never hit (the batch functions of raycore.primitives refuse the
    same shapes with a ValueError)."""
    scene = Scene(dtype="float32")
    with pytest.raises(ValueError, match=name):
        add(scene)
        scene.build()


def test_a_triangle_whose_arithmetic_overflows_never_gives_a_nan_hit():
    """Regression: in float32, when the watertight test's edge functions overflow (vertices
    near 1e30), det and T are inf, the range test accepted inf <= tmax * inf, and
    t = inf / inf = NaN came back as a hit (from Scene.intersect and intersect_all, and as t
    from the batch function)."""
    scene = Scene(dtype="float32")
    scene.add_mesh([[-1e30, -1e30, 10], [1e30, -1e30, 10], [0, 1e30, 10]], [[0, 1, 2]])
    origins, directions = [[0, 0, 0]], [[0, 0, 1]]
    for tmin, tmax in [(1e-3, 1e30), (-np.inf, np.inf)]:
        hits = scene.intersect(origins, directions, tmin, tmax)
        assert not np.isnan(hits.t).any(), f"t = {hits.t}, geom_id = {hits.geom_id}"
        assert not np.isnan(scene.intersect_all(origins, directions, tmin, tmax).t).any()


def test_surface_fields_at_a_hit_are_never_nan():
    """Regression: a sphere below float32's resolution at distance 1 (its hit point rounds onto
    its centre) gave NaN normal and uv."""
    scene = Scene(dtype="float32")
    scene.add_sphere([0, 0, 0], 1e-8)
    hits = scene.intersect([[0, 0, -1]], [[0, 0, 1]], fields=("uv", "normal"))
    assert hits.geom_id.tolist() == [0]
    assert not np.isnan(hits.normal).any() and not np.isnan(hits.uv).any()
