"""The API key: when ``RAYCORE_API_KEY`` is set, the endpoints that change the store (uploads,
scene builds, deletions) need it, as ``X-API-Key: <key>`` or ``Authorization: Bearer <key>``."""

import hmac
from typing import Annotated

from fastapi import HTTPException, Request, Security
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from service.runtime import runtime

_KEY_HEADER = APIKeyHeader(
    name="X-API-Key", auto_error=False,
    description="The service's API key (RAYCORE_API_KEY), needed by endpoints that change the "
                "store when the service is configured with one")
_BEARER = HTTPBearer(auto_error=False, description="The API key as a bearer token, the same as "
                                                   "X-API-Key")


async def require_api_key(
        request: Request, key: Annotated[str | None, Security(_KEY_HEADER)],
        bearer: Annotated[HTTPAuthorizationCredentials | None, Security(_BEARER)]):
    """FastAPI dependency: 401 unless the request carries the configured key (or none is)."""
    expected = runtime(request).settings.api_key
    if expected is None:
        return
    given = [value for value in (key, bearer.credentials if bearer is not None else None)
             if value is not None]
    if not given:
        raise HTTPException(401, "this endpoint needs the API key: send it as X-API-Key or "
                                 "Authorization: Bearer", headers={"WWW-Authenticate": "Bearer"})
    # every key sent must be right (a wrong one beside a right one is still refused), compared
    # in constant time: the comparison must not tell how much of a guess was right
    if not all([hmac.compare_digest(value.encode(), expected.encode()) for value in given]):
        raise HTTPException(401, "the API key is wrong", headers={"WWW-Authenticate": "Bearer"})
