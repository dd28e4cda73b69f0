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


#: CompressedImage formats as image_transport's compressed plugin writes them, per raw encoding.
_JPEG_FORMATS = {"mono8": "mono8; jpeg compressed mono8", "bgr8": "bgr8; jpeg compressed bgr8"}


def encode_compressed(image: NDArray[Any], encoding: str, quality: int = 90) -> tuple[bytes, str]:
    """(data, format) of a sensor_msgs/CompressedImage holding an 8-bit image as JPEG (mono8, or colour).

    Raises:
        ValueError: an encoding JPEG cannot hold (16-bit, Bayer).
    """
    import cv2

    if encoding == "rgb8":
        image, encoding = cv2.cvtColor(np.asarray(image), cv2.COLOR_RGB2BGR), "bgr8"
    if encoding not in _JPEG_FORMATS:
        raise ValueError(f"JPEG holds mono8 or colour images, not {encoding}")
    ok, data = cv2.imencode(".jpg", np.asarray(image), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV encodes any 8-bit image
        raise ValueError(f"OpenCV could not encode a {encoding} image as JPEG")
    return bytes(data), _JPEG_FORMATS[encoding]


def decode_compressed(data: bytes | NDArray[np.uint8], fmt: str) -> tuple[NDArray[Any], str]:
    """(pixels, encoding) of a sensor_msgs/CompressedImage's data: JPEG as its grey (luma) image, which is all
    the detector reads (libjpeg decodes it without the colour); PNG as stored (mono8, mono16, bgr8 or bgra8).

    Raises:
        ValueError: data that neither decoder reads.
    """
    import cv2

    buffer = np.frombuffer(bytes(data), dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    png = "png" in fmt.lower() or bytes(buffer[:4]) == b"\x89PNG"
    image = cv2.imdecode(buffer, cv2.IMREAD_UNCHANGED if png else cv2.IMREAD_GRAYSCALE) if buffer.size else None
    if image is None:
        raise ValueError(f"compressed image ({fmt or 'no format'}, {buffer.size} bytes) could not be decoded")
    if image.ndim == 2:
        return image, "mono16" if image.dtype == np.uint16 else "mono8"
    if image.dtype != np.uint8:
        image = (np.asarray(image, dtype=np.uint16) // 256).astype(np.uint8)
    return image, "bgr8" if image.shape[2] == 3 else "bgra8"
