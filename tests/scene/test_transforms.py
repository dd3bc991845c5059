"""Affine transforms are inverted, composed and conditioned exactly, then rounded once: the same
bits on every CPU, whatever OpenBLAS kernel NumPy would have used."""

from fractions import Fraction

import numpy as np
import pytest

from raycore.mesh import affine_inverse, affine_product, condition_number
from raycore.primitives import box
from tests.primitives.reference import fraction_inverse

from .brute import exact_inverse, random_affine


def ill_conditioned(rng, log_condition, log_scale):
    """A random affine map whose linear part has singular values spread over ``10**cond``, all
    scaled by ``10**scale``, with a translation of the same size."""
    m = random_affine(rng)
    m[:3, :3] = m[:3, :3] * np.logspace(0, log_condition, 3) @ random_affine(rng)[:3, :3]
    m[:3, :] *= 10.0**log_scale
    return m


@pytest.mark.parametrize("log_condition", [0, 3, 6, 10])
@pytest.mark.parametrize("log_scale", [-100, 0, 100])
def test_the_inverse_is_the_exact_one_rounded_once(log_condition, log_scale):
    rng = np.random.default_rng([log_condition, log_scale + 100])
    for _ in range(20):
        m = ill_conditioned(rng, log_condition, log_scale)
        assert np.array_equal(affine_inverse(m), exact_inverse(m))
        assert np.array_equal(affine_inverse(m[:3]), exact_inverse(m))


def test_the_product_is_the_exact_one_rounded_once():
    rng = np.random.default_rng(1)
    for _ in range(50):
        a, b = ill_conditioned(rng, 4, 3), ill_conditioned(rng, 2, -5)
        exact = [[float(sum(Fraction(a[i, k]) * Fraction(b[k, j]) for k in range(4)))
                  for j in range(4)] for i in range(4)]
        assert np.array_equal(affine_product(a, b), exact)


def test_the_condition_number_is_exact_and_near_the_2_norm_one():
    rng = np.random.default_rng(2)
    for log_condition in (0, 4, 8, 11):
        for _ in range(10):
            linear = ill_conditioned(rng, log_condition, 0)[:3, :3]
            exact = [[Fraction(x) for x in row] for row in linear.tolist()]
            norm = max(sum(abs(x) for x in row) for row in exact)
            inverse_norm = max(sum(abs(x) for x in row) for row in fraction_inverse(exact))
            kappa = condition_number(linear)
            assert kappa == float(norm * inverse_norm)
            assert np.linalg.cond(linear) / 3 <= kappa * (1 + 1e-6) <= 3 * np.linalg.cond(
                linear) * (1 + 1e-6) ** 2
    assert condition_number(np.diag([1e-6, 1e6, 1.0])) == 1e6 / 1e-6
    assert condition_number(np.diag([1.0, 1.0, 0.0])) == np.inf
    assert condition_number([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]) == np.inf
    assert condition_number(np.diag([1e300, 1e300, 1e-300])) == np.inf


def test_a_singular_or_overflowing_inverse_names_the_transform():
    with pytest.raises(ValueError, match="transform"):
        affine_inverse(np.diag([1.0, 1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="transform"):
        affine_inverse(np.diag([1e-310, 1.0, 1.0, 1.0]))


def test_transformed_box_bounds_hold_the_box_the_kernels_test():
    """The kernels map rays by the stored inverse: the world box is that inverse's exact inverse
    applied to [lo, hi], and the bounds must hold all eight of its corners, exactly computed."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        m = ill_conditioned(rng, rng.uniform(0, 6), rng.uniform(-3, 3))
        lo, hi = -rng.uniform(0.1, 2, 3), rng.uniform(0.1, 2, 3)
        params = box.pack_transformed(lo, hi, m)
        stored = np.vstack([params[6:18].reshape(3, 4), [0, 0, 0, 1]])
        to_world = [[Fraction(x) for x in row] for row in stored.tolist()]
        linear = fraction_inverse([row[:3] for row in to_world[:3]])
        shift = [-sum(linear[i][k] * to_world[k][3] for k in range(3)) for i in range(3)]
        b_lo, b_hi = box.bounds_transformed(params)
        for corner in np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, 8).T:
            world = [sum(linear[i][k] * Fraction(corner[k]) for k in range(3)) + shift[i]
                     for i in range(3)]
            assert all(Fraction(b_lo[i]) <= world[i] <= Fraction(b_hi[i]) for i in range(3))
