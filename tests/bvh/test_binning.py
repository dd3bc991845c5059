"""The builder's vector binning (raycore.bvh.build_simd) against the same arithmetic in NumPy."""

import numpy as np
import pytest

from raycore.bvh.records import FLOAT32_MAX, PRIM_INDEX, PRIM_WIDTH
from raycore.bvh.split import bin_range, clear_bins, new_bins, set_scale


def records(count, seed):
    """Random primitive records: boxes of every size, repeated coordinates, and boxes at the
    ends of float32's range (records are clamped to it); index bits in lane 6."""
    rng = np.random.default_rng(seed)
    lo = rng.normal(0, 1, (count, 3)) * 10.0 ** rng.integers(-3, 4, (count, 1))
    hi = lo + rng.exponential(1, (count, 3)) * rng.choice([0, 1e-6, 1, 100], (count, 1))
    lo[::17] = -FLOAT32_MAX
    hi[::19] = FLOAT32_MAX
    lo[::23] = lo[0]  # centroids that coincide
    hi[::23] = hi[0]
    prims = np.zeros((count, PRIM_WIDTH), np.float32)
    prims[:, :3], prims[:, 3:6] = lo, hi
    prims[:, 3:6] = np.maximum(prims[:, :3], prims[:, 3:6])
    prims[:, PRIM_INDEX] = np.arange(count, dtype=np.int32).view(np.float32)
    return prims


@pytest.mark.parametrize("bins", [2, 7, 16, 32])
@pytest.mark.parametrize("seed", range(4))
def test_vector_binning_equals_numpy(bins, seed):
    prims = records(3000, seed)
    half = np.float32(0.5)
    centroids = half * prims[:, :3] + half * prims[:, 3:6]
    cbox = np.zeros(8, np.float32)
    cbox[:3], cbox[3:6] = centroids.min(0), centroids.max(0)
    scale = np.zeros(4, np.float32)
    set_scale(cbox, bins, scale)
    counts, boxes = new_bins(bins)
    clear_bins(counts, boxes, bins)
    start, end = 5, len(prims) - 3  # a range inside the records, as a node's
    bin_range(prims, start, end, cbox, scale, bins, counts, boxes)

    last = np.float32(bins - 1)
    for axis in range(3):
        keys = np.minimum((centroids[start:end, axis] - cbox[axis]) * scale[axis],
                          last).astype(np.int64)
        np.testing.assert_array_equal(counts[axis], np.bincount(keys, minlength=bins))
        want_lo = np.full((bins, 3), np.inf, np.float32)
        want_hi = np.full((bins, 3), -np.inf, np.float32)
        np.minimum.at(want_lo, keys, prims[start:end, :3])
        np.maximum.at(want_hi, keys, prims[start:end, 3:6])
        np.testing.assert_array_equal(boxes[axis, :, :3], want_lo)
        np.testing.assert_array_equal(boxes[axis, :, 3:6], want_hi)
