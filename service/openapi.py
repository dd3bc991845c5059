"""The OpenAPI document as the running configuration makes it: the configured limits as the
schemas' maxima, and security only where an API key is configured (see ``create_app``)."""

from fastapi.openapi.utils import get_openapi

from service.schemas import IntersectRequest

#: (component schema, property, JSON Schema keyword, Settings attribute): each limit that a
#: schema can state, set from the settings the app runs with.
LIMITS = [
    ("IntersectRequest", "origins", "maxItems", "max_rays"),
    ("IntersectRequest", "directions", "maxItems", "max_rays"),
    ("IntersectRequest", "tmin", "maxItems", "max_rays"),
    ("IntersectRequest", "tmax", "maxItems", "max_rays"),
    ("PerspectiveRays", "width", "maximum", "max_rays"),
    ("PerspectiveRays", "height", "maximum", "max_rays"),
    ("OrthographicRays", "width", "maximum", "max_rays"),
    ("OrthographicRays", "height", "maximum", "max_rays"),
    ("LidarRays", "elevations", "maxItems", "max_rays"),
    ("LidarRays", "channels", "maximum", "max_rays"),
    ("LidarRays", "columns", "maximum", "max_rays"),
    ("PointRays", "sources", "maxItems", "max_rays"),
    ("PointRays", "targets", "maxItems", "max_rays"),
    ("MeshObject", "faces", "maxItems", "max_triangles"),
    ("PerspectiveCamera", "width", "maximum", "max_render_pixels"),
    ("PerspectiveCamera", "height", "maximum", "max_render_pixels"),
    ("OrthographicCamera", "width", "maximum", "max_render_pixels"),
    ("OrthographicCamera", "height", "maximum", "max_render_pixels"),
]


def document(app, settings):
    """The app's OpenAPI document (made once, then kept as ``app.openapi_schema``).

    Parameters
    ----------
    app : FastAPI
    settings : Settings
        Whose limits the schemas state.
    """
    if app.openapi_schema is None:
        openapi = get_openapi(title=app.title, version=app.version,
                              description=app.description, routes=app.routes)
        schemas = openapi["components"]["schemas"]
        # the intersect body is read by the route itself (JSON or .npy): not a FastAPI
        # parameter; its sensors' schemas join the components
        request = IntersectRequest.model_json_schema(ref_template="#/components/schemas/{model}")
        schemas.update(request.pop("$defs"))
        schemas["IntersectRequest"] = request
        for schema, name, keyword, limit in LIMITS:
            _limit(schemas[schema]["properties"][name], keyword, getattr(settings, limit))
        # a finer horizontal step would make more columns than the ray limit
        _limit(schemas["LidarRays"]["properties"]["horizontal_resolution"], "minimum",
               360 / settings.max_rays)
        app.openapi_schema = openapi
    return app.openapi_schema


def _limit(schema, keyword, value):
    """Set ``keyword`` on ``schema``, or on each of its ``anyOf`` branches that it applies to
    (``maxItems`` to arrays, ``maximum`` and ``minimum`` to numbers)."""
    kind = "array" if keyword == "maxItems" else ("integer", "number")  # maximum, minimum
    branches = schema.get("anyOf", [schema])
    for branch in branches:
        if branch.get("type") in kind:
            branch[keyword] = value
