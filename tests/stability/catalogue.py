"""The catalogue of failure cases: ray sets where ray casting methods are known to fail.

Each :class:`Case` is a scene and a seeded ray set for each precision, with the exact answer of
every ray (from the references in ``tests/primitives``, composed in :mod:`tests.stability.exact`).
:func:`measure` runs one method on one case and counts what it got wrong.  ``tests/stability``
asserts the outcome for the methods that claim it and prints the rest (``pytest -s``);
``benchmarks/speed_accuracy.py`` charts and tabulates the same numbers.

Every coordinate of every case is a float32 value (or is computed in the precision it is run in,
for rays aimed at edge points), so that the exact answer is the answer to the very question each
precision is asked.

Methods and their claims (what the tests assert):

* triangle ``watertight`` (Woop 2013, behind a conservative NaN-safe box test): a ray that starts
  inside a closed mesh hits it (no leaks, whatever the ray); no hit on degenerate triangles or
  rays parallel to a triangle; tiny triangles hit; hit/miss agreement with the exact reference
  on every case below, and a median relative t error of a few units of roundoff.
* sphere ``precise`` (stable quadratic, Hearn–Baker discriminant), and the cylinder and the cone
  (one method each, built the same way): agreement with the exact reference on every ray that
  is *decided* at the precision's resolution — its answer is the same for the shape grown and
  shrunk by ``CLAIM_ULPS`` units of roundoff times (distance / size), the uncertainty that the
  rounding of the ray's own coordinates brings (:func:`tests.stability.exact.decided`).  Rays
  within that band are counted, not asserted.
* triangle ``moller``, ``geometric`` and sphere ``geometric``, ``analytic``: measured only.
"""

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from raycore import Scene
from tests.primitives import sampling
from tests.primitives.triangle_reference import edges, icosphere, rotated, tessellated_box
from tests.stability.exact import decided, mesh_closest, quadric_closest

DTYPES = ("float32", "float64")
TRIANGLE_TESTS = ("watertight", "moller", "geometric")
SPHERE_METHODS = ("precise", "geometric", "analytic")

#: Width of the band of undecided rays for the claims of the analytic shapes, in units of
#: roundoff times (distance from the shape / its size).
CLAIM_ULPS = 16

SHARED_MESHES = Path(__file__).resolve().parents[3] / "shared" / "meshes"


def eps(dtype):
    return float(np.finfo(np.dtype(dtype)).eps)


def f32(values):
    """Values rounded to float32, as float64."""
    return np.asarray(values, np.float64).astype(np.float32).astype(np.float64)


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ----------------------------------------------------------------------------- methods


@dataclass(frozen=True)
class Method:
    """A way of intersecting: ``family`` is "triangle", "sphere" or "quadric" (cylinder and
    cone, one method each)."""

    family: str
    name: str

    @property
    def label(self):
        return self.name if self.family == "quadric" else f"{self.family} {self.name}"

    @property
    def options(self):
        if self.family == "triangle":
            return {"triangle_test": self.name}
        if self.family == "sphere":
            return {"sphere_method": self.name}
        return {}

    @property
    def claims(self):
        """Whether the method claims the outcome asserted on every case of its family."""
        return self.name in ("watertight", "precise") or self.family == "quadric"


METHODS = (
    tuple(Method("triangle", name) for name in TRIANGLE_TESTS)
    + tuple(Method("sphere", name) for name in SPHERE_METHODS)
)
QUADRIC = Method("quadric", "cylinder/cone")


# ----------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class Rays:
    """A case's rays in one precision and their exact answer.

    ``truth`` is the exact nearest t (float64, inf for a miss; NaN for "hits, t not computed");
    ``claimed`` marks the rays on which the claiming methods must agree with it.
    """

    origins: np.ndarray
    directions: np.ndarray
    tmin: np.ndarray
    tmax: np.ndarray
    truth: np.ndarray
    claimed: np.ndarray

    def __len__(self):
        return len(self.origins)


@dataclass(frozen=True, eq=False)
class Case:
    """One failure case.

    Attributes
    ----------
    name : str
        Short identifier (test ids, table rows).
    title : str
        What the rays do.
    family : str
        Which methods run it: "triangle", "sphere" or "quadric".
    panel : str
        "leak": rays aimed at shared edges and vertices from inside closed meshes (and from
        inside a sphere), where a miss is a leak; "reference": the rest.
    geometry : callable
        ``geometry(dtype)``: ("mesh", vertices, faces) or (shape, params) of the scene.
    rays : callable
        ``rays(dtype)`` -> :class:`Rays` (cached).
    """

    name: str
    title: str
    family: str
    panel: str
    geometry: object
    rays: object
    #: whether t is well conditioned on the claimed rays (not for tangent rays), so that the
    #: claiming methods' median relative t error is asserted to be a few units of roundoff
    sharp: bool = True

    def methods(self):
        if self.family == "quadric":
            return (QUADRIC,)
        return tuple(m for m in METHODS if m.family == self.family)

    @functools.cache  # noqa: B019 (cases live as long as the process)
    def scene(self, dtype):
        kind, *args = self.geometry(dtype)
        scene = Scene(dtype=dtype)
        if kind == "mesh":
            scene.add_mesh(*args)
        elif kind == "sphere":
            scene.add_sphere(*args[0])
        elif kind == "cylinder":
            scene.add_cylinder(*args[0])
        else:
            scene.add_cone(*args[0])
        return scene.build()


