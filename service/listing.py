"""Paginated listings of the store's meshes and scenes (``GET /v1/meshes``, ``GET /v1/scenes``)."""

from datetime import UTC, datetime
from typing import Annotated

from fastapi import Query

from service.schemas import Listing, Stored

#: The most entries one page holds.
MAX_PAGE = 1000

Limit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="Entries per page")]
Offset = Annotated[int, Query(ge=0, description="Entries to skip, in id order")]


def page(entries, limit, offset):
    """One page of ``entries`` (``(id, bytes, last used)``, in order), as a :class:`Listing`."""
    chosen = entries[offset:offset + limit]
    following = offset + len(chosen)
    return Listing(items=[Stored(id=key, bytes=nbytes,
                                 last_used=datetime.fromtimestamp(used, UTC))
                          for key, nbytes, used in chosen],
                   total=len(entries),
                   next_offset=following if chosen and following < len(entries) else None)
