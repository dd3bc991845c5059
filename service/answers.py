"""What the scene routes compute, apart from HTTP: a ray query's answer and a render's image.

``raycore cast`` and ``raycore render`` call these too, so that the command line answers
exactly as the service does.  The library's ``ValueError``s become
:class:`~service.errors.ClientError`s here.
"""

import numpy as np

from raycore import TooManyHits
from raycore.render import ARRAY_SHADINGS, render_arrays, render_camera
from service import codecs
from service.errors import ClientError, LimitExceeded, NotAcceptable
from service.sensors import camera_of, camera_rays


def run_query(scene, rays, options, max_hits=None):
    """Answer ``options.query`` for ``rays`` (origins, directions, tmin, tmax) with ``scene``.

    Parameters
    ----------
    scene : raycore.Scene
    rays : tuple
        Origins and directions (N, 3), tmin and tmax (scalars or (N,)).
    options : service.schemas.QueryOptions
    max_hits : int, optional
        Most crossings that ``query=all`` may list: ``Scene.intersect_all`` refuses more once
        it has counted them, before it makes their arrays, so that an answer of gigabytes is
        never made (2M rays through 1,000 parallel quads took the service past 8 GB).

    Returns
    -------
    Hits (closest), AllHits (all), (N,) bool (any) or (N,) int64 (count)

    Raises
    ------
    ClientError
        With the library's message for rays it refuses.
    LimitExceeded
        When ``query=all`` would list more than ``max_hits`` crossings.
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
            return scene.intersect_all(*rays, triangle_test=test, max_hits=max_hits)
        return scene.count(*rays, triangle_test=test)
    except TooManyHits as error:
        raise LimitExceeded(f"the rays cross the scene {error.crossings} times; an answer "
                            f"lists at most {max_hits}: send fewer rays") from error
    except ValueError as error:
        raise ClientError(str(error)) from error


def encode_columns(columns, accept):
    """Result columns as the Accept header asks: (.npy bytes, its media type), else JSON's."""
    if codecs.accepts_npy(accept):
        return codecs.columns_to_npy(columns), codecs.NPY
    return codecs.columns_to_json(columns), "application/json"


def lidar_answer(scene, rays, options, point_cloud, accept, max_hits=None):
    """A LiDAR's answer: closest hits with each return's ``range`` and hit ``point`` besides
    the asked fields, or (``point_cloud``) the hit points alone, in ray order, as the Accept
    header asks (.npy, PLY, else JSON ``points``); other queries answer as for any rays.

    Returns
    -------
    content : bytes-like
    media_type : str

    Raises
    ------
    ClientError
        For a point cloud of a query other than closest, and rays the library refuses.
    """
    if options.query != "closest":
        if point_cloud:
            raise ClientError(f"point_cloud applies to closest-hit queries, not "
                              f"query={options.query}")
        return encode_columns(codecs.result_columns(options.query,
                                                    run_query(scene, rays, options, max_hits)),
                              accept)
    fields = [*options.fields, *(["point"] if "point" not in options.fields else [])]
    hits = run_query(scene, rays, options.model_copy(update={"fields": fields}))
    if point_cloud:
        points = hits.point[hits.hit]
        if codecs.accepts_npy(accept):
            return codecs.array_to_npy(points), codecs.NPY
        if codecs.accepts(accept, codecs.PLY):
            return codecs.points_to_ply(points), codecs.PLY
        return codecs.columns_to_json({"points": points}), "application/json"
    # directions are unit length: t is the distance from the sensor
    return encode_columns({**codecs.result_columns("closest", hits), "range": hits.t}, accept)


def render_image(scene, colors, spec):
    """The image of a render request: its camera's rays (``spec.samples`` per pixel), traced
    and shaded.

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
    try:
        return render_camera(scene, camera_of(camera), spec.shading, samples=spec.samples,
                             smooth=spec.smooth, light_direction=spec.light_direction,
                             colors=colors, background=np.asarray(spec.background),
                             ambient=spec.ambient, triangle_test=spec.triangle_test)
    except ValueError as error:
        raise ClientError(str(error)) from error


def render_data(scene, spec):
    """The .npy answer of a depth, normal or id render request: the data of one ray per pixel
    centre (:func:`raycore.render.render_arrays`).

    Returns
    -------
    memoryview
        The .npy file's bytes.

    Raises
    ------
    NotAcceptable
        For a lambert render, which has no data but its picture.
    ClientError
        With the library's message for a degenerate camera.
    """
    if spec.shading not in ARRAY_SHADINGS:
        raise NotAcceptable(f"a {spec.shading} render is answered as image/png only; .npy "
                            f"answers are for {', '.join(ARRAY_SHADINGS)}")
    camera = spec.camera
    try:
        rays = camera_rays(camera, scene.dtype)
        return codecs.array_to_npy(render_arrays(
            scene, rays.origins, rays.directions, camera.width, camera.height, spec.shading,
            smooth=spec.smooth, triangle_test=spec.triangle_test))
    except ValueError as error:
        raise ClientError(str(error)) from error
