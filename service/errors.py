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


class NotAcceptable(ClientError):
    """The Accept header asks for an answer type that the request cannot have (406)."""

    status = 406


class UnsupportedMedia(ClientError):
    """The body's content type is not one the endpoint reads (415)."""

    status = 415


def validation_detail(problems, shown=3):
    """One line naming the first ``shown`` problems of a pydantic validation, ``loc: msg`` each.

    Parameters
    ----------
    problems : list of dict
        ``ValidationError.errors()``, or its items' ``loc`` and ``msg``.
    """
    detail = "; ".join(".".join(map(str, problem["loc"])) + ": " + problem["msg"]
                       for problem in problems[:shown])
    if len(problems) > shown:
        detail += f" (and {len(problems) - shown} more)"
    return detail
