import pytest


@pytest.fixture(params=["float64", "float32"])
def dtype(request):
    """Both precisions the kernels are compiled for."""
    return request.param
