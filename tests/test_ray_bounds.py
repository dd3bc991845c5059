"""Regression: a per-ray bound beside a scalar one (found by raycore.integrations.trimesh).

The kernels indexed tmin and tmax with one stride, taken from tmin; an (N,) tmin with the default
scalar tmax read tmax past its end, and rays came back refused or missed at random.  Each bound
now has its own stride.
"""

import numpy as np
import pytest

import raycore


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("bound", ["tmin", "tmax"])
@pytest.mark.parametrize("n", [300, 3000])  # on the calling thread, and over the threads
def test_one_per_ray_bound_beside_a_scalar(dtype, bound, n):
    scene = raycore.Scene(dtype=dtype)
    scene.add_sphere([0, 0, 0], 1.0)
    rng = np.random.default_rng(1)
    origins = rng.normal(size=(n, 3))
    origins *= (3 + rng.random((n, 1))) / np.linalg.norm(origins, axis=1, keepdims=True)
    directions = -origins  # every ray starts outside and aims at the centre
    bounds = {bound: np.full(n, 1e-3 if bound == "tmin" else 10.0)}
    assert scene.intersect(origins, directions, **bounds).hit.all()
    assert scene.occluded(origins, directions, **bounds).all()
    assert (scene.count(origins, directions, **bounds) == 2).all()
    assert (scene.intersect_all(origins, directions, **bounds).counts == 2).all()
