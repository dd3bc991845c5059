"""Closest hits on the shared test meshes agree with Embree (float32) and trimesh (float64)."""

import numpy as np
import pytest

from .brute import (
    MESH_NAMES,
    camera_rays,
    embree_closest,
    inside_rays,
    mesh_scene,
    shared_mesh,
    trimesh_closest,
)

#: Embree computes in float32: t agrees to this many float32 ulps of (t + the mesh's size).
EMBREE_ULPS = 256
#: trimesh computes in float64.
TRIMESH_ULPS = 1024


def size_of(mesh):
    return float(np.linalg.norm(mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)))


@pytest.mark.parametrize("name", MESH_NAMES)
def test_closest_hits_agree_with_embree(name):
    mesh = shared_mesh(name)
    rng = np.random.default_rng(7)
    o1, d1 = camera_rays(mesh.vertices, 15000, rng)
    o2, d2 = inside_rays(mesh.vertices, 15000, rng)
    origins = np.concatenate([o1, o2]).astype(np.float32)
    directions = np.concatenate([d1, d2]).astype(np.float32)
    t_ref, prim_ref = embree_closest(mesh.vertices, mesh.faces, origins, directions)
    hit = prim_ref >= 0
    assert len(origins) >= 30000 and 0.2 < hit.mean() < 0.9, "rays must both hit and miss"
    tol = EMBREE_ULPS * np.finfo(np.float32).eps * (np.where(hit, t_ref, 0) + size_of(mesh))
    for dtype in ("float32", "float64"):
        hits = mesh_scene(name, dtype).intersect(origins, directions)
        agree = hits.prim_id == prim_ref  # -1 on both sides for misses
        rate = agree.mean()
        both = agree & hit
        t_err = np.abs(hits.t[both].astype(np.float64) - t_ref[both]) / tol[both]
        print(f"\n{name} {dtype} vs embree: {rate:.6f} of {len(origins)} rays agree "
              f"({(~agree).sum()} differ); worst |dt| = {t_err.max():.3g} x tolerance")
        assert rate >= 0.9999
        assert np.all(t_err <= 1)


@pytest.mark.parametrize("name", MESH_NAMES)
def test_closest_hits_agree_with_trimesh(name):
    mesh = shared_mesh(name)
    rng = np.random.default_rng(11)
    # trimesh's intersector tests every triangle in a ray's bounding box: telephoto cameras
    # keep those thin; they aim at points near the surface (most hit, some miss)
    surface = mesh.triangles[rng.integers(0, len(mesh.faces), 4000)].mean(axis=1)
    aim = surface + rng.normal(scale=0.03 * size_of(mesh), size=surface.shape)
    o1, d1 = camera_rays(mesh.vertices, 2100, rng, aim=aim, telephoto=True)
    o2, d2 = inside_rays(mesh.vertices, 400, rng)
    origins = np.concatenate([o1, o2])
    directions = np.concatenate([d1, d2])
    t_ref, prim_ref = trimesh_closest(mesh, origins, directions)
    scene = mesh_scene(name, "float64")
    hits = scene.intersect(origins, directions, fields=("uv",))
    crossings = scene.intersect_all(origins, directions)
    # a reference hit is ambiguous when it lies within rounding of an edge (trimesh accepts
    # barycentrics down to -1e-12), of the origin (it accepts hits 1e-6 behind) or of another hit
    size = size_of(mesh)
    uv = hits.uv
    edge = np.minimum(np.minimum(uv[:, 0], uv[:, 1]), 1 - uv[:, 0] - uv[:, 1])
    second = np.full(len(origins), np.inf)
    two = crossings.counts >= 2
    second[two] = crossings.t[crossings.offsets[:-1][two] + 1]
    with np.errstate(invalid="ignore"):  # inf - inf on misses
        ambiguous = ((edge < 1e-9) | (np.minimum(hits.t, t_ref) < 1e-6 * size)
                     | (second - hits.t < 1e-9 * size))
    clear = ~ambiguous
    agree = hits.prim_id == prim_ref
    hit = prim_ref >= 0
    print(f"\n{name} float64 vs trimesh: {agree.mean():.6f} of {len(origins)} rays agree, "
          f"{agree[clear].mean():.6f} of {clear.sum()} unambiguous ones")
    assert 0.3 < hit.mean() < 0.9 and ambiguous.mean() < 0.01
    assert np.array_equal(hits.prim_id[clear], prim_ref[clear])
    both = clear & hit
    tol = TRIMESH_ULPS * np.finfo(np.float64).eps * (t_ref[both] + size)
    assert np.all(np.abs(hits.t[both] - t_ref[both]) <= tol)
