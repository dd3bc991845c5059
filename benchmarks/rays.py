"""Ray sets for benchmarks: coherent camera rays and incoherent random rays."""

import numpy as np


def camera_rays(lo, hi, width, height, fov_degrees=40.0):
    """Pinhole camera rays framing the box [lo, hi] from outside, one per pixel.

    Returns
    -------
    origins, directions : ndarray of float64, shape (width * height, 3)
        Scanline order; directions are unit length.
    """
    center = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    distance = radius / np.tan(np.radians(fov_degrees) / 2)
    eye = center + distance * np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])
    forward = (center - eye) / np.linalg.norm(center - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(np.radians(fov_degrees) / 2)
    x = (np.arange(width) + 0.5) / width * 2 - 1
    y = 1 - (np.arange(height) + 0.5) / height * 2
    px, py = np.meshgrid(x * half * width / height, y * half)
    directions = forward + px.reshape(-1, 1) * right + py.reshape(-1, 1) * up
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return np.broadcast_to(eye, directions.shape).copy(), directions


def random_rays(lo, hi, count, seed=0):
    """Rays from uniform points inside [lo, hi] in uniform random directions (unit length)."""
    rng = np.random.default_rng(seed)
    origins = lo + (hi - lo) * rng.random((count, 3))
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return origins, directions
