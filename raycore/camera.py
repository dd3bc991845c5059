"""Camera rays: one ray per pixel centre, in scanline order (row 0 at the top of the image).

The camera looks from ``position`` towards ``look_at``; ``up`` fixes the roll (it need not be
perpendicular to the view direction, only not parallel to it).  Image x grows to the right of
the view, image y grows downwards.
"""

import numpy as np
from numba import njit, prange

from raycore.rays import as_float_array, resolve_dtype


def _frame(position, look_at, up):
    """Camera position and its orthonormal (right, true up, forward) axes, each (3,) float64."""
    position = as_float_array(position, "position", np.float64, (3,))
    look_at = as_float_array(look_at, "look_at", np.float64, (3,))
    up = as_float_array(up, "up", np.float64, (3,))
    forward = look_at - position
    if not np.any(forward):
        raise ValueError("look_at must differ from position")
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    norm = np.linalg.norm(right)
    if norm <= 1e-9 * np.linalg.norm(up):
        raise ValueError("up must not be zero or parallel to the view direction")
    right /= norm
    return position, right, np.cross(right, forward), forward


def _pixel_grid(width, height):
    """Pixel centres in [-1, 1]: x of each column (to the right), y of each row (upwards)."""
    for name, value in (("width", width), ("height", height)):
        if not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    x = (np.arange(width) + 0.5) / width * 2 - 1
    y = 1 - (np.arange(height) + 0.5) / height * 2
    return x, y


def _plane_rays(center, right, up, across, rise, constant, dtype, unit=False):
    """Rays of an image plane, in scanline order, both (H*W, 3) of ``dtype``: the points
    ``center + across[w] * right + rise[h] * up`` (computed in float64, rounded once, scaled to
    unit length when ``unit``), and rows that all equal ``constant``, written in the same pass."""
    points = np.empty((len(rise) * len(across), 3), dtype)
    constants = np.empty_like(points)
    _plane_rays_kernel(center, right, up, across, rise, unit, constant, points, constants)
    return points, constants


@njit(cache=True, parallel=True)
def _plane_rays_kernel(center, right, up, across, rise, unit, constant, points, constants):
    width = len(across)
    for h in prange(len(rise)):
        for w in range(width):
            x = center[0] + across[w] * right[0] + rise[h] * up[0]
            y = center[1] + across[w] * right[1] + rise[h] * up[1]
            z = center[2] + across[w] * right[2] + rise[h] * up[2]
            if unit:
                length = np.sqrt(x * x + y * y + z * z)
                x, y, z = x / length, y / length, z / length
            row = h * width + w
            points[row, 0] = x
            points[row, 1] = y
            points[row, 2] = z
            for k in range(3):
                constants[row, k] = constant[k]


def perspective_rays(position, look_at, up, fov, width, height, dtype="float64"):
    """Pinhole camera rays.

    Parameters
    ----------
    position, look_at, up : array_like, shape (3,)
    fov : float
        Vertical field of view in degrees, in (0, 180).
    width, height : int
        Image size in pixels.
    dtype : {"float64", "float32"}
        Precision of the rays: that of the scene they go to saves it a conversion.

    Returns
    -------
    origins, directions : ndarray, shape (height * width, 3)
        Every origin is ``position``; directions are unit length.

    Raises
    ------
    ValueError
        Naming the argument that is out of range or degenerate.
    """
    if not 0 < fov < 180:
        raise ValueError(f"fov must be in (0, 180) degrees, got {fov!r}")
    position, right, true_up, forward = _frame(position, look_at, up)
    x, y = _pixel_grid(width, height)
    # offsets on the image plane at distance 1, per column and per row
    across = x * np.tan(np.radians(fov) / 2) * width / height
    rise = y * np.tan(np.radians(fov) / 2)
    dtype = resolve_dtype(dtype)
    directions, origins = _plane_rays(forward, right, true_up, across, rise, position, dtype,
                                      unit=True)
    return origins, directions


def orthographic_rays(position, look_at, up, view_height, width, height, dtype="float64"):
    """Parallel rays from a view plane through ``position``, perpendicular to it.

    Parameters
    ----------
    position, look_at, up : array_like, shape (3,)
    view_height : float
        Height of the view in scene units (its width follows the image's aspect ratio).
    width, height : int
        Image size in pixels.
    dtype : {"float64", "float32"}
        Precision of the rays.

    Returns
    -------
    origins, directions : ndarray, shape (height * width, 3)
        Origins on the view plane; every direction is the unit view direction.

    Raises
    ------
    ValueError
        Naming the argument that is out of range or degenerate.
    """
    if not (np.isfinite(view_height) and view_height > 0):
        raise ValueError(f"view_height must be positive and finite, got {view_height!r}")
    position, right, true_up, forward = _frame(position, look_at, up)
    x, y = _pixel_grid(width, height)
    across = x * view_height / 2 * width / height
    rise = y * view_height / 2
    dtype = resolve_dtype(dtype)
    return _plane_rays(position, right, true_up, across, rise, forward, dtype)
