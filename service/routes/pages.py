"""Pages for people: the viewer (``/viewer``, ``/`` leads there) and the API docs (``/docs``),
with every asset served from ``service/static`` (Swagger UI vendored from npm's
swagger-ui-dist, with its licence), so that they work with no network but the service's."""

from pathlib import Path

from fastapi import APIRouter
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

STATIC = Path(__file__).resolve().parent.parent / "static"
#: Where ``STATIC`` is served.
STATIC_URL = "/static"

router = APIRouter(include_in_schema=False)


@router.get("/")
def home():
    return RedirectResponse("/viewer")


@router.get("/viewer")
def viewer():
    return FileResponse(STATIC / "viewer" / "index.html")


@router.get("/docs")
def docs():
    swagger = f"{STATIC_URL}/swagger-ui"
    return get_swagger_ui_html(
        openapi_url="/openapi.json", title="raycore API",
        swagger_js_url=f"{swagger}/swagger-ui-bundle.js",
        swagger_css_url=f"{swagger}/swagger-ui.css",
        swagger_favicon_url=f"{swagger}/favicon-32x32.png",
        oauth2_redirect_url=None)


def static_files():
    """The ASGI app that serves ``STATIC`` (mounted at ``STATIC_URL``)."""
    return StaticFiles(directory=STATIC)
