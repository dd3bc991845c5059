"""HTTP method semantics that FastAPI leaves out: ``Allow`` naming every method of a path, and
HEAD and OPTIONS answered for every path.

FastAPI routes a path's GET and DELETE as two routes, and Starlette answers a method that none
allows with the ``Allow`` of the first route whose path matched (``Allow: GET`` where DELETE is
allowed too); it answers HEAD and OPTIONS with 405.
"""

from fastapi.responses import JSONResponse, Response
from starlette.routing import Match

#: Methods that routes may serve (HEAD and OPTIONS are answered here).
ROUTED = ("GET", "POST", "PUT", "PATCH", "DELETE")


def allowed_methods(routes, scope):
    """The methods that some route serves at the request's path (by the routes' own matching),
    with HEAD where GET is, and OPTIONS; empty when no route has that path."""
    methods = {method for method in ROUTED
               if any(route.matches({**scope, "method": method})[0] == Match.FULL
                      for route in routes)}
    if not methods:
        return methods
    if "GET" in methods:
        methods.add("HEAD")
    return methods | {"OPTIONS"}


class Methods:
    """ASGI middleware: OPTIONS is answered 204 with ``Allow``; HEAD runs GET and drops the body
    (its headers, Content-Length included, are GET's); any other method that the path does not
    allow is answered 405 with ``Allow`` and a JSON ``detail``."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        allowed = allowed_methods(scope["app"].router.routes, scope)
        method = scope["method"]
        if not allowed or (method in allowed and method not in ("HEAD", "OPTIONS")):
            await self.app(scope, receive, send)  # unknown paths get their 404 from the router
            return
        allow = {"allow": ", ".join(sorted(allowed))}
        if method == "OPTIONS":
            await Response(status_code=204, headers=allow)(scope, receive, send)
        elif method == "HEAD":
            await self.app({**scope, "method": "GET"}, receive, _without_body(send))
        else:
            await JSONResponse({"detail": f"{method} is not allowed here; allowed: "
                                          f"{allow['allow']}"},
                               status_code=405, headers=allow)(scope, receive, send)


def _without_body(send):
    """``send`` that passes a response's start (its headers) and ends it with an empty body."""

    async def send_head(message):
        if message["type"] == "http.response.body":
            if message.get("more_body", False):
                return
            message = {"type": "http.response.body", "body": b""}
        await send(message)

    return send_head
