"""An intersect request's ``"rays"``: a sensor described in JSON, made into rays by
:mod:`raycore.sensors`, once its ray count is known to be within the configured limit."""

import numpy as np

from raycore import sensors
from raycore.camera import orthographic_camera, perspective_camera
from service.errors import ClientError, LimitExceeded


def sensor_rays(spec, dtype, max_rays):
    """The rays of ``spec``, in the scene's precision.

    Parameters
    ----------
    spec : service.schemas.PerspectiveRays, OrthographicRays, LidarRays or PointRays
    dtype : numpy float type
        The scene's.
    max_rays : int
        The configured limit, checked before any ray is made.

    Returns
    -------
    raycore.sensors.SensorRays

    Raises
    ------
    LimitExceeded
        When the sensor makes more than ``max_rays`` rays (413).
    ClientError
        With the library's message for a degenerate sensor (422).
    """
    _check_maxima(spec, max_rays)
    try:
        # (the points' counts are held to the limit by _check_maxima)
        if spec.type == "points":
            return sensors.points(spec.sources, spec.targets, dtype)
        if spec.type == "lidar":
            return _lidar(spec, dtype, max_rays)
        _check_count(spec.width * spec.height, max_rays, f"{spec.width}x{spec.height} pixels")
        return camera_rays(spec, dtype)
    except ValueError as error:
        raise ClientError(f"body.rays: {error}") from error


def camera_rays(camera, dtype, samples=1, seed=0):
    """The rays of a camera: a render request's (``samples`` per pixel), or a ``"rays"``
    camera (its subclass).

    Returns
    -------
    raycore.sensors.SensorRays

    Raises
    ------
    ValueError
        The library's, for a degenerate camera.
    """
    return sensors.SensorRays(*camera_of(camera).rays(dtype, samples, seed), 0.0, np.inf)


def camera_of(camera):
    """The library's :class:`raycore.camera.Camera` of a request's camera (a render's, or a
    ``"rays"`` camera): the one that :func:`raycore.sensors.perspective` and
    :func:`raycore.sensors.orthographic` make their rays with.

    Raises
    ------
    ValueError
        The library's, for a degenerate camera.
    """
    view = (camera.position, camera.look_at, camera.up)
    if camera.type == "perspective":
        return perspective_camera(*view, camera.fov, camera.width, camera.height)
    return orthographic_camera(*view, camera.view_height, camera.width, camera.height)


def _lidar(spec, dtype, max_rays):
    layout = {name: getattr(spec, name) for name in (
        "preset", "elevations", "vertical_fov", "channels", "horizontal_resolution", "columns",
        "min_range", "max_range")}
    elevations, columns, _, _ = sensors.lidar_layout(**layout)
    _check_count(len(elevations) * columns, max_rays,
                 f"{len(elevations)} channels x {columns} columns")
    return sensors.lidar(spec.position, spec.forward, spec.up, dtype=dtype, **layout)


#: Fields that the document bounds by the ray limit: (name, whether their length is bounded)
_BOUNDED = {"perspective": [("width", False), ("height", False)],
            "orthographic": [("width", False), ("height", False)],
            "lidar": [("channels", False), ("columns", False), ("elevations", True)],
            "points": [("sources", True), ("targets", True)]}


def _check_maxima(spec, max_rays):
    """The document's maxima (see service.openapi.LIMITS): a value over one is invalid (422),
    not merely too large."""
    for name, sized in _BOUNDED[spec.type]:
        value = getattr(spec, name)
        if value is not None and (len(value) if sized else value) > max_rays:
            raise ClientError(f"body.rays.{name}: at most {max_rays}, the ray limit")
    resolution = getattr(spec, "horizontal_resolution", None)
    if resolution is not None and resolution < 360 / max_rays:
        raise ClientError(f"body.rays.horizontal_resolution: at least {360 / max_rays} degrees "
                          "(a finer step makes more columns than the ray limit)")


def _check_count(count, max_rays, what=None):
    if count > max_rays:
        what = f" ({what})" if what else ""
        raise LimitExceeded(f"body.rays makes {count} rays{what}; the limit is {max_rays}")


def bounded(rays, tmin, tmax):
    """``rays`` within the request's own tmin and tmax too (scalars; tmax None for none): the
    later start and the earlier stop of the two."""
    stop = rays.tmax if tmax is None else np.minimum(rays.tmax, tmax)
    return rays._replace(tmin=np.maximum(rays.tmin, tmin), tmax=stop)
