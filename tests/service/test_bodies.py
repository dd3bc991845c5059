"""service.bodies.read_body against bodies that do and do not match their Content-Length."""

import anyio
import numpy as np
import pytest
from starlette.requests import Request

from service.bodies import read_body
from service.errors import BadRequest


def request_with(chunks, content_length):
    """A Starlette request whose body arrives in ``chunks``, announcing ``content_length``."""
    headers = [] if content_length is None else [(b"content-length", str(content_length).encode())]
    messages = [{"type": "http.request", "body": chunk, "more_body": i + 1 < len(chunks)}
                for i, chunk in enumerate(chunks)]

    async def receive():
        return messages.pop(0)

    return Request({"type": "http", "method": "POST", "headers": headers}, receive)


@pytest.mark.parametrize("content_length", [11, None])
def test_the_body_arrives_whole(content_length):
    chunks = [b"hello", b" ", b"world"]
    body = anyio.run(read_body, request_with(chunks, content_length))
    assert bytes(np.asarray(memoryview(body))) == b"hello world"


@pytest.mark.parametrize("declared, words", [(4, "longer"), (20, "has 11 bytes")])
def test_a_body_that_contradicts_its_content_length_is_refused(declared, words):
    with pytest.raises(BadRequest, match=words):
        anyio.run(read_body, request_with([b"hello", b" ", b"world"], declared))
