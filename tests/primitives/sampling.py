"""Seeded ray sets for the accuracy bars, and the bar itself.

A ray set mixes, for one shape: rays aimed from outside at points on or near its surface,
grazing rays (tangent to the surface, through rims and edges; the shape's test module builds
them), rays starting inside (or, for open shapes, just off the surface), random rays (mostly
misses), axis-parallel rays with one or two zero direction components aimed at the surface, and
aimed rays clipped by random ``tmin`` / ``tmax``.  Directions have random lengths.  Every value is
rounded to float32, so that one exact reference serves both precisions.
"""

from dataclasses import dataclass

import numpy as np
from hypothesis import strategies as st

BAR_RAYS = 100_000

#: Share of each category in a set.
SHARES = {"aimed": 0.30, "grazing": 0.15, "inside": 0.15, "random": 0.15, "axis": 0.15,
          "clipped": 0.10}


@dataclass(frozen=True)
class RaySet:
    """Rays as float64 arrays holding float32 values; ``category`` labels each ray."""

    origins: np.ndarray
    directions: np.ndarray
    tmin: np.ndarray
    tmax: np.ndarray
    category: np.ndarray

    def __len__(self):
        return len(self.origins)


def _float32(values):
    return np.asarray(values, dtype=np.float32).astype(np.float64)


def unit_vectors(rng, count):
    """Uniformly distributed unit vectors, shape (count, 3)."""
    v = rng.normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_directions(rng, count):
    """Random directions of random lengths (2**-3 to 2**3), shape (count, 3)."""
    return unit_vectors(rng, count) * 2.0 ** rng.uniform(-3, 3, size=(count, 1))


def _towards(rng, targets, directions, size):
    """Origins placed 1.5 to 6 sizes before the targets along the directions."""
    distance = size * rng.uniform(1.5, 6.0, size=(len(targets), 1))
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    return targets - distance * unit


def tangent_rays(rng, points, normals, size):
    """Rays touching the surface at ``points`` (unit ``normals``), from 1.5 to 6 sizes away."""
    directions = random_directions(rng, len(points))
    directions -= np.sum(directions * normals, axis=1, keepdims=True) * normals
    return _towards(rng, points, directions, size), directions


def mixed_rays(rng, count, shape):
    """A seeded mix of rays for one shape (see the module docstring).

    Parameters
    ----------
    rng : numpy.random.Generator
    count : int
    shape : object
        With ``center`` (3,), ``size`` (float), and methods ``surface(rng, n)`` (points on the
        surface, (n, 3)), ``grazing(rng, n)`` (origins, directions) and ``inside(rng, n)``
        (points inside, or just off the surface of an open shape).
    """
    sizes = {name: int(round(share * count)) for name, share in SHARES.items()}
    sizes["aimed"] += count - sum(sizes.values())
    size = shape.size

    def aimed(n):
        targets = shape.surface(rng, n) + rng.normal(scale=0.02 * size, size=(n, 3))
        directions = random_directions(rng, n)
        return _towards(rng, targets, directions, size), directions

    def axis_parallel(n):
        directions = random_directions(rng, n)
        # zero one or two components: rays parallel to a coordinate plane or axis
        zeroed = rng.random((n, 3)) < rng.choice([1 / 3, 2 / 3], size=(n, 1))
        zeroed[zeroed.all(axis=1), 0] = False
        directions[zeroed] = 0.0
        return _towards(rng, shape.surface(rng, n), directions, size), directions

    parts = {
        "aimed": aimed(sizes["aimed"]),
        "grazing": shape.grazing(rng, sizes["grazing"]),
        "inside": (shape.inside(rng, sizes["inside"]), random_directions(rng, sizes["inside"])),
        "random": (shape.center + rng.uniform(-3 * size, 3 * size, size=(sizes["random"], 3)),
                   random_directions(rng, sizes["random"])),
        "axis": axis_parallel(sizes["axis"]),
        "clipped": aimed(sizes["clipped"]),
    }
    origins = _float32(np.concatenate([p[0] for p in parts.values()]))
    directions = _float32(np.concatenate([p[1] for p in parts.values()]))
    category = np.concatenate([np.full(sizes[name], name) for name in parts])
    tmin = np.zeros(count)
    tmax = np.full(count, np.inf)
    clipped = category == "clipped"
    # around the parameter of the aimed-at point: clips near hits, far hits, or both
    reach = 7 * size / np.linalg.norm(directions[clipped], axis=1)
    tmin[clipped] = _float32(reach * rng.uniform(0.0, 1.0, clipped.sum()))
    tmax[clipped] = _float32(tmin[clipped] + reach * rng.uniform(0.0, 1.0, clipped.sum()))
    assert np.all(np.any(directions != 0, axis=1))
    return RaySet(origins, directions, tmin, tmax, category)


