"""The FastAPI app: routers, error handlers, the body size limit, and startup."""

import asyncio
import ctypes
import ctypes.util
import logging
import os
import sys
import time
from contextlib import asynccontextmanager
from importlib.metadata import version

import anyio
from fastapi import Depends, FastAPI, HTTPException
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from service.auth import require_api_key
from service.config import Settings, load_settings
from service.datadir import DataDir
from service.demo import load_demo
from service.errors import ClientError, validation_detail
from service.methods import Methods
from service.openapi import document
from service.query_params import single_values
from service.routes import health, meshes, pages, scenes
from service.runtime import Runtime
from service.schemas import error_responses
from service.store import Store

logger = logging.getLogger("raycore.service")

DESCRIPTION = """Ray queries and renders over HTTP, answered by `raycore.Scene`.

Upload meshes (`POST /v1/meshes`), build scenes from JSON (`POST /v1/scenes`), then cast ray
batches at them (`POST /v1/scenes/{id}/intersect`, JSON or .npy both ways) or render PNGs
(`POST /v1/scenes/{id}/render`); look at them in the viewer page, `/viewer`.  Scene and mesh ids
are content hashes; `demo` names a built-in scene.  Errors are answered as `{"detail": "..."}`
with a 4xx status.  This document describes the running service: its limits (`RAYCORE_*`) are
the schemas' maxima.
"""

#: Added to the description when an API key is configured (and the operations say so).
KEY_DESCRIPTION = """
This service is configured with an API key: the endpoints that change the store (uploads, scene
builds, deletions) need it, as `X-API-Key: <key>` or `Authorization: Bearer <key>`, and answer
401 without it; queries, renders, listings and descriptions need no key.
"""


#: glibc malloc settings (mallopt parameter, value), each unless its environment variable is set.
#: Geometry work runs in a pool of worker threads, and glibc gives each thread that allocates
#: its own arena, up to 8 per core, keeping what was freed in it; under a load of scene builds
#: the process then held several times the store's budget (``make load``: 1.2 GiB for a 128 MiB
#: store after 60 s, growing): two arenas.  A batch of a million rays allocates some 100 MB of
#: arrays of 4-25 MB, and by default glibc hands freed memory back to the system as soon as 50 MB
#: of it lie at the top of an arena, so that the next batch faults every page in again, zeroed
#: (1M camera rays: 107-129 ms of the service's time per batch, 73-83 ms without those faults).
#: Allocations below 64 MB come from the arenas, which keep up to 256 MB free.
_MALLOC = {"MALLOC_ARENA_MAX": (-8, 2), "MALLOC_MMAP_THRESHOLD_": (-3, 64 * 2**20),
           "MALLOC_TRIM_THRESHOLD_": (-1, 256 * 2**20)}


