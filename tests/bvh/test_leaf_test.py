"""The vector leaf test (a block's triangles at once) against the scalar watertight test.

``watertight_block`` promises, lane by lane, the scalar test's t, u and v bit for bit, and to hand
every lane whose edge function rounds to 0 back to the scalar test.  The cases are chosen where
that promise is easiest to break: rays through shared edges and vertices (edge functions of
exactly 0), hits at the ends of [tmin, tmax], axis-aligned rays (ties in the axis permutation),
slivers, NaN lanes (padding, and degenerate triangles, which the leaves store as NaN), and
random triangles.
"""

import numpy as np
import pytest
from numba import njit

from raycore.bvh.leaves import FACE_COLUMN, face_ints
from raycore.bvh.simd import block_lanes, block_width, lanes_for, watertight_block
from raycore.primitives.triangle import watertight, watertight_setup


@njit(cache=True)
def _both_tests(blocks, origins, directions, tmin, tmax):
    """For every ray and block: (hit bits, scalar-fallback bits) of the vector test, its t, u,
    v, and the scalar test's t, u, v, per lane."""
    rays, count, width = len(origins), len(blocks), block_lanes(blocks)
    bits = np.zeros((rays, count, 2), np.int64)
    vector = np.full((rays, count, 3, width), np.nan, blocks.dtype)
    scalar = np.full((rays, count, 3, width), np.nan, blocks.dtype)
    lanes = np.empty(3 * width, blocks.dtype)
    for r in range(rays):
        ox, oy, oz = origins[r]
        dx, dy, dz = directions[r]
        kx, ky, kz, sx, sy, sz = watertight_setup(dx, dy, dz)
        for b in range(count):
            found = watertight_block(blocks, b, ox, oy, oz, kx, ky, kz, sx, sy, sz, tmin[r],
                                     tmax[r], lanes)
            bits[r, b, 0] = found & ((1 << width) - 1)
            bits[r, b, 1] = found >> width
            for lane in range(width):
                if found >> lane & 1:
                    for k in range(3):
                        vector[r, b, k, lane] = lanes[k * width + lane]
                v = blocks[b, lane::width]
                t, u, w = watertight(ox, oy, oz, kx, ky, kz, sx, sy, sz, tmin[r], tmax[r], v[0],
                                     v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8])
                scalar[r, b, 0, lane], scalar[r, b, 1, lane], scalar[r, b, 2, lane] = t, u, w
    return bits, vector, scalar


def _blocks(triangles, dtype):
    """Triangles (T, 3, 3) packed into blocks as the leaves hold them (padding NaN, face
    indices -1)."""
    lanes = lanes_for(dtype)
    count = -(-len(triangles) // lanes) * lanes
    padded = np.full((count, 9), np.nan)
    padded[:len(triangles)] = triangles.reshape(-1, 9)
    blocks = np.full((count // lanes, block_width(dtype)), np.nan, dtype)
    blocks[:, :9 * lanes] = padded.reshape(-1, lanes, 9).transpose(0, 2, 1).reshape(-1, 9 * lanes)
    face_ints(blocks)[:, FACE_COLUMN:] = -1
    return blocks


def _fan(dtype):
    """Eight triangles around the origin in the z = 1 plane (shared edges, one shared vertex),
    a sliver, a NaN triangle, and random triangles."""
    rng = np.random.default_rng(7)
    angles = np.linspace(0, 2 * np.pi, 9)
    rim = np.stack([np.cos(angles), np.sin(angles), np.ones(9)], axis=1)
    centre = np.array([0.0, 0.0, 1.0])
    fan = [np.stack([centre, rim[k], rim[k + 1]]) for k in range(8)]
    sliver = np.array([[-1, 0, 2], [1, 0, 2], [0, 1e-7, 2]], float)
    padding = np.full((3, 3), np.nan)
    scattered = rng.uniform(-1, 1, (21, 3, 3)) + [0, 0, 2]
    return _blocks(np.concatenate([fan, [sliver, padding], scattered]), dtype)


def _rays(dtype):
    """Rays at the fan's centre, along its spokes, through its rim vertices, along axes, and at
    random; tmin/tmax that put some hits exactly on a bound."""
    rng = np.random.default_rng(11)
    angles = np.linspace(0, 2 * np.pi, 9)[:8]
    spoke = np.stack([np.cos(angles), np.sin(angles), np.zeros(8)], axis=1) * 0.5
    rim = np.stack([np.cos(angles), np.sin(angles), np.zeros(8)], axis=1)
    targets = np.concatenate([[[0, 0, 0]], spoke, rim, rng.uniform(-1, 1, (40, 3)) * [1, 1, 0]])
    targets = targets + [0, 0, 1]
    origins = np.concatenate([np.zeros((len(targets), 3)) + [0.1, -0.2, -1],
                              rng.uniform(-2, 2, (30, 3)) + [0, 0, -3]])
    ends = np.concatenate([targets, rng.uniform(-1, 1, (30, 3)) + [0, 0, 2]])
    directions = ends - origins
    axis_rays = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 1, 1]], float)
    origins = np.concatenate([origins, [[0, 0, 0], [0, 0, 5], [-3, 0, 1], [0.2, 0.1, -1]]])
    directions = np.concatenate([directions, axis_rays])
    n = len(origins)
    tmin = np.zeros(n)
    tmax = np.full(n, np.inf)
    tmin[:5] = 1.0  # the centre ray hits at t = 1: on the lower bound, then on the upper
    tmax[5:10] = 1.0
    return (np.ascontiguousarray(origins, dtype), np.ascontiguousarray(directions, dtype),
            tmin.astype(dtype), tmax.astype(dtype))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_vector_lanes_equal_the_scalar_test_bit_for_bit(dtype):
    blocks = _fan(dtype)
    bits, vector, scalar = _both_tests(blocks, *_rays(dtype))
    hit, fallback = bits[..., 0], bits[..., 1]
    lane_bits = 1 << np.arange(lanes_for(dtype))
    hit_lanes = (hit[..., None] & lane_bits) > 0
    fallback_lanes = (fallback[..., None] & lane_bits) > 0
    scalar_hit = np.isfinite(scalar[:, :, 0, :])
    # a lane is a hit or handed back, never both
    assert not np.any(hit_lanes & fallback_lanes)
    # every scalar hit is a vector hit or handed back; no vector hit is a scalar miss
    assert np.all(scalar_hit[~fallback_lanes] == hit_lanes[~fallback_lanes])
    # the hits agree bit for bit in t, u and v
    got = np.moveaxis(vector, 2, -1)[hit_lanes]
    expected = np.moveaxis(scalar, 2, -1)[hit_lanes]
    assert np.array_equal(got.view(np.uint8), expected.view(np.uint8))
    # the cases occur: hits, rays through shared edges handed back, misses
    assert hit_lanes.sum() > 50 and fallback_lanes.sum() > 10 and (~scalar_hit).sum() > 50
