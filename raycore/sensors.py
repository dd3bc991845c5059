"""Sensor rays: cameras, spinning LiDARs and point-to-point sight lines, as ray batches.

Each generator returns :class:`SensorRays`, whose four members are the arguments of
:meth:`raycore.Scene.intersect` (and of ``occluded``, ``intersect_all`` and ``count``)::

    rays = raycore.sensors.lidar([0, 0, 1.8], preset="velodyne-vlp16", dtype=scene.dtype)
    hits = scene.intersect(*rays, fields=("point",))
    hits.t          # the range of each return (directions are unit length), inf for none

The HTTP service makes its ``"rays"`` with these same functions (its cameras with the
:class:`raycore.camera.Camera` that :func:`perspective` and :func:`orthographic` use), so that a
sensor described in a request gives exactly the rays it gives in process.  Cameras are those of
:mod:`raycore.camera` (one implementation for renders and ray batches).
"""

from typing import NamedTuple

import numpy as np

from raycore.camera import orthographic_rays, perspective_rays
from raycore.primitives._common import as_unit
from raycore.rays import as_float_array, integer, real_number, resolve_dtype


class SensorRays(NamedTuple):
    """A sensor's rays: ``origins`` and ``directions`` (N, 3) of the requested dtype, and
    ``tmin`` and ``tmax``, scalars or (N,), where each ray starts and stops."""

    origins: np.ndarray
    directions: np.ndarray
    tmin: float | np.ndarray
    tmax: float | np.ndarray


def perspective(position, look_at, up=(0.0, 1.0, 0.0), fov=45.0, width=512, height=512,
                dtype="float64", samples=1, seed=0):
    """Pinhole camera rays, ``samples`` per pixel in scanline order, from
    :func:`raycore.camera.perspective_rays` (see there for the arguments).

    Returns
    -------
    SensorRays
        (width * height * samples, 3) origins and unit directions; tmin 0, tmax inf.
    """
    return SensorRays(*perspective_rays(position, look_at, up, fov, width, height, dtype,
                                        samples, seed), 0.0, np.inf)


def orthographic(position, look_at, view_height, up=(0.0, 1.0, 0.0), width=512, height=512,
                 dtype="float64", samples=1, seed=0):
    """Parallel camera rays, ``samples`` per pixel in scanline order, from
    :func:`raycore.camera.orthographic_rays` (see there for the arguments).

    Returns
    -------
    SensorRays
        (width * height * samples, 3) origins on the view plane and the unit view direction;
        tmin 0, tmax inf.
    """
    return SensorRays(*orthographic_rays(position, look_at, up, view_height, width, height,
                                         dtype, samples, seed), 0.0, np.inf)


class LidarPreset(NamedTuple):
    """A spinning LiDAR's beam layout and range, as :func:`lidar` takes them."""

    vertical_fov: tuple[float, float]
    channels: int
    columns: int
    min_range: float
    max_range: float


#: Common spinning sensors, as approximations from their data sheets: channels evenly spread
#: over the vertical field of view (the real HDL-64E and some others space them unevenly; give
#: ``elevations`` for an exact layout), one column per horizontal step at 10 Hz, ranges in
#: metres (scale them to the scene's units).
LIDAR_PRESETS = {
    # Velodyne VLP-16 (Puck): +-15 deg, 2 deg apart; 0.2 deg at 10 Hz; 100 m
    "velodyne-vlp16": LidarPreset((-15.0, 15.0), 16, 1800, 0.5, 100.0),
    # Velodyne HDL-32E: -30.67 to +10.67 deg, 1.33 deg apart; 0.16 deg at 10 Hz; 100 m
    "velodyne-hdl32e": LidarPreset((-30.67, 10.67), 32, 2250, 1.0, 100.0),
    # Velodyne HDL-64E: -24.9 to +2 deg (really two blocks of 32 spaced differently);
    # about 0.17 deg at 10 Hz; 120 m
    "velodyne-hdl64e": LidarPreset((-24.9, 2.0), 64, 2083, 1.0, 120.0),
    # Ouster OS1-128: 45 deg (+-22.5), 1024 columns (its 1024x10 mode); 120 m
    "ouster-os1-128": LidarPreset((-22.5, 22.5), 128, 1024, 0.3, 120.0),
}


