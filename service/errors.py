"""Errors a client caused, each with the HTTP status it is answered with.

Code below the routes raises these (converting the library's ``ValueError`` where it calls the
library); the app answers them as ``{"detail": message}``.
"""


class ClientError(Exception):
    """The request is well-formed but cannot be processed (422)."""

    status = 422


class BadRequest(ClientError):
    """The body cannot be decoded (400)."""

    status = 400


class NotFound(ClientError):
    """An id names nothing in the store (404)."""

    status = 404


class LimitExceeded(ClientError):
    """The request asks for more than the configured limits allow (413)."""

    status = 413


class UnsupportedMedia(ClientError):
    """The body's content type is not one the endpoint reads (415)."""

    status = 415
