"""sensor_msgs/Image pixels as numpy arrays, for messages of rclpy and of rosbags alike.

Both message classes carry ``height``, ``width``, ``step``, ``encoding``,
``is_bigendian`` and ``data``; this is the one place that turns them into an array.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Bytes per pixel of the encodings the detector reads (Bayer images are read as grey).
BYTES_PER_PIXEL = {
    "mono8": 1,
    "mono16": 2,
    "bgr8": 3,
    "rgb8": 3,
    "bgra8": 4,
    "rgba8": 4,
    "bayer_rggb8": 1,
    "bayer_bggr8": 1,
    "bayer_gbrg8": 1,
    "bayer_grbg8": 1,
}


def image_array(message: Any) -> NDArray[Any]:
    """(H, W) or (H, W, channels) pixels of a sensor_msgs/Image (a view of 8-bit data, no copy).

    An encoding outside :data:`BYTES_PER_PIXEL` gives an empty (0, 0) array: the detector then
    reports the encoding as unusable.

    Raises:
        ValueError: the data do not hold ``height`` rows of ``step`` bytes, or the step is too small.
    """
    encoding = message.encoding
    if encoding not in BYTES_PER_PIXEL:
        return np.zeros((0, 0), np.uint8)
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.frombuffer(message.data, dtype=np.uint8) if not isinstance(message.data, np.ndarray) else message.data
    per_pixel = BYTES_PER_PIXEL[encoding]
    if height * step > data.size or step < width * per_pixel:
        raise ValueError(f"image data of {data.size} bytes do not fit {width}x{height} {encoding} (step {step})")
    rows = data[: height * step].reshape(height, step)[:, : width * per_pixel]
    if encoding == "mono16":
        dtype = ">u2" if message.is_bigendian else "<u2"
        return rows.copy().view(dtype).reshape(height, width).astype(np.uint16)
    return rows.reshape(height, width, per_pixel) if per_pixel > 1 else rows
