"""What the scene routes compute, apart from HTTP: a ray query's answer and a render's image.

``raycore cast`` and ``raycore render`` call these too, so that the command line answers
exactly as the service does.  The library's ``ValueError``s become
:class:`~service.errors.ClientError`s here.
"""

import numpy as np

from raycore.camera import orthographic_rays, perspective_rays
from raycore.render import render
from service.errors import ClientError


def run_query(scene, rays, options):
    """Answer ``options.query`` for ``rays`` (origins, directions, tmin, tmax) with ``scene``.

    Parameters
    ----------
    scene : raycore.Scene
    rays : tuple
        Origins and directions (N, 3), tmin and tmax (scalars or (N,)).
    options : service.schemas.QueryOptions

    Returns
    -------
    Hits (closest), AllHits (all), (N,) bool (any) or (N,) int64 (count)

    Raises
    ------
    ClientError
        With the library's message for rays it refuses.
    """
    if options.fields and options.query != "closest":
        raise ClientError(f"fields apply to closest-hit queries, not query={options.query}")
    test = options.triangle_test
    try:
        if options.query == "closest":
            return scene.intersect(*rays, triangle_test=test, fields=options.fields)
        if options.query == "any":
            return scene.occluded(*rays, triangle_test=test)
        if options.query == "all":
            return scene.intersect_all(*rays, triangle_test=test)
        return scene.count(*rays, triangle_test=test)
    except ValueError as error:
        raise ClientError(str(error)) from error


def render_image(scene, colors, spec):
    """The image of a render request: its camera's rays, traced and shaded.

    Parameters
    ----------
    scene : raycore.Scene
    colors : ndarray, shape (G, 3)
        Linear RGB of each geometry id (lambert).
    spec : service.schemas.RenderRequest

    Returns
    -------
    ndarray of uint8, shape (height, width, 3)

    Raises
    ------
    ClientError
        With the library's message for a degenerate camera or light.
    """
    camera = spec.camera
    view = (camera.position, camera.look_at, camera.up)
    try:
        size = (camera.width, camera.height, scene.dtype)
        if camera.type == "perspective":
            rays = perspective_rays(*view, camera.fov, *size)
        else:
            rays = orthographic_rays(*view, camera.view_height, *size)
        return render(scene, *rays, camera.width, camera.height, spec.shading,
                      light_direction=spec.light_direction, colors=colors,
                      background=np.asarray(spec.background), ambient=spec.ambient,
                      triangle_test=spec.triangle_test)
    except ValueError as error:
        raise ClientError(str(error)) from error