def lidar_layout(*, preset=None, elevations=None, vertical_fov=None, channels=None,
                 horizontal_resolution=None, columns=None, min_range=None, max_range=None):
    """A LiDAR's beam elevations, column count and range, checked, without making any ray.

    What ``preset`` gives is used where an argument is None.  The ray count is
    ``len(elevations) * columns``: check it against a limit before calling :func:`lidar`.

    Parameters
    ----------
    preset : str, optional
        A key of :data:`LIDAR_PRESETS`.
    elevations : array_like, shape (C,), optional
        Each channel's elevation above the sensor's horizontal plane, in degrees, in
        [-90, 90]; or give ``vertical_fov`` and ``channels``.
    vertical_fov : (float, float), optional
        Lowest and highest elevation in degrees; ``channels`` beams evenly spread from the
        lowest to the highest (one beam: at the lowest).
    channels : int, optional
    horizontal_resolution : float, optional
        Degrees between columns, in (0, 360]; ``columns = round(360 / horizontal_resolution)``.
        Or give ``columns``.
    columns : int, optional
        Rays per channel in one revolution.
    min_range, max_range : float, optional
        Where returns start and stop, in scene units: 0 <= min_range < max_range (inf allowed).
        Default 0 and inf.

    Returns
    -------
    elevations : ndarray of float64, shape (C,)
    columns : int
    min_range, max_range : float

    Raises
    ------
    ValueError
        Naming the argument that is missing, given twice or out of range.
    """
    if preset is not None:
        if not isinstance(preset, str) or preset not in LIDAR_PRESETS:
            raise ValueError(f"preset must be one of {sorted(LIDAR_PRESETS)}, got {preset!r}")
        known = LIDAR_PRESETS[preset]
        if elevations is None and vertical_fov is None:
            vertical_fov = known.vertical_fov
            channels = known.channels if channels is None else channels
        if horizontal_resolution is None and columns is None:
            columns = known.columns
        min_range = known.min_range if min_range is None else min_range
        max_range = known.max_range if max_range is None else max_range
    return (_elevations(elevations, vertical_fov, channels),
            _columns(horizontal_resolution, columns), *_ranges(min_range, max_range))


def _elevations(elevations, vertical_fov, channels):
    if (elevations is None) == (vertical_fov is None):
        raise ValueError("give either elevations or vertical_fov (with channels)")
    if elevations is not None:
        if channels is not None:
            raise ValueError("channels goes with vertical_fov, not with elevations")
        elevations = as_float_array(elevations, "elevations", np.float64, (None,))
        if len(elevations) == 0:
            raise ValueError("elevations must not be empty")
    else:
        lowest, highest = as_float_array(vertical_fov, "vertical_fov", np.float64, (2,))
        if lowest > highest:
            raise ValueError(f"vertical_fov must be (lowest, highest), got {vertical_fov!r}")
        integer(channels, "channels", 1, MAX_BEAMS)
        elevations = np.linspace(lowest, highest, channels)
    if np.any(np.abs(elevations) > 90):
        name = "elevations" if vertical_fov is None else "vertical_fov"
        raise ValueError(f"{name} must lie within [-90, 90] degrees")
    return elevations


def _columns(horizontal_resolution, columns):
    if (horizontal_resolution is None) == (columns is None):
        raise ValueError("give either horizontal_resolution or columns")
    if columns is not None:
        integer(columns, "columns", 1, MAX_BEAMS)
        return int(columns)
    if not 360 / MAX_BEAMS <= real_number(horizontal_resolution, "horizontal_resolution") <= 360:
        raise ValueError(f"horizontal_resolution must be in [360 / {MAX_BEAMS}, 360] degrees, "
                         f"got {horizontal_resolution!r}")
    return max(1, round(360 / horizontal_resolution))


def _ranges(min_range, max_range):
    min_range = 0.0 if min_range is None else real_number(min_range, "min_range")
    max_range = np.inf if max_range is None else real_number(max_range, "max_range")
    if not (np.isfinite(min_range) and min_range >= 0):
        raise ValueError(f"min_range must be finite and >= 0, got {min_range!r}")
    if not max_range > min_range:  # also refuses NaN
        raise ValueError(f"max_range must be above min_range ({min_range}), got {max_range!r}")
    return min_range, max_range


#: Channels, and columns, at most: a count that NumPy could not have made an array of (a
#: resolution of 1e-300 degrees asked for 3.6e302 columns) is refused by name.
MAX_BEAMS = 2**31 - 1


#: Rays per block of :func:`lidar`'s float64 arithmetic (1.5 MiB of float64 directions)
_BLOCK_RAYS = 2**16


