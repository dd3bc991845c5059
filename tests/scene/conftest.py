"""Fixtures of the Scene tests; the shared helpers live in :mod:`brute`."""

import pytest

from .brute import DTYPES


@pytest.fixture(params=DTYPES)
def dtype(request):
    """Both precisions of a Scene."""
    return request.param
