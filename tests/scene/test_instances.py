"""Instances: many placements of one mesh answer as the same geometry flattened into one mesh,
share its memory, and come from trimesh scenes and files."""

import numpy as np
import pytest
import trimesh

from raycore import Scene

from .brute import MESH_DIR, SceneSpec, apply_affine, random_affine, shared_mesh, unit
from .t_error import instance_tolerance


def placements(count, seed=0):
    rng = np.random.default_rng(seed)
    return [random_affine(rng, 0.4, 1.6, spread=12.0) for _ in range(count)]


def flattened(vertices, faces, transforms):
    """One mesh holding every placement: vertices mapped in float64, faces offset."""
    world = [apply_affine(m, vertices) for m in transforms]
    return np.concatenate(world), np.concatenate([faces + i * len(vertices)
                                                 for i in range(len(transforms))])


def instanced_spec(vertices, faces, transforms):
    spec = SceneSpec()
    proto = spec.mesh(vertices, faces, visible=False)
    for m in transforms:
        spec.instance(proto, m)
    return spec


def rays(count, transforms, seed=1, reach=20.0):
    """Rays from a sphere around the scene towards points near the placements' centres."""
    rng = np.random.default_rng(seed)
    origins = unit(rng.normal(size=(count, 3))) * reach
    centres = np.array([m[:3, 3] for m in transforms])
    aim = centres[rng.integers(0, len(centres), count)] + rng.normal(scale=1.2, size=(count, 3))
    return origins, aim - origins


def tolerance(dtype, origins, directions, t, placements, block, prim):
    """:func:`t_error.instance_tolerance` of the watertight test on triangle ``prim[i]`` of
    placement ``block[i]``, for each ray; ``placements`` lists ``(vertices, faces, transform)``.
    """
    corners = np.empty((len(block), 3, 3))
    transforms = np.empty((len(block), 4, 4))
    for k, (vertices, faces, transform) in enumerate(placements):
        rows = np.flatnonzero(block == k)
        corners[rows] = vertices[faces[prim[rows]]]
        transforms[rows] = transform
    seen = [x.astype(dtype).astype(np.float64) for x in (origins, directions)]
    return instance_tolerance("watertight", dtype, *seen, t, corners, transforms)