def _mesh_rays(origins, directions, vertices, faces, tmin=0.0, tmax=np.inf, truth=None):
    count = len(origins)
    if truth is None:
        truth = mesh_closest(origins, directions, vertices, faces, tmin, tmax)
    return Rays(np.asarray(origins, np.float64), np.asarray(directions, np.float64),
                np.full(count, tmin), np.full(count, tmax), truth, np.ones(count, bool))


def _cached(function):
    """Cache a ``rays(dtype)`` builder (the exact answers take a second or two)."""
    return functools.cache(function)


# -- closed meshes, rays through shared edges and vertices from inside

#: Points inside every closed test mesh around the origin (radius >= 0.5).
ORIGINS_INSIDE = np.array([[0, 0, 0], [0.125, -0.0625, 0.25], [-0.3125, 0.1875, -0.125]])


def edge_targets(vertices, faces, levels=2, rng=None, count=None):
    """Points ``p + k/2**levels (q - p)`` on every edge (computed in the vertices' precision)
    and the vertices; a seeded subsample of ``count`` of them if given."""
    pairs = edges(faces)
    if rng is not None and count is not None and count < len(pairs) * (2**levels - 1):
        pairs = pairs[rng.choice(len(pairs), count, replace=False)]
        vertices_used = vertices[np.unique(pairs)][: count // 4]
    else:
        vertices_used = vertices
    p, q = vertices[pairs[:, 0]], vertices[pairs[:, 1]]
    k = (np.arange(1, 2**levels)[:, None, None] / 2.0**levels).astype(vertices.dtype)
    points = (p + k * (q - p)).reshape(-1, 3)
    return np.concatenate([points, vertices_used])


def _edge_case(name, title, make_mesh, origins=ORIGINS_INSIDE, count=None, exact_truth=True):
    """Rays from ``origins`` through every edge point and vertex, computed in ``dtype``."""

    def geometry(dtype):
        vertices, faces = make_mesh()
        return "mesh", vertices.astype(dtype).astype(np.float64), faces

    @_cached
    def rays(dtype):
        _, vertices, faces = geometry(dtype)
        rng = np.random.default_rng(5)
        targets = edge_targets(vertices.astype(dtype), faces, rng=rng, count=count)
        o = np.repeat(np.asarray(origins, dtype), len(targets), axis=0)
        d = (np.tile(targets, (len(origins), 1)) - o).astype(np.float64)
        o = o.astype(np.float64)
        # from inside a closed mesh every ray hits; t is only computed where affordable
        truth = None if exact_truth else np.full(len(o), np.nan)
        return _mesh_rays(o, d, vertices, faces, truth=truth)

    return Case(name, title, "triangle", "leak", geometry, rays)


@functools.cache
def shared_mesh(name):
    """(vertices, faces) of a mesh in ../shared/meshes, or None when it is not there."""
    path = SHARED_MESHES / f"{name}.obj"
    if not path.exists():
        return None
    mesh = trimesh.load(path, force="mesh", process=False)
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def nefertiti_inside():
    """Points well inside nefertiti (a closed scan): its centroid and two more along its axis."""
    vertices, faces = shared_mesh("nefertiti")
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    center = f32(mesh.center_mass)
    extent = vertices.max(axis=0) - vertices.min(axis=0)
    return f32(center + np.array([[0, 0, 0], [0, -0.15, 0], [0, 0.1, 0]]) * extent)


def _grid_line_rays(in_faces):
    """Axis-aligned rays along the grid lines of ``tessellated_box(4)`` (ticks every 0.5).

    Not ``in_faces``: from inside points on grid lines along ±x, ±y, ±z (two zero direction
    components, crossing a face at a vertex or an edge), and from outside along grid lines onto
    the faces.  ``in_faces``: rays lying in a face's plane, along a grid line or a diagonal,
    that touch the box along its surface (entering at the box's own edges): the exact answer
    counts the touch, and so does the watertight test.
    """
    ticks = np.array([-0.5, 0.0, 0.5])
    all_ticks = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
    origins, directions = [], []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for sign in (-1.0, 1.0):
            d = np.zeros(3)
            d[axis] = sign
            if not in_faces:
                for s in ticks:
                    for t in ticks:
                        for start in (0.0, -2.0 * sign, -1.5 * sign):
                            o = np.zeros(3)
                            o[axis], o[u], o[v] = start, s, t
                            origins.append(o)
                            directions.append(d)
                continue
            for s in all_ticks:
                for t in all_ticks:
                    if abs(s) == 1 or abs(t) == 1:
                        o = np.zeros(3)
                        o[axis], o[u], o[v] = -1.5 * sign, s, t
                        origins.append(o)
                        directions.append(d)
            for face in (-1.0, 1.0):
                for t in ticks:
                    for lean in (1.0, -1.0):
                        o = np.zeros(3)
                        o[axis], o[u], o[v] = -1.5 * sign, face, t - lean * 0.5 * sign
                        diagonal = d.copy()
                        diagonal[v] = lean
                        origins.append(o)
                        directions.append(diagonal)
    return np.array(origins), np.array(directions)


def _grid_lines_case(in_faces):
    def geometry(dtype):
        return ("mesh", *tessellated_box(4))

    @_cached
    def rays(dtype):
        _, vertices, faces = geometry(dtype)
        o, d = _grid_line_rays(in_faces)
        return _mesh_rays(o, d, vertices, faces)

    if in_faces:
        return Case("face-planes-box", "rays lying in the face planes of a tessellated box, "
                    "along grid lines and diagonals: they touch it along its surface",
                    "triangle", "reference", geometry, rays)
    return Case("grid-lines-box", "axis-aligned rays along the grid lines of a tessellated box "
                "(two zero direction components), from inside and from outside",
                "triangle", "leak", geometry, rays)


def _in_plane_case():
    """A flat tessellated square in z = 0 and rays parallel to it: in its plane or 2**-10 off."""
    def geometry(dtype):
        vertices, faces = tessellated_box(4)
        top = np.all(vertices[faces][:, :, 2] == 1.0, axis=1)
        vertices = vertices.copy()
        vertices[:, 2] -= 1.0  # the top face now lies in z = 0
        return "mesh", vertices, faces[top]

    @_cached
    def rays(dtype):
        _, vertices, faces = geometry(dtype)
        rng = np.random.default_rng(11)
        count = 4000
        angle = rng.uniform(0, 2 * np.pi, count)
        d = np.stack([np.cos(angle), np.sin(angle), np.zeros(count)], axis=1)
        target = rng.integers(-8, 9, (count, 3)) / 8.0
        target[:, 2] = np.where(rng.random(count) < 0.75, 0.0, 2.0**-10)
        o = f32(target - 2.5 * d)
        d = f32(d)
        return _mesh_rays(o, d, vertices, faces)

    return Case("in-plane", "rays parallel to triangles: in their plane and 2^-10 off it",
                "triangle", "reference", geometry, rays)


def _degenerate_case():
    """Collinear and repeated-vertex triangles on a 2**-6 grid, rays exactly through them."""
    rng = np.random.default_rng(13)
    m = 400
    a, b = (rng.integers(-64, 65, (m, 3)) / 64.0 for _ in range(2))
    repeated = rng.random(m) < 0.5
    c = np.where(repeated[:, None], np.where(rng.random((m, 1)) < 0.5, a, b), 2 * b - a)
    vertices = np.concatenate([a, b, c])
    faces = np.arange(3 * m).reshape(3, m).T.copy()

    def geometry(dtype):
        return "mesh", vertices, faces

    @_cached
    def rays(dtype):
        rng = np.random.default_rng(14)
        pick = rng.integers(0, m, 4000)
        weight = rng.integers(0, 9, (4000, 1)) / 8.0  # on the segment a-b, ends included
        target = a[pick] + weight * (b[pick] - a[pick])
        o = rng.integers(-32, 33, (4000, 3)) / 8.0
        d = target - o
        d[np.all(d == 0, axis=1), 0] = 1.0
        return _mesh_rays(o, d, vertices, faces)

    return Case("degenerate", "degenerate triangles (collinear, repeated vertex), rays exactly "
                "through them", "triangle", "reference", geometry, rays)


def _tiny_case():
    """500 well-shaped triangles with legs of about 1e-5 in [-1, 1]^3, rays aimed inside."""
    rng = np.random.default_rng(17)
    m = 500
    a = f32(rng.uniform(-1, 1, (m, 3)))
    e1 = sampling.unit_vectors(rng, m)
    e2 = unit(np.cross(e1, sampling.unit_vectors(rng, m)))
    angle = rng.uniform(np.pi / 3, 2 * np.pi / 3, (m, 1))
    legs = rng.uniform(0.5e-5, 2e-5, (m, 2))
    b = f32(a + legs[:, :1] * e1)
    c = f32(a + legs[:, 1:] * (np.cos(angle) * e1 + np.sin(angle) * e2))
    vertices = np.concatenate([a, b, c])
    faces = np.arange(3 * m).reshape(3, m).T.copy()

    def geometry(dtype):
        return "mesh", vertices, faces

    @_cached
    def rays(dtype):
        rng = np.random.default_rng(18)
        count = 4000
        pick = rng.integers(0, m, count)
        w = rng.uniform(0.1, 0.45, (count, 2))
        target = a[pick] + w[:, :1] * (b[pick] - a[pick]) + w[:, 1:] * (c[pick] - a[pick])
        # from 0.5 to 3 away, at least 30 degrees off the triangle's plane (a grazing ray near
        # an edge is decided by rounding, whatever the triangle's size)
        normal = unit(np.cross(b[pick] - a[pick], c[pick] - a[pick]))
        lean = sampling.unit_vectors(rng, count)
        lean = unit(lean - np.sum(lean * normal, axis=1, keepdims=True) * normal)
        side = rng.choice([-1.0, 1.0], (count, 1))
        away = unit(side * normal + rng.uniform(0, 1.5, (count, 1)) * lean)
        o = f32(target + rng.uniform(0.5, 3, (count, 1)) * away)
        return _mesh_rays(o, f32(target - o), vertices, faces)

    return Case("tiny", "triangles with legs of 1e-5, rays aimed inside them", "triangle",
                "reference", geometry, rays)


def _offset_case(offset):
    """An icosphere of radius 1 around (offset, -offset/2, offset/4), on the float32 grid there,
    with rays from inside it to points inside its triangles, to its vertices and edge
    midpoints."""
    center = f32(np.array([1.0, -0.5, 0.25]) * offset)
    grid = float(np.spacing(np.float32(offset)))
    vertices, faces = icosphere(2, grid=grid, center=center)

    def geometry(dtype):
        return "mesh", vertices, faces

    @_cached
    def rays(dtype):
        rng = np.random.default_rng(int(offset))
        count = 3000
        face = faces[rng.integers(0, len(faces), count)]
        u = rng.uniform(0.1, 0.8, (count, 1))
        v = rng.uniform(0.1, 0.9 - u, (count, 1))
        a, b, c = vertices[face[:, 0]], vertices[face[:, 1]], vertices[face[:, 2]]
        targets = np.concatenate([a + u * (b - a) + v * (c - a),
                                  edge_targets(vertices, faces, levels=1)])
        inside = center + np.round(ORIGINS_INSIDE / grid) * grid
        o = f32(inside[rng.integers(0, len(inside), len(targets))])
        return _mesh_rays(o, f32(f32(targets) - o), vertices, faces)

    return Case(f"offset-{offset:.0e}".replace("+0", ""),
                f"a closed mesh of radius 1 at {offset:.0e} from the origin, rays from inside",
                "triangle", "reference", geometry, rays)


# -- analytic shapes


def _quadric_rays(shape, params, o, d, size=1.0, round32=True):
    """Rays at one analytic shape (rounded to float32 values unless not ``round32``) with their
    truth and claimed rays."""
    count = len(o)
    if round32:
        o, d = f32(o), f32(d)
    tmin, tmax = np.zeros(count), np.full(count, np.inf)
    truth = quadric_closest(shape, o, d, params, tmin, tmax)
    center = np.asarray(params[0], np.float64)
    reach = (np.linalg.norm(o - center, axis=1).max() + size) / size

    def claimed(dtype):
        return decided(shape, o, d, params, tmin, tmax, CLAIM_ULPS * eps(dtype) * reach)

    return o, d, tmin, tmax, truth, claimed


def _analytic_case(name, title, shape, params, make_rays, panel="reference", size=1.0,
                   per_dtype=False, sharp=True):
    """A case of one analytic shape; ``make_rays()`` (or ``make_rays(dtype)`` if
    ``per_dtype``) gives the origins and directions."""
    family = "sphere" if shape == "sphere" else "quadric"

    def geometry(dtype):
        return shape, params

    @functools.cache
    def shared(dtype):
        return _quadric_rays(shape, params, *make_rays(*((dtype,) if per_dtype else ())),
                             size=size, round32=dtype != "float64")

    @_cached
    def rays(dtype):
        o, d, tmin, tmax, truth, claimed = shared(dtype if per_dtype else None)
        return Rays(o, d, tmin, tmax, truth, claimed(dtype))

    return Case(name, title, family, panel, geometry, rays, sharp)


FAR_CENTER = np.array([3.0, -2.0, 1.0])


def _far_sphere_rays(distance, radius=1.0, center=FAR_CENTER, seed=0, count=4000):
    """Rays from ``distance`` away aimed across a disk of 1.5 radii facing them; a fifth within
    about 1e-4 radii of the silhouette.  Direction lengths vary from 2**-3 to 2**3."""
    rng = np.random.default_rng(seed)
    view = sampling.unit_vectors(rng, count)
    across = sampling.unit_vectors(rng, count)
    across = unit(across - np.sum(across * view, axis=1, keepdims=True) * view)
    grazing = rng.random(count) < 0.2
    offset = np.where(grazing, 1 + rng.normal(scale=1e-4, size=count),
                      1.5 * np.sqrt(rng.random(count)))
    origins = center + distance * view
    directions = (center + radius * offset[:, None] * across - origins) / distance
    directions *= 2.0 ** rng.uniform(-3, 3, size=(count, 1))
    return origins, directions


def _grazing_sphere_rays():
    rng = np.random.default_rng(23)
    normals = sampling.unit_vectors(rng, 4000)
    return sampling.tangent_rays(rng, FAR_CENTER + normals, normals, 1.0)


def _inside_sphere_rays(center, radius, seed=29, count=4000):
    """From inside a sphere (after rounding to float32), some within a few ulps of its
    surface, in random directions."""
    rng = np.random.default_rng(seed)
    depth = 1 - 2.0 ** -rng.uniform(1, 12, (2 * count, 1))
    o = f32(center + radius * depth * sampling.unit_vectors(rng, 2 * count))
    inside = np.sum((o - center) ** 2, axis=1) < radius**2 * (1 - 1e-12)
    o = o[inside][:count]
    return o, sampling.random_directions(rng, len(o))


def _cylinder_rays(p0, p1, radius, seed=31, count=4000):
    """Grazing rays at a cylinder: a quarter each tangent to the side, along the axis at
    radius r (lying in the side), along the axis near the rim, and nearly parallel to a cap
    across its rim."""
    rng = np.random.default_rng(seed)
    w = unit(p1 - p0)
    e1 = unit(np.cross(w, [0.3, 0.5, 0.7]))
    e2 = np.cross(w, e1)
    angle = rng.uniform(0, 2 * np.pi, (count, 1))
    radial = np.cos(angle) * e1 + np.sin(angle) * e2
    along = rng.uniform(0, 1, (count, 1)) * (p1 - p0)
    q = count // 4
    side = p0 + along + radius * radial
    o, d = sampling.tangent_rays(rng, side[:q], radial[:q], radius)
    on_side = p0 + radius * radial[q:2 * q] - 3 * (p1 - p0)
    near_rim = (p0 + radius * (1 + rng.normal(scale=1e-5, size=(q, 1))) * radial[2 * q:3 * q]
                - 3 * (p1 - p0))
    cap_dirs = radial[3 * q:] + rng.normal(scale=1e-5, size=(count - 3 * q, 1)) * w
    cap = p1 - radius * 3 * cap_dirs
    return (np.concatenate([o, on_side, near_rim, cap]),
            np.concatenate([d, np.tile(p1 - p0, (2 * q, 1)), cap_dirs]))


def _cone_rays(base, apex, radius, seed=37, count=4000):
    """Grazing rays at a cone: a third tangent to the side, a third along generators (parallel
    to the surface: a = 0), some exactly in the surface, and a third grazing the base's rim."""
    rng = np.random.default_rng(seed)
    w = unit(apex - base)
    e1 = unit(np.cross(w, [0.3, 0.5, 0.7]))
    e2 = np.cross(w, e1)
    angle = rng.uniform(0, 2 * np.pi, (count, 1))
    radial = np.cos(angle) * e1 + np.sin(angle) * e2
    rim = base + radius * radial
    height = np.linalg.norm(apex - base)
    normals = unit(height * radial + radius * w)
    third = count // 3
    fraction = rng.random((count, 1))
    side = apex + fraction * (rim - apex)
    o1, d1 = sampling.tangent_rays(rng, side[:third], normals[:third], height)
    generators = (rim - apex)[third:2 * third]
    lift = np.where(rng.random((third, 1)) < 0.5, 0.0, rng.normal(scale=0.05, size=(third, 1)))
    o2 = apex + lift * normals[third:2 * third] - 2 * generators
    # tangent to the rim circle, in the base plane or leaning out of it a little
    tangent = np.cross(w, radial[2 * third:]) + rng.normal(scale=1e-3, size=(count - 2 * third,
                                                                              1)) * w
    o3 = rim[2 * third:] - 2 * tangent
    return np.concatenate([o1, o2, o3]), np.concatenate([d1, generators, tangent])


def _cone_apex_rays(base, apex, radius, dtype, count=4000):
    """From points well inside a cone towards points near its apex, 1e-9 ... 1e-5 away for
    float32 and 1e-17 ... 1e-13 for float64 (targets rounded to the precision): every ray
    leaves through the side within about that distance of the apex."""
    rng = np.random.default_rng(53)
    w = unit(apex - base)
    height = np.linalg.norm(apex - base)
    e1 = unit(np.cross(w, [0.3, 0.5, 0.7]))
    e2 = np.cross(w, e1)
    angle = rng.uniform(0, 2 * np.pi, (count, 1))
    along = rng.uniform(0.05, 0.8, (count, 1))
    out = rng.uniform(0, 0.8, (count, 1)) * radius * (1 - along)
    o = f32(base + along * height * w + out * (np.cos(angle) * e1 + np.sin(angle) * e2))
    low = -9 if dtype == "float32" else -17
    target = apex + 10.0 ** rng.uniform(low, low + 4, (count, 1)) * sampling.unit_vectors(
        rng, count)
    if dtype == "float32":
        return o, f32(target) - o
    return o, target - o


def _cone_generator_rays(count=1200):
    """An axis-aligned cone with r = h, so that rays along (±1, 0, -1), (0, ±1, -1) are exactly
    parallel to generators (a = 0 exactly), on the surface and off it."""
    rng = np.random.default_rng(41)
    d = np.array([[1, 0, -1], [-1, 0, -1], [0, 1, -1], [0, -1, -1]], float)[
        rng.integers(0, 4, count)]
    lift = rng.integers(-4, 5, (count, 1)) / 16.0
    shift = (rng.integers(-4, 5, (count, 1)) / 16.0) * np.cross(d, [0, 0, 1])
    o = np.array([0, 0, 1.0]) - 2 * d + lift * np.array([0, 0, 1.0]) + shift
    return o, d


def _scaled_lengths(origins, directions, seed):
    """Directions scaled by 2**k, k in [-60, 60] (exact; their squares stay normal floats)."""
    rng = np.random.default_rng(seed)
    return origins, directions * 2.0 ** rng.integers(-60, 61, (len(directions), 1))


def _lengths_mesh_case():
    def geometry(dtype):
        vertices, faces = tessellated_box(4)
        return "mesh", rotated(vertices).astype(np.float32).astype(np.float64), faces

    @_cached
    def rays(dtype):
        _, vertices, faces = geometry(dtype)
        rng = np.random.default_rng(59)
        o = f32(3 * sampling.unit_vectors(rng, 3000))
        d = f32(1.2 * sampling.unit_vectors(rng, 3000)) - o
        return _mesh_rays(*_scaled_lengths(o, d, 61), vertices, faces)

    return Case("lengths-mesh", "direction lengths from 2^-60 to 2^60, at a rotated box",
                "triangle", "reference", geometry, rays)


def _lengths_rays(seed):
    rng = np.random.default_rng(seed)
    o = FAR_CENTER + 3 * sampling.unit_vectors(rng, 3000)
    d = FAR_CENTER + 1.2 * sampling.unit_vectors(rng, 3000) - o
    return _scaled_lengths(f32(o), f32(d), seed + 1)


def _cases():
    cases = [
        _edge_case("edges-icosphere-exact", "rays through edge points and vertices of a closed "
                   "icosphere (1280 triangles; exact edge points)",
                   lambda: icosphere(3, grid=2.0**-12)),
        _edge_case("edges-icosphere", "the same with full-mantissa vertices (edge points "
                   "rounded)", lambda: icosphere(3)),
        _edge_case("edges-box-rotated", "rays through edge points and vertices of a rotated "
                   "tessellated box", lambda: (rotated(tessellated_box(4)[0]),
                                               tessellated_box(4)[1])),
        _grid_lines_case(in_faces=False),
        _grid_lines_case(in_faces=True),
        _in_plane_case(),
        _degenerate_case(),
        _tiny_case(),
    ]
    cases += [_offset_case(offset) for offset in (1e3, 1e4, 1e5, 1e6)]
    cases.append(_lengths_mesh_case())
    for exponent in (4, 5, 6):
        distance = 10.0**exponent
        cases.append(_analytic_case(
            f"sphere-far-1e-{exponent}", f"a unit sphere seen from {distance:.0e} (radius / "
            f"distance = 1e-{exponent}), a fifth of the rays within 1e-4 of the silhouette",
            "sphere", (FAR_CENTER, 1.0),
            functools.partial(_far_sphere_rays, distance, seed=exponent)))
    tiny_center = np.array([0.5, 0.25, -0.125])
    cases += [
        _analytic_case("sphere-tiny-2^-20", "a sphere of radius 2^-20 seen from 2^-16 ... 1",
                       "sphere", (tiny_center, 2.0**-20),
                       lambda: _far_sphere_rays(2.0**-16, 2.0**-20, tiny_center, seed=43),
                       size=2.0**-20),
        _analytic_case("sphere-tiny-2^-60", "a sphere of radius 2^-60 at the origin, seen from "
                       "2^-56", "sphere", (np.zeros(3), 2.0**-60),
                       lambda: _far_sphere_rays(2.0**-56, 2.0**-60, np.zeros(3), seed=47),
                       size=2.0**-60),
        _analytic_case("lengths-sphere", "direction lengths from 2^-60 to 2^60, at a unit "
                       "sphere", "sphere", (FAR_CENTER, 1.0), lambda: _lengths_rays(67)),
        _analytic_case("sphere-grazing", "rays tangent to a unit sphere from 1.5 to 6 radii",
                       "sphere", (FAR_CENTER, 1.0), _grazing_sphere_rays, sharp=False),
        _analytic_case("sphere-inside-1e4", "rays from inside a unit sphere 1e4 from the origin, "
                       "some within ulps of its surface", "sphere",
                       (f32(np.array([1e4, -1e4, 1e4])), 1.0),
                       lambda: _inside_sphere_rays(f32(np.array([1e4, -1e4, 1e4])), 1.0),
                       panel="leak"),
    ]
    p0, p1 = np.array([1.0, -1.0, 0.5]), np.array([1.5, 0.25, 2.0])
    base, apex = np.array([-0.5, 0.75, 0.25]), np.array([0.25, 1.5, 1.75])
    cases += [
        _analytic_case("cylinder-grazing", "a tilted cylinder: tangent rays, rays along its "
                       "side, along the axis near the rim, and nearly parallel to a cap",
                       "cylinder", (p0, p1, 0.75), lambda: _cylinder_rays(p0, p1, 0.75),
                       size=0.75, sharp=False),
        _analytic_case("cone-grazing", "a tilted cone: tangent rays, rays along generators "
                       "(parallel to the surface), rays grazing the base's rim", "cone",
                       (base, apex, 0.5), lambda: _cone_rays(base, apex, 0.5), size=0.5,
                       sharp=False),
        _analytic_case("cone-apex-inside", "rays from inside a tilted cone leaving within a few "
                       "units of roundoff of its apex (1e-9 ... 1e-5 in float32, 1e-17 ... "
                       "1e-13 in float64)", "cone", (base, apex, 0.5),
                       functools.partial(_cone_apex_rays, base, apex, 0.5), panel="leak",
                       size=0.5, per_dtype=True),
        _analytic_case("lengths-cone", "direction lengths from 2^-60 to 2^60, at a cone",
                       "cone", (FAR_CENTER - [0, 0, 1.0], FAR_CENTER + [0, 0, 1.0], 1.0),
                       lambda: _lengths_rays(71)),
        _analytic_case("cone-generators", "rays exactly parallel to generators of an axis-"
                       "aligned cone (a = 0), in its surface and off it", "cone",
                       (np.zeros(3), np.array([0, 0, 1.0]), 1.0), _cone_generator_rays),
    ]
    return cases


CASES = _cases()


def nefertiti_case(count=None):
    """Leak rays through nefertiti's edges and vertices from inside it (None when the shared
    meshes are not there).  ``count`` edges subsampled (seeded); t is not computed."""
    if shared_mesh("nefertiti") is None:
        return None
    return _edge_case("edges-nefertiti", "rays through edge points and vertices of nefertiti "
                      "(a closed scan, 100k triangles) from inside",
                      lambda: shared_mesh("nefertiti"), origins=nefertiti_inside(), count=count,
                      exact_truth=False)


# ----------------------------------------------------------------------------- measuring


@dataclass
class Outcome:
    """What one method got wrong on one case's rays."""

    rays: int
    leaks: int  # the exact answer hits, the method misses
    spurious: int  # the exact answer misses, the method hits
    nan: int  # t = NaN returned
    claimed: int  # rays the claim covers
    claimed_wrong: int  # hit/miss disagreements among them
    errors: np.ndarray  # relative t errors over common hits with a computed exact t
    claimed_errors: np.ndarray  # the same over the claimed rays

    @property
    def wrong(self):
        return self.leaks + self.spurious + self.nan

    @property
    def disagreement(self):
        return self.wrong / self.rays

    @property
    def leak_rate(self):
        return self.leaks / self.rays

    @property
    def median_error(self):
        return float(np.median(self.errors)) if len(self.errors) else float("nan")

    def describe(self):
        return (f"disagree {100 * self.disagreement:.3f} % (leaks {self.leaks}, spurious "
                f"{self.spurious}, NaN {self.nan}); claimed {self.claimed} rays, wrong "
                f"{self.claimed_wrong}; median rel t error {self.median_error:.1e}")


def compare(t, rays):
    """Count what the answers ``t`` (inf on a miss) got wrong against ``rays.truth``."""
    t = np.asarray(t, np.float64)
    nan = np.isnan(t)
    hit = np.isfinite(t)
    truth_hit = ~np.isinf(rays.truth)  # NaN truth: hits, t not computed
    wrong = (hit != truth_hit) | nan
    both = hit & np.isfinite(rays.truth)
    scale = np.abs(rays.truth[both])
    errors = np.abs(t[both] - rays.truth[both]) / np.where(scale > 0, scale, 1.0)
    return Outcome(
        rays=len(t),
        leaks=int(np.sum(truth_hit & ~hit & ~nan)),
        spurious=int(np.sum(~truth_hit & hit)),
        nan=int(nan.sum()),
        claimed=int(rays.claimed.sum()),
        claimed_wrong=int(np.sum(wrong & rays.claimed)),
        errors=errors,
        claimed_errors=errors[rays.claimed[both]],
    )


def run(case, method, dtype):
    """``Scene.intersect`` of the case's rays with ``method`` in ``dtype``: the hits."""
    rays = case.rays(dtype)
    return case.scene(dtype).intersect(rays.origins, rays.directions, rays.tmin, rays.tmax,
                                       **method.options)


def measure(case, method, dtype):
    """:class:`Outcome` of ``method`` in ``dtype`` on ``case``."""
    return compare(run(case, method, dtype).t, case.rays(dtype))


def measure_anchor(case, anchor_class, limit=None):
    """:class:`Outcome` of an anchor (``benchmarks.anchors``: float32 rays, tmin = 0) on a mesh
    case, on the first ``limit`` rays."""
    _, vertices, faces = case.geometry("float32")
    rays = case.rays("float32")
    if limit is not None and limit < len(rays):
        rows = np.random.default_rng(3).choice(len(rays), limit, replace=False)
        rays = Rays(*(x[rows] for x in (rays.origins, rays.directions, rays.tmin, rays.tmax,
                                        rays.truth, rays.claimed)))
    anchor = anchor_class(vertices.astype(np.float32), faces)
    origins, directions = rays.origins, rays.directions
    if anchor_class.name != "trimesh":
        origins, directions = origins.astype(np.float32), directions.astype(np.float32)
    t, _ = anchor.closest(origins, directions)
    return compare(t, rays)


# ----------------------------------------------------------------------------- secondary rays

#: Where the spawning surface lies: (center, radius) of a sphere (analytic for the sphere
#: methods, an icosphere of 1280 triangles for the triangle tests), from near the origin to
#: 1e6 away; "box-surface": points exactly on the faces of a tessellated box (triangles only): ray
#: origins that lie exactly on a surface.
SPAWN_PLACES = {
    "near the origin": ((0.0, 0.0, 0.0), 1.0),
    "at 1e4": ((1e4, -1e4, 1e4), 100.0),
    "at 1e6": ((-1e6, 1e6, 1e6), 1e4),
    "box-surface": None,
}
#: How the secondary rays start: from the hit point with tmin = 0; from the hit point with a
#: fixed tmin = 1e-4 (unit directions); from raycore.offset_ray_origin with tmin = 0.
SPAWN_STRATEGIES = ("tmin = 0", "tmin = 1e-4", "offset_ray_origin")


@functools.cache
def _spawn_scene(family, dtype, place):
    scene = Scene(dtype=dtype)
    if place == "box-surface":
        scene.add_mesh(*tessellated_box(4))
        return scene.build()
    center, radius = SPAWN_PLACES[place]
    if family == "sphere":
        scene.add_sphere(center, radius)
    else:
        vertices, faces = icosphere(3, radius=radius, center=center)
        scene.add_mesh(vertices, faces)
    return scene.build()


def _hemisphere(rng, normals, outward, lean=0.0):
    """Random unit directions on the outer (or inner) side of unit ``normals``, at least
    ``lean / (1 + lean)`` off the surface in cosine."""
    directions = sampling.unit_vectors(rng, len(normals))
    side = np.sign(np.sum(directions * normals, axis=1, keepdims=True)) * (1 if outward else -1)
    directions = directions * side + lean * normals * (1 if outward else -1)
    return unit(directions)


@functools.cache
def _spawn_points(family, dtype, place, count=2000):
    """Points on the surface, their unit normals and the surface's size."""
    rng = np.random.default_rng(73)
    scene = _spawn_scene(family, dtype, place)
    if place == "box-surface":
        # exactly on the faces of [-1, 1]^3, on a 2**-8 grid, on the triangles' edges and
        # vertices too, an eighth or more away from the box's edges (where a ray entering
        # through one face may leave at once through the next)
        axis = rng.integers(0, 3, count)
        side = rng.choice([-1.0, 1.0], count)
        points = rng.integers(-224, 225, (count, 3)) / 256.0
        points[np.arange(count), axis] = side
        normals = np.zeros((count, 3))
        normals[np.arange(count), axis] = side
        return points.astype(dtype), normals.astype(dtype), 1.0
    center, radius = np.asarray(SPAWN_PLACES[place][0]), SPAWN_PLACES[place][1]
    origins = center + 3 * radius * sampling.unit_vectors(rng, count)
    targets = center + 0.9 * radius * sampling.unit_vectors(rng, count)
    hits = scene.intersect(origins, targets - origins, fields=("normal", "point"))
    assert hits.hit.all()
    return hits.point, hits.normal, radius


def self_intersection(method, dtype, place, strategy, count=2000):
    """Failure rate of secondary rays spawned on a closed convex surface.

    Half the rays leave the surface (outwards: any hit is a self-hit), half enter it, leaning
    at least 1/6 in cosine towards the inside (they must cross the inside and hit the far side,
    further than 1e-3 of the size: a nearer hit is a self-hit, a miss an escape).

    Returns
    -------
    float
        The fraction of rays that self-hit or escape.
    """
    from raycore import offset_ray_origin

    scene = _spawn_scene(method.family, dtype, place)
    points, normals, size = _spawn_points(method.family, dtype, place, count)
    rng = np.random.default_rng(79)
    half = len(points) // 2
    directions = np.concatenate([_hemisphere(rng, normals[:half], outward=True),
                                 _hemisphere(rng, normals[half:], outward=False, lean=0.2)])
    directions = directions.astype(points.dtype)
    tmin = 0.0
    origins = points
    if strategy == "tmin = 1e-4":
        tmin = 1e-4
    elif strategy == "offset_ray_origin":
        origins = offset_ray_origin(points, normals, directions)
    hits = scene.intersect(origins, directions, tmin, **method.options)
    leaving_hit = hits.hit[:half]
    entering_bad = ~hits.hit[half:] | (hits.t[half:] < 1e-3 * size)
    return float((leaving_hit.sum() + entering_bad.sum()) / len(points))