def measure(kernel_t, reference_t):
    """Hit/miss agreement and relative t errors over the rays that both call hits.

    Returns
    -------
    agreement : float
        Fraction of rays where kernel and reference agree on hit or miss.
    errors : ndarray
        ``|t - t_ref| / |t_ref|`` (absolute where ``t_ref == 0``) over the common hits.
    """
    kernel_t = np.asarray(kernel_t, dtype=np.float64)
    assert not np.any(np.isnan(kernel_t))
    kernel_hit = np.isfinite(kernel_t)
    reference_hit = np.isfinite(reference_t)
    both = kernel_hit & reference_hit
    scale = np.abs(reference_t[both])
    errors = np.abs(kernel_t[both] - reference_t[both]) / np.where(scale > 0, scale, 1.0)
    return float(np.mean(kernel_hit == reference_hit)), errors


#: Bars per precision: least hit/miss agreement (float64: over all rays; float32: over the
#: rays that are not grazing, which are built within float32 rounding of the surface) and largest
#: median relative t error.
BARS = {"float64": (0.9999, 1e-12), "float32": (0.999, 1e-6)}


def check_bar(label, dtype, kernel_t, reference_t, category):
    """Print the figures and assert the bar of ``dtype``."""
    agreement, errors = measure(kernel_t, reference_t)
    grazing = category == "grazing"
    clear_agreement, _ = measure(kernel_t[~grazing], reference_t[~grazing])
    graze_agreement, _ = measure(kernel_t[grazing], reference_t[grazing])
    median = float(np.median(errors))
    print(
        f"\n{label} [{dtype}]: hit/miss agreement {100 * agreement:.4f} % (grazing rays "
        f"{100 * graze_agreement:.2f} %, others {100 * clear_agreement:.4f} %); relative t error "
        f"median {median:.2e}, p99 {np.quantile(errors, 0.99):.2e}, max {errors.max():.2e}; "
        f"{len(errors)} common hits of {len(reference_t)} rays"
    )
    least_agreement, largest_median = BARS[dtype]
    assert (agreement if dtype == "float64" else clear_agreement) >= least_agreement
    assert median <= largest_median
    return agreement, median


# Hypothesis strategies for single rays: float32 values, with exact zeros in directions often.
coordinates = st.floats(-4, 4, width=32)
components = st.one_of(st.just(0.0), st.floats(-2, 2, width=32))
points = st.tuples(coordinates, coordinates, coordinates)
directions = st.tuples(components, components, components).filter(any)


def check_solid_bar_data(rays, expected):
    """The bar's rays around a closed solid cover the interesting cases: hits and misses mixed,
    every ray starting inside hits, grazing and clipped rays go both ways."""
    hit = np.isfinite(expected)
    assert 0.3 < hit.mean() < 0.8
    assert hit[rays.category == "inside"].all()
    assert 0.2 < hit[rays.category == "grazing"].mean() < 0.8
    assert 0.1 < hit[rays.category == "clipped"].mean() < 0.9


def scalar_reference(function, rays, *shape, count=300):
    """A scalar reference on every k-th ray of a set (about ``count`` rays, every category).

    Returns
    -------
    sample : slice
        The rays used.
    t : ndarray, shape (about count,)
    """
    sample = slice(None, None, max(1, len(rays) // count))
    rows = zip(rays.origins[sample], rays.directions[sample], rays.tmin[sample],
               rays.tmax[sample], strict=True)
    return sample, np.array([function(o, d, *shape, lo, hi) for o, d, lo, hi in rows])
