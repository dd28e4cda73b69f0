"""Bright-blob extraction: LED spots with sub-pixel, background-subtracted centres.

The threshold is relative to the frame: the background level and its noise
come from the median and the median absolute deviation of the image, and a
pixel belongs to a blob when it stands clearly above both the noise and a
fraction of the brightest pixel. Connected components are measured in a small
window around each: the centre is the intensity-weighted mean of the
background-subtracted pixels (exact for symmetric spots), the size gates
reject single hot pixels and large reflections.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.errors import ImageError

FloatArray = NDArray[np.float64]

#: Encodings accepted by :func:`to_gray` (sensor_msgs/Image names).
ENCODINGS = (
    "mono8",
    "mono16",
    "bgr8",
    "rgb8",
    "bgra8",
    "rgba8",
    "bayer_rggb8",
    "bayer_bggr8",
    "bayer_gbrg8",
    "bayer_grbg8",
)

_BAYER = {
    "bayer_rggb8": cv2.COLOR_BayerRG2GRAY,
    "bayer_bggr8": cv2.COLOR_BayerBG2GRAY,
    "bayer_gbrg8": cv2.COLOR_BayerGB2GRAY,
    "bayer_grbg8": cv2.COLOR_BayerGR2GRAY,
}


@dataclass(frozen=True)
class BlobOptions:
    """Blob extraction settings.

    Attributes:
        noise_sigmas: a blob pixel stands this many background noise sigmas above the background.
        peak_fraction: ... and above this fraction of the frame's brightest pixel (above background).
        min_area: smallest component (px) that counts as an LED.
        max_area: largest component (px); larger ones are reflections or lamps.
        window: half size (px) of the window around a component used for its centre.
    """

    noise_sigmas: float = 8.0
    peak_fraction: float = 0.25
    min_area: int = 2
    max_area: int = 400
    window: int = 3


@dataclass(frozen=True, eq=False)
class Blobs:
    """Blobs of one image.

    Attributes:
        centres: (N, 2) sub-pixel centres, OpenCV pixel convention.
        areas: (N,) pixels above the threshold.
        peaks: (N,) brightest value above background.
        saturated: (N,) True where a pixel reached the image's maximum value.
        at_border: (N,) True where the blob touches the image border (cut: its centre is pulled
            inwards); None: none does.
    """

    centres: FloatArray
    areas: NDArray[np.int64]
    peaks: FloatArray
    saturated: NDArray[np.bool_]
    at_border: NDArray[np.bool_] | None = None

    def cut(self, index: list[int]) -> bool:
        """Whether any of the blobs ``index`` touches the image border."""
        return self.at_border is not None and bool(self.at_border[index].any())


def to_gray(image: NDArray[Any], encoding: str) -> NDArray[Any]:
    """A single-channel image (uint8, or uint16 for mono16) from a decoded sensor_msgs/Image array.

    Raises:
        ImageError: unknown encoding or an array that does not match it.
    """
    if encoding not in ENCODINGS:
        raise ImageError(f"unsupported image encoding '{encoding}' (supported: {', '.join(ENCODINGS)})")
    array = np.asarray(image)
    colour = encoding in ("bgr8", "rgb8", "bgra8", "rgba8")
    if array.ndim != (3 if colour else 2) or (colour and array.shape[2] != len(encoding) - 1):
        raise ImageError(f"image of shape {array.shape} does not match encoding '{encoding}'")
    if array.size == 0:
        raise ImageError("empty image")
    if encoding in _BAYER:
        array = cv2.cvtColor(array.astype(np.uint8), _BAYER[encoding])
    elif colour:
        code = {
            "bgr8": cv2.COLOR_BGR2GRAY,
            "rgb8": cv2.COLOR_RGB2GRAY,
            "bgra8": cv2.COLOR_BGRA2GRAY,
            "rgba8": cv2.COLOR_RGBA2GRAY,
        }[encoding]
        array = cv2.cvtColor(array.astype(np.uint8), code)
    return array if array.dtype in (np.uint8, np.uint16) else array.astype(np.float32)


def find_blobs(gray: NDArray[Any], options: BlobOptions = BlobOptions(), *, saturation: float = 255.0) -> Blobs:
    """Bright blobs of a grey image (see the module docstring).

    Args:
        gray: (H, W) single-channel image (any numeric dtype).
        options: thresholds and gates.
        saturation: the image's maximum value (255 for 8 bit, 65535 for 16 bit).
    """
    height, width = gray.shape
    # Background and noise from a sparse sample of pixels (fast and robust: LEDs cover few pixels).
    sample = gray[:: max(1, height // 32), :: max(1, width // 32)].astype(np.float64)
    background = float(np.median(sample))
    noise = max(1.4826 * float(np.median(np.abs(sample - background))), 0.5)
    peak = float(cv2.minMaxLoc(gray)[1] if gray.dtype == np.uint8 else gray.max()) - background
    empty = Blobs(np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0, dtype=bool))
    if peak <= options.noise_sigmas * noise:
        return empty
    threshold = background + max(options.noise_sigmas * noise, options.peak_fraction * peak)
    if gray.dtype == np.uint8:  # OpenCV's threshold is several times faster than numpy on 8 bit
        mask = cv2.threshold(gray, float(np.floor(threshold)), 1, cv2.THRESH_BINARY)[1]
    else:
        mask = (gray > threshold).astype(np.uint8)
    # External contours of a sparse mask are much cheaper than labelling the whole image.
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    centres, areas, peaks, saturated, at_border = [], [], [], [], []
    w = options.window
    for contour in contours:
        x, y, bw, bh = cv2.boundingRect(contour)
        area = int(mask[y : y + bh, x : x + bw].sum())
        if not (options.min_area <= area <= options.max_area):
            continue
        x0, y0 = max(x - w, 0), max(y - w, 0)
        x1, y1 = min(x + bw + w, width), min(y + bh + w, height)
        window = gray[y0:y1, x0:x1].astype(np.float64)
        weights = np.clip(window - (background + 0.5 * options.noise_sigmas * noise), 0.0, None)
        total = float(weights.sum())
        if total <= 0:
            continue
        centres.append(
            [
                float(weights.sum(axis=0) @ np.arange(x0, x1)) / total,
                float(weights.sum(axis=1) @ np.arange(y0, y1)) / total,
            ]
        )
        areas.append(area)
        peaks.append(float(window.max()) - background)
        saturated.append(bool(window.max() >= saturation))
        at_border.append(x == 0 or y == 0 or x + bw == width or y + bh == height)
    if not centres:
        return empty
    return Blobs(
        np.array(centres, dtype=np.float64),
        np.array(areas, dtype=np.int64),
        np.array(peaks, dtype=np.float64),
        np.array(saturated, dtype=bool),
        np.array(at_border, dtype=bool),
    )