def lidar(position, forward=(1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), *, preset=None,
          elevations=None, vertical_fov=None, channels=None, horizontal_resolution=None,
          columns=None, min_range=None, max_range=None, dtype="float64"):
    """The rays of one revolution of a spinning multi-channel LiDAR.

    The sensor sits at ``position``; ``up`` is its spin axis and ``forward`` (made perpendicular
    to ``up``) the direction of its first column.  Column ``j`` looks at azimuth
    ``360 * j / columns`` degrees, turning from ``forward`` towards ``up x forward`` (counter-
    clockwise seen from above); a channel of elevation ``e`` looks ``e`` degrees above the plane
    perpendicular to ``up``.  Rays come channel by channel, in the order of the elevations, each
    channel's columns in order: a (channels, columns) range image, flattened.

    Parameters
    ----------
    position, forward, up : array_like, shape (3,)
        The pose.  The defaults are a sensor's own frame (x forward, z up).
    preset, elevations, vertical_fov, channels, horizontal_resolution, columns, min_range, \
max_range
        The beam layout and range, as :func:`lidar_layout` takes them.
    dtype : {"float64", "float32"}
        Precision of the rays.

    Returns
    -------
    SensorRays
        (channels * columns, 3) origins (each ``position``) and unit directions (computed in
        float64, rounded once); tmin ``min_range`` and tmax ``max_range``, so that a hit's t is
        its range.

    Raises
    ------
    ValueError
        Naming the argument that is missing, degenerate or out of range.
    """
    elevations, columns, min_range, max_range = lidar_layout(
        preset=preset, elevations=elevations, vertical_fov=vertical_fov, channels=channels,
        horizontal_resolution=horizontal_resolution, columns=columns, min_range=min_range,
        max_range=max_range)
    position = as_float_array(position, "position", np.float64, (3,))
    forward, left, up = _sensor_frame(forward, up)
    dtype = resolve_dtype(dtype)
    azimuth = np.radians(np.arange(columns) * (360.0 / columns))[:, None]
    level = np.cos(azimuth) * forward + np.sin(azimuth) * left  # (columns, 3)
    elevation = np.radians(elevations)
    directions = np.empty((len(elevation), columns, 3), dtype)
    # a block of channels at a time, in float64, each rounded once into the output: temporaries
    # that stay in the cache rather than three float64 copies of the whole batch
    block = max(1, _BLOCK_RAYS // columns)
    for first in range(0, len(elevation), block):
        part = elevation[first:first + block, None, None]
        directions[first:first + block] = np.cos(part) * level + np.sin(part) * up
    directions = directions.reshape(-1, 3)
    origins = np.empty_like(directions)
    origins[:] = position
    return SensorRays(origins, directions, min_range, max_range)


def _sensor_frame(forward, up):
    """Unit (forward, left, up) axes, forward made perpendicular to up, each (3,) float64.

    Lengths through :func:`~raycore.primitives._common.as_unit` and the dot product summed in
    a fixed order, not through ``np.linalg.norm`` and ``@``, whose BLAS kernels depend on the
    CPU: the axes, and the scan's rays, have the same bits on every machine.
    """
    forward = as_float_array(forward, "forward", np.float64, (3,))
    up = as_float_array(up, "up", np.float64, (3,))
    up = as_unit(up, "up", "must not be zero")[0]
    forward = as_unit(forward, "forward", "must not be zero")[0]
    along = (forward[0] * up[0] + forward[1] * up[1]) + forward[2] * up[2]
    level = as_unit(forward - along * up, "forward", "must not be parallel to up",
                    shortest=1e-9)[0]
    return level, np.cross(up, level), up


def points(sources, targets, dtype="float64"):
    """Sight lines from ``sources`` to ``targets``: for visibility and line of sight.

    Each ray starts at its source and its direction is ``target - source`` (not unit length),
    so that t = 1 at the target and tmax is 1: ``Scene.occluded(*rays)`` tells whether
    anything lies between the two points (on the segment, ends included: give a slightly
    larger tmin and smaller tmax, or offset the points, to leave out surfaces they lie on), and
    a closest hit's t is the fraction of the way to the target.

    Parameters
    ----------
    sources, targets : array_like, shape (N, 3) or (3,)
        A single point is paired with every point of the other set.
    dtype : {"float64", "float32"}

    Returns
    -------
    SensorRays
        (N, 3) origins and directions; tmin 0, tmax 1.

    Raises
    ------
    ValueError
        Naming ``sources`` or ``targets`` when the shapes do not pair up, a point is not finite,
        or a target equals its source.
    """
    dtype = resolve_dtype(dtype)
    ends = []
    for name, value in (("sources", sources), ("targets", targets)):
        array = as_float_array(value, name, np.float64)
        if array.ndim == 1:
            array = array.reshape(1, -1)
        if array.ndim != 2 or array.shape[1] != 3:
            raise ValueError(f"{name} must have shape (N, 3) or (3,), got {np.shape(value)}")
        ends.append(array)
    sources, targets = ends
    if len(sources) != len(targets) and 1 not in (len(sources), len(targets)):
        raise ValueError(f"sources and targets must be as many, or one of them a single point; "
                         f"got {len(sources)} and {len(targets)}")
    count = max(len(sources), len(targets))
    origins = np.empty((count, 3), dtype)
    origins[:] = sources
    # from the rounded origin, so that origin + direction lands on the target itself
    directions = (targets - origins).astype(dtype)
    zero = np.flatnonzero(~np.any(directions, axis=1))
    if len(zero):
        raise ValueError(f"targets must differ from their sources: ray {zero[0]} has none "
                         "(or too short a one for the precision)")
    return SensorRays(origins, directions, 0.0, 1.0)
