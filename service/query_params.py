"""One value for each single-valued URL parameter.

FastAPI reads the last of a repeated parameter: ``?offset=x&offset=0`` lists from 0, where the
document says ``offset`` is one integer.  Schemathesis sends such requests and expects them
refused, as a client that repeats a parameter by mistake should be told.  Which parameters take
several values (``fields``) is read from the served document, route by route, so that the two
never disagree.
"""

from collections import Counter

from fastapi import Request
from fastapi.exceptions import RequestValidationError


async def single_values(request: Request):
    """A dependency of every route: 422, as FastAPI's own validation answers, when a URL
    parameter that the route's document declares with one value is given several times."""
    counts = Counter(name for name, _ in request.query_params.multi_items())
    repeated = [name for name, count in counts.items() if count > 1]
    if not repeated:
        return
    route = request.scope.get("route")
    lists = _list_parameters(request.app).get((getattr(route, "path", None), request.method))
    problems = [{"loc": ("query", name), "type": "repeated",
                 "msg": f"given {counts[name]} times; this parameter takes one value"}
                for name in repeated if name not in (lists or ())]
    if problems:
        raise RequestValidationError(problems)


def _list_parameters(app):
    """``{(path template, METHOD): names of the query parameters that take several values}``
    from the app's OpenAPI document, made once."""
    found = getattr(app.state, "list_parameters", None)
    if found is None:
        found = {}
        for path, operations in app.openapi()["paths"].items():
            for method, operation in operations.items():
                found[path, method.upper()] = {
                    parameter["name"] for parameter in operation.get("parameters", ())
                    if parameter["in"] == "query" and _is_array(parameter["schema"])}
        app.state.list_parameters = found
    return found


def _is_array(schema):
    return schema.get("type") == "array" or any(map(_is_array, schema.get("anyOf", ())))
