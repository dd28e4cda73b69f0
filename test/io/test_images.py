"""sensor_msgs/Image data to arrays: padded rows, 16-bit byte order, colour, and too little data."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from wand_calib_ros.io.images import image_array


def _message(pixels: np.ndarray, encoding: str, *, pad: int = 0, big: bool = False) -> SimpleNamespace:
    rows = pixels.astype(pixels.dtype.newbyteorder(">" if big else "<")) if pixels.dtype.itemsize > 1 else pixels
    raw = rows.reshape(pixels.shape[0], -1).view(np.uint8)
    padded = np.hstack([raw, np.zeros((raw.shape[0], pad), np.uint8)])
    return SimpleNamespace(
        height=pixels.shape[0],
        width=pixels.shape[1],
        step=padded.shape[1],
        encoding=encoding,
        is_bigendian=int(big),
        data=padded.tobytes(),
    )


@pytest.mark.parametrize("big", [False, True])
def test_mono16_either_byte_order_with_row_padding(big: bool) -> None:
    pixels = np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000
    assert np.array_equal(image_array(_message(pixels, "mono16", pad=6, big=big)), pixels)


def test_colour_and_mono8_keep_their_shape() -> None:
    colour = np.random.default_rng(0).integers(0, 255, size=(5, 7, 3), dtype=np.uint8)
    assert np.array_equal(image_array(_message(colour, "bgr8", pad=3)), colour)
    grey = colour[:, :, 0].copy()
    assert np.array_equal(image_array(_message(grey, "mono8")), grey)


def test_truncated_data_and_unknown_encodings() -> None:
    message = _message(np.zeros((4, 4), np.uint8), "mono8")
    message.data = message.data[:10]
    with pytest.raises(ValueError, match="do not fit 4x4 mono8"):
        image_array(message)
    assert image_array(_message(np.zeros((2, 2), np.uint8), "yuv422")).shape == (0, 0)
