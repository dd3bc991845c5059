"""Encoding at the edge: PNG, .npy answers, Accept headers."""

import io
import zlib

import numpy as np
import pytest
from PIL import Image

from service import codecs


# the last two are deflated in two halves at once
@pytest.mark.parametrize("shape", [(1, 1, 3), (7, 5, 3), (64, 48, 3), (150, 583, 3),
                                   (512, 512, 3)])
def test_png_decodes_to_the_image(shape):
    image = np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8)
    image[: shape[0] // 3] = 200  # compressible rows too
    encoded = codecs.png(image)
    decoded = np.asarray(Image.open(io.BytesIO(encoded)))
    np.testing.assert_array_equal(decoded, image)
    # one IDAT chunk, whose zlib stream's checksum holds (Pillow does not check it)
    start = encoded.index(b"IDAT")
    length = int.from_bytes(encoded[start - 4:start], "big")
    rows = zlib.decompress(encoded[start + 4:start + 4 + length])
    assert len(rows) == shape[0] * (1 + 3 * shape[1])


def test_npy_answer_is_a_structured_array_of_the_columns():
    columns = {"t": np.array([1.5, np.inf], np.float32), "geom_id": np.array([3, -1]),
               "prim_id": np.array([7, -1]), "normal": np.array([[0, 0, 1], [np.nan] * 3])}
    table = np.load(io.BytesIO(bytes(codecs.columns_to_npy(columns))), allow_pickle=False)
    assert table.dtype.names == ("t", "geom_id", "prim_id", "normal")
    assert table.dtype["geom_id"] == np.int32 and table.dtype["normal"].shape == (3,)
    np.testing.assert_array_equal(table["t"], columns["t"])
    np.testing.assert_array_equal(table["geom_id"], [3, -1])
    np.testing.assert_array_equal(table["normal"], columns["normal"])


def test_json_answer_has_null_for_misses():
    columns = {"t": np.array([2.0, np.inf]), "uv": np.array([[0.25, 0.5], [np.nan, np.nan]]),
               "occluded": np.array([True, False])}
    assert codecs.columns_to_json(columns) == (
        b'{"t":[2.0,null],"uv":[[0.25,0.5],null],"occluded":[true,false]}')


@pytest.mark.parametrize(("accept", "wanted"), [
    ("application/x-npy", True), ("application/json, application/x-npy;q=0.9", True),
    ("APPLICATION/X-NPY", True), ("application/json", False), ("", False), ("*/*", False),
])
def test_accept_header(accept, wanted):
    assert codecs.accepts_npy(accept) is wanted