def _tune_malloc():
    """Apply ``_MALLOC`` where malloc is glibc's."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        for variable, (parameter, value) in _MALLOC.items():
            if variable not in os.environ:
                libc.mallopt(parameter, value)
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        pass


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app.

    Parameters
    ----------
    settings : Settings, optional
        Defaults to :func:`service.config.load_settings` (the environment).
    """
    settings = load_settings() if settings is None else settings
    _tune_malloc()
    keyed = settings.api_key is not None
    # the docs page is served by routes.pages, with assets of its own rather than a CDN's
    app = FastAPI(title="raycore", version=version("raycore"),
                  description=DESCRIPTION + (KEY_DESCRIPTION if keyed else ""),
                  lifespan=_lifespan, docs_url=None, redoc_url=None,
                  dependencies=[Depends(single_values)])
    disk = None if settings.data_dir is None else DataDir(settings.data_dir, settings.data_bytes)
    app.state.runtime = Runtime(settings, Store(settings.store_bytes), disk)
    app.add_middleware(Methods)
    app.add_middleware(BodyLimit, max_bytes=settings.max_body_bytes,
                       seconds=settings.body_seconds)
    app.add_middleware(ServerTiming)
    app.add_exception_handler(ClientError, _client_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.add_exception_handler(RequestValidationError, _invalid_request)
    app.add_exception_handler(Exception, _unexpected)
    for module in (health, meshes, scenes, pages):
        app.include_router(module.router)
    app.mount(pages.STATIC_URL, pages.static_files())
    # the routes that change the store need the key, and the document declares its security,
    # only when a key is configured
    guard = {"dependencies": [Depends(require_api_key)],
             "responses": error_responses(401)} if keyed else {}
    for module in (meshes, scenes):
        app.include_router(module.guarded, **guard)
    app.openapi = lambda: document(app, settings)
    return app


@asynccontextmanager
async def _lifespan(app):
    state = app.state.runtime
    state.limiter = anyio.CapacityLimiter(state.settings.compute_slots)
    if state.settings.demo:
        # In the background, so that /healthz answers while kernels load, and in a compute slot,
        # so that no request's kernels run beside the demo's: Numba's workqueue threading layer
        # (the image's) aborts the process when two threads launch parallel loops at once.
        state.startup = asyncio.create_task(state.compute(load_demo, state))
    else:
        state.ready.set()
    yield
    if state.startup is not None:
        await state.startup  # a worker thread cannot be stopped: shutting down waits for it


class ServerTiming:
    """ASGI middleware: a ``Server-Timing: app;dur=<ms>`` header, the time from the request's
    arrival to its answer's start (reading the body included), so that clients can tell the
    service's time from the network's; after the metrics that the route gave, if any."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()

        async def timed_send(message):
            if message["type"] == "http.response.start":
                elapsed = f"app;dur={1000 * (time.perf_counter() - start):.1f}".encode()
                headers = message.get("headers", [])
                # a route's own metrics (e.g. intersect's body and compute) lead, in one header
                own = [value for name, value in headers if name.lower() == b"server-timing"]
                headers = [(name, value) for name, value in headers
                           if name.lower() != b"server-timing"]
                message = {**message, "headers": [
                    *headers, (b"server-timing", b", ".join([*own, elapsed]))]}
            await send(message)

        await self.app(scope, receive, timed_send)


class BodyLimit:
    """ASGI middleware: 413 for bodies over ``max_bytes``, by Content-Length or as they stream;
    408 when the body has not all arrived ``seconds`` after the request did."""

    def __init__(self, app, max_bytes, seconds=None):
        self.app = app
        self.max_bytes = max_bytes
        self.seconds = seconds

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope["headers"]).get(b"content-length", b"0")
        if declared.isdigit() and int(declared) > self.max_bytes:
            detail = f"the body has {int(declared)} bytes; the limit is {self.max_bytes}"
            await JSONResponse({"detail": detail}, status_code=413)(scope, receive, send)
            return
        received = 0
        deadline = None if self.seconds is None else time.monotonic() + self.seconds

        async def limited_receive():
            nonlocal received, deadline
            if deadline is None:  # the body is all here: later calls wait for a disconnect
                message = await receive()
            else:
                try:
                    with anyio.fail_after(max(deadline - time.monotonic(), 0)):
                        message = await receive()
                except TimeoutError:
                    raise HTTPException(408, f"the body did not all arrive within {self.seconds}"
                                             " s, the limit") from None
                if not message.get("more_body", False):
                    deadline = None
            received += len(message.get("body", b""))
            if received > self.max_bytes:
                # answered by the app's HTTPException handler, whoever is reading the body
                raise HTTPException(413, f"the body has over {self.max_bytes} bytes, the limit")
            return message

        await self.app(scope, limited_receive, send)


async def _client_error(request, error):
    return JSONResponse({"detail": str(error)}, status_code=error.status)


async def _http_error(request, error):
    # FastAPI answers any failure to parse a JSON body but a syntax error as "There was an error
    # parsing the body": say which
    detail, cause = error.detail, error.__cause__
    if error.status_code == 400 and cause is not None:
        if isinstance(cause, RecursionError):
            detail = "the JSON body is nested too deeply (recursion limit exceeded)"
        elif isinstance(cause, UnicodeDecodeError):
            detail = f"the JSON body is not valid {cause.encoding} text: {cause.reason}"
        else:
            detail = f"the body cannot be parsed as JSON: {cause}"
    return JSONResponse({"detail": detail}, status_code=error.status_code, headers=error.headers)


async def _invalid_request(request, error):
    # without the offending input: it can be huge, or NaN, which JSON cannot carry
    problems = [{"loc": list(problem["loc"]), "msg": problem["msg"], "type": problem["type"]}
                for problem in error.errors()]
    return JSONResponse({"detail": validation_detail(problems), "errors": problems[:100]},
                        status_code=422)


async def _unexpected(request, error):
    logger.error("unhandled error on %s %s", request.method, request.url.path, exc_info=error)
    return JSONResponse({"detail": "internal server error"}, status_code=500)
