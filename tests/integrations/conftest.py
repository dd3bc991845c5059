"""Meshes and rays shared by the integration tests."""

import functools
from pathlib import Path

import numpy as np
import pytest
import trimesh

MESH_DIR = Path(__file__).resolve().parents[3] / "shared" / "meshes"


@functools.cache
def load(name):
    """A shared mesh as trimesh loads it by default (vertices merged, so edges are shared)."""
    path = MESH_DIR / f"{name}.obj"
    if not path.exists():
        pytest.skip(f"{path} is not there (the shared/ folder beside the repository)")
    return trimesh.load(path, force="mesh")


def random_rays(mesh, count, seed):
    """(count, 3) origins on a sphere of two radii around the mesh and (count, 3) directions
    towards random points of its bounding box: about half of them hit."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo)
    around = rng.normal(size=(count, 3))
    origins = centre + radius * around / np.linalg.norm(around, axis=1, keepdims=True)
    return origins, lo + rng.random((count, 3)) * (hi - lo) - origins


def edge_rays(mesh, count, seed, at="edges"):
    """Rays aimed exactly at points of shared edges (``at="edges"``, a random point of each) or
    at vertices (``at="vertices"``), the rays trimesh's intersectors let through.

    Each comes from a bounding-box diagonal away against the mean normal of the faces around
    its target, so that it crosses the surface there rather than grazing it (a ray that only
    touches a silhouette edge may rightly miss); targets where some face around is seen
    edge-on (within about 6 degrees) are left out.  Returns (M, 3) origins and directions,
    M <= ``count``.
    """
    rng = np.random.default_rng(seed)
    if at == "edges":
        pick = rng.choice(len(mesh.edges_unique), count)
        edges = mesh.edges_unique[pick]
        w = rng.random((count, 1))
        targets = mesh.vertices[edges[:, 0]] * w + mesh.vertices[edges[:, 1]] * (1 - w)
        around = _faces_of_edges(mesh, edges)
    else:
        pick = rng.choice(len(mesh.vertices), count)
        targets = mesh.vertices[pick]
        around = _faces_of_vertices(mesh, pick)
    normals = np.where((around >= 0)[..., None], mesh.face_normals[around], 0.0)
    directions = -normals.sum(axis=1)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    facing = np.einsum("nfk,nk->nf", normals, directions)
    crossing = np.all((around < 0) | (facing < -0.1), axis=1)
    origins = targets - np.linalg.norm(mesh.extents) * directions
    return origins[crossing], directions[crossing]


def _faces_of_edges(mesh, edges):
    """(M, 2) the two faces on each of ``edges`` ((M, 2) vertex indices) of a closed mesh."""
    key = {tuple(sorted(e)): pair for e, pair in
           zip(mesh.face_adjacency_edges.tolist(), mesh.face_adjacency.tolist(), strict=True)}
    return np.array([key[tuple(sorted(e))] for e in edges.tolist()])


def _faces_of_vertices(mesh, vertices):
    """(M, K) the faces around each of ``vertices``, padded with -1 (trimesh's vertex_faces
    wants scipy)."""
    flat = mesh.faces.ravel()
    order = np.argsort(flat, kind="stable")
    start = np.searchsorted(flat[order], vertices)
    stop = np.searchsorted(flat[order], vertices, side="right")
    around = np.full((len(vertices), (stop - start).max()), -1)
    for row, (a, b) in enumerate(zip(start, stop, strict=True)):
        around[row, :b - a] = order[a:b] // 3
    return around
