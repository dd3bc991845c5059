"""``raycore cast``: the service's .npy answers, equal to Scene's on the same rays."""

import numpy as np
import pytest

from raycore import Scene
from raycore.cli import main
from raycore.commands import cast
from tests.commands.conftest import mesh_file, refused


def _rays(path, count, seed, dtype=np.float32):
    """(count, 3) origins around the mesh and directions towards its box: about half hit."""
    scene = Scene.from_file(path)
    lo, hi = scene.bounds
    rng = np.random.default_rng(seed)
    around = rng.normal(size=(count, 3))
    origins = (lo + hi) / 2 + np.linalg.norm(hi - lo) * around / np.linalg.norm(
        around, axis=1, keepdims=True)
    directions = lo + rng.random((count, 3)) * (hi - lo) - origins
    return origins.astype(dtype), directions.astype(dtype)


def _cast(tmp_path, mesh, rays, *options):
    np.save(tmp_path / "rays.npy", rays)
    main(["cast", str(mesh), str(tmp_path / "rays.npy"), "-o", str(tmp_path / "hits.npy"),
          *options])
    return np.load(tmp_path / "hits.npy")


def test_closest_hits_equal_scene_intersect(tmp_path):
    mesh = mesh_file("spot")
    origins, directions = _rays(mesh, 3000, 0)
    hits = _cast(tmp_path, mesh, np.hstack([origins, directions]), "--fields", "normal,uv")
    expected = Scene.from_file(mesh).intersect(origins, directions, fields=("normal", "uv"))
    assert hits.dtype.names == ("t", "geom_id", "prim_id", "uv", "normal")
    assert 0.3 < expected.hit.mean() < 0.9
    for name in ("t", "geom_id", "prim_id", "uv", "normal"):
        np.testing.assert_array_equal(hits[name], getattr(expected, name))


@pytest.mark.parametrize("query", ["any", "count", "all"])
def test_other_queries_with_per_ray_bounds_equal_scene(tmp_path, query, monkeypatch):
    mesh = mesh_file("suzanne")
    origins, directions = _rays(mesh, 2000, 1, np.float64)
    rng = np.random.default_rng(2)
    tmin, tmax = rng.random(2000) * 0.3, 0.5 + rng.random(2000)
    # in chunks of 300 rays, so that the answers are put together from several calls
    monkeypatch.setattr(cast, "CHUNK", 300)
    hits = _cast(tmp_path, mesh, np.hstack([origins, directions, tmin[:, None], tmax[:, None]]),
                 "--query", query, "--dtype", "float64", "--triangle-test", "moller")
    scene = Scene.from_file(mesh, dtype="float64")
    call = {"any": scene.occluded, "count": scene.count, "all": scene.intersect_all}[query]
    expected = call(origins, directions, tmin, tmax, triangle_test="moller")
    if query == "all":
        assert hits.dtype.names == ("ray_index", "t", "geom_id", "prim_id")
        assert len(np.unique(expected.ray_index)) > 300  # hits in several chunks
        for name in hits.dtype.names:
            np.testing.assert_array_equal(hits[name], getattr(expected, name))
    else:
        column = {"any": "occluded", "count": "count"}[query]
        assert hits.dtype.names == (column,)
        assert 0 < np.count_nonzero(expected) < len(expected)
        np.testing.assert_array_equal(hits[column], expected)


def test_fields_only_with_closest_hits(tmp_path, capsys):
    np.save(tmp_path / "rays.npy", np.zeros((2, 6)))
    code, err = refused(["cast", mesh_file("suzanne"), tmp_path / "rays.npy", "-o",
                         tmp_path / "hits.npy", "--query", "count", "--fields", "normal"],
                        capsys)
    assert code == 1
    assert err.strip() == "raycore cast: --fields apply to closest-hit queries, not --query count"


def test_refused_rays_name_the_file(tmp_path, capsys):
    rays = np.zeros((3, 6), np.float32)
    rays[:, 3] = 1
    rays[1, 3] = 0  # a zero direction
    np.save(tmp_path / "rays.npy", rays)
    code, err = refused(["cast", mesh_file("suzanne"), tmp_path / "rays.npy", "-o",
                         tmp_path / "hits.npy"], capsys)
    assert code == 1 and err.startswith(f"raycore cast: {tmp_path / 'rays.npy'}: ")
    assert "direction" in err and err.count("\n") <= 1
    assert not (tmp_path / "hits.npy").exists()