@pytest.mark.parametrize("shape", ["icosphere", "capsule", "soup"])
def test_instances_answer_as_the_flattened_mesh(dtype, shape):
    rng = np.random.default_rng(2)
    mesh = {"icosphere": trimesh.creation.icosphere(subdivisions=2),
            "capsule": trimesh.creation.capsule(height=1.0, radius=0.5, count=[8, 8]),
            "soup": trimesh.Trimesh(rng.uniform(-1, 1, (90, 3)), np.arange(90).reshape(30, 3),
                                    process=False)}[shape]
    vertices, faces = mesh.vertices, mesh.faces
    transforms = placements(40)
    spec = instanced_spec(vertices, faces, transforms)
    instanced = spec.scene(dtype)
    flat = Scene(dtype=dtype)
    flat.add_mesh(*flattened(vertices, faces, transforms))
    origins, directions = rays(4000, transforms)

    a = instanced.intersect(origins, directions, fields=("normal",))
    b = flat.intersect(origins, directions, fields=("normal",))
    crossings = flat.intersect_all(origins, directions)
    # the data: misses and hits, on every instance, rays through several instances
    assert 0.05 < (b.geom_id < 0).mean() < 0.9
    assert len(np.unique(b.prim_id[b.geom_id >= 0] // len(faces))) == len(transforms)
    assert (crossings.counts >= 4).sum() > 50

    # geometry ids map: instance k (id k + 1, after the prototype) <-> faces of block k
    f = len(faces)
    hit = b.geom_id >= 0
    bad = (a.geom_id >= 0) != hit
    both = np.flatnonzero(hit & (a.geom_id >= 0))
    # t: the instanced scene reports triangle A, the flattened one B; each found the other's
    # triangle no closer, so |a.t - b.t| <= the larger of their tolerances (t_error.py)
    placed = [(vertices, faces, m) for m in transforms]
    tol_a, tol_b = (tolerance(dtype, origins[both], directions[both], b.t[both], placed, block,
                              prim)
                    for block, prim in [(a.geom_id[both] - 1, a.prim_id[both]),
                                        (b.prim_id[both] // f, b.prim_id[both] % f)])
    bad[both] |= np.abs(a.t[both] - b.t[both]) > np.maximum(tol_a, tol_b)
    # ids: the same triangle, unless another crossing lies within both tolerances
    second = np.full(len(both), np.inf)
    two = crossings.counts[both] >= 2
    second[two] = crossings.t[crossings.offsets[:-1][both[two]] + 1]
    ids = both[second - b.t[both] > tol_a + tol_b]
    bad[ids] |= (a.geom_id[ids] != b.prim_id[ids] // f + 1) | (a.prim_id[ids] != b.prim_id[ids] % f)
    # rays within rounding of an instance's edge may differ (object- vs world-space tests)
    rays_bad = np.flatnonzero(bad)
    excused = spec.near_instance_edge(origins[rays_bad], directions[rays_bad], 0.0, np.inf, dtype)
    assert excused.all(), f"rays {rays_bad[~excused][:5]} differ"
    assert len(rays_bad) <= 0.01 * len(origins)
    # normals: the same up to rounding, where the same triangle is hit
    same = both[(a.geom_id[both] == b.prim_id[both] // f + 1)
                & (a.prim_id[both] == b.prim_id[both] % f)]
    limit = 1e-4 if dtype == "float32" else 1e-10
    assert np.abs(a.normal[same] - b.normal[same]).max() <= limit
    # all hits and counts
    all_a = instanced.intersect_all(origins, directions)
    differ = np.flatnonzero(all_a.counts != crossings.counts)
    assert spec.near_instance_edge(origins[differ], directions[differ], 0.0, np.inf, dtype).all()
    occluded = instanced.occluded(origins, directions)
    differ = np.flatnonzero(occluded != hit)
    assert spec.near_instance_edge(origins[differ], directions[differ], 0.0, np.inf, dtype).all()


def test_instance_memory_does_not_grow_with_the_number_of_instances():
    ico = trimesh.creation.icosphere(subdivisions=3)
    sizes = {}
    for count in (1, 10, 200):
        scene = Scene()
        proto = scene.add_mesh(ico.vertices, ico.faces, visible=False)
        for m in placements(count):
            scene.add_instance(proto, m)
        stats = scene.stats()
        assert scene.triangle_count == len(ico.faces)
        assert len(stats["meshes"]) == 1 and stats["meshes"][0]["triangles"] == len(ico.faces)
        assert stats["objects"] == count + 1
        sizes[count] = (stats["bytes"], stats["meshes"][0]["bytes"])
    # the mesh's memory is the same whatever the number of instances...
    assert sizes[1][1] == sizes[10][1] == sizes[200][1]
    # ...and each instance adds a small, constant amount, not a copy of its triangles
    per_instance = (sizes[200][0] - sizes[10][0]) / 190
    assert per_instance < 256
    assert per_instance * len(ico.faces) < sizes[1][1] * 2
    flat = Scene()
    flat.add_mesh(*flattened(ico.vertices, ico.faces, placements(200)))
    assert flat.stats()["bytes"] > 50 * sizes[200][0]


def test_from_trimesh_scene_turns_repeated_geometry_into_instances(dtype):
    ico = trimesh.creation.icosphere(subdivisions=2)
    box = trimesh.creation.box(extents=[1, 2, 3])
    tscene = trimesh.Scene()
    tscene.add_geometry(ico, geom_name="ico", node_name="ico0")
    tscene.add_geometry(box, geom_name="box", node_name="box0")
    transforms = placements(6, seed=3)
    for i, m in enumerate(transforms):
        # the same geometry under several nodes (add_geometry would copy it)
        tscene.graph.update(frame_to=f"ico{i + 1}", frame_from=tscene.graph.base_frame,
                            matrix=m, geometry="ico")
    assert len(tscene.geometry) == 2 and len(tscene.graph.nodes_geometry) == 8
    scene = Scene.from_trimesh(tscene, dtype=dtype)
    stats = scene.stats()
    assert len(stats["meshes"]) == 2
    assert scene.triangle_count == len(ico.faces) + len(box.faces)
    assert stats["objects"] >= 8
    # same answers as the flattened scene
    flat_mesh = tscene.to_mesh()
    assert len(flat_mesh.faces) == 7 * len(ico.faces) + len(box.faces)
    flat = Scene(dtype=dtype)
    flat.add_mesh(flat_mesh.vertices, flat_mesh.faces)
    origins, directions = rays(3000, transforms, seed=4)
    a = scene.intersect(origins, directions)
    b = flat.intersect(origins, directions)
    assert 0.05 < (b.geom_id >= 0).mean() < 0.95
    assert len(np.unique(a.geom_id[a.geom_id >= 0])) == 8
    # to_mesh concatenates the placements in the graph's order (checked here): face i of the
    # flattened mesh is face i - start[k] of placement k
    placed = []
    for node in tscene.graph.nodes_geometry:
        matrix, name = tscene.graph[node]
        placed.append((tscene.geometry[name].vertices, tscene.geometry[name].faces, matrix))
    start = np.cumsum([0] + [len(faces) for _, faces, _ in placed])
    for (vertices, faces, matrix), first in zip(placed, start, strict=False):
        got = flat_mesh.vertices[flat_mesh.faces[first:first + len(faces)]]
        assert np.allclose(got, apply_affine(matrix, vertices)[faces], rtol=0, atol=1e-12)
    bad = (a.geom_id >= 0) != (b.geom_id >= 0)
    both = np.flatnonzero((a.geom_id >= 0) & (b.geom_id >= 0))
    # t: |a.t - b.t| <= the larger tolerance of the two triangles hit (t_error.py); which
    # placement the library hit is not known here, so its tolerance is the largest over the
    # placements that have its triangle
    flat_block = np.searchsorted(start, b.prim_id[both], side="right") - 1
    tol = tolerance(dtype, origins[both], directions[both], b.t[both], placed, flat_block,
                    b.prim_id[both] - start[flat_block])
    for k, (_, faces, _) in enumerate(placed):
        has = np.flatnonzero(a.prim_id[both] < len(faces))
        tol[has] = np.maximum(tol[has], tolerance(
            dtype, origins[both[has]], directions[both[has]], b.t[both[has]], placed,
            np.full(len(has), k), a.prim_id[both[has]]))
    bad[both] |= np.abs(a.t[both] - b.t[both]) > tol
    # the same placements as instances, to excuse rays within rounding of an edge
    spec = SceneSpec()
    protos = {"ico": spec.mesh(ico.vertices, ico.faces, visible=False),
              "box": spec.mesh(box.vertices, box.faces, visible=False)}
    for node in tscene.graph.nodes_geometry:
        matrix, name = tscene.graph[node]
        spec.instance(protos[name], matrix)
    rays_bad = np.flatnonzero(bad)
    assert spec.near_instance_edge(origins[rays_bad], directions[rays_bad], 0.0, np.inf,
                                   dtype).all()


def test_from_file_loads_a_shared_mesh(dtype):
    mesh = shared_mesh("fandisk")
    scene = Scene.from_file(MESH_DIR / "fandisk.obj", dtype=dtype)
    assert scene.triangle_count == len(mesh.faces)
    direct = Scene(dtype=dtype)
    direct.add_mesh(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(6)
    lo, hi = mesh.bounds
    origins = rng.uniform(lo, hi, (3000, 3))
    directions = rng.normal(size=(3000, 3))
    a = scene.intersect(origins, directions)
    b = direct.intersect(origins, directions)
    assert (b.geom_id >= 0).mean() > 0.3
    assert np.array_equal(a.t, b.t)
    assert np.array_equal(a.prim_id, b.prim_id)
    assert np.array_equal(a.geom_id >= 0, b.geom_id >= 0)
    with pytest.raises(ValueError):
        Scene.from_file(MESH_DIR / "no-such-mesh.obj")
