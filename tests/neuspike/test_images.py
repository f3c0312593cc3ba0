"""One 8-bit conversion and one PNG writer: round(255 x), clipping only where the caller says so."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from neuspike.errors import InputError
from neuspike.formats.images import encode_png, to_uint8, write_png


def test_round_trip_of_every_level_and_the_clip_rule(tmp_path):
    levels = np.arange(256, dtype=np.float64).reshape(16, 16) / 255.0
    assert np.array_equal(to_uint8(levels, clip=False), np.arange(256, dtype=np.uint8).reshape(16, 16))
    path = write_png(tmp_path / "levels.png", levels, clip=False)
    assert np.array_equal(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), to_uint8(levels, clip=False))
    hdr = np.array([[-0.5, 0.5, 1.5]])
    assert to_uint8(hdr, clip=True).tolist() == [[0, 128, 255]]  # round(127.5) is 128 (half to even)
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        to_uint8(hdr, clip=False)
    with pytest.raises(InputError, match="non-finite"):
        to_uint8(np.array([[np.nan]]), clip=True)


def test_an_8_bit_picture_is_written_as_it_is():
    sheet = np.arange(12, dtype=np.uint8).reshape(3, 4) * 20
    decoded = cv2.imdecode(np.frombuffer(encode_png(sheet, clip=False), np.uint8), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(decoded, sheet)
    with pytest.raises(InputError, match="2-D"):
        encode_png(np.zeros((2, 2, 3), np.uint8), clip=False)
