"""Debug overlays: an image with its blobs and the chosen A, B, C drawn on it."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.blobs import Blobs, to_gray
from wand_calib_ros.detection.errors import ImageError
from wand_calib_ros.detection.wand import WandDetection

_COLOURS = {"A": (0, 0, 255), "B": (0, 200, 0), "C": (255, 0, 0)}  # BGR


def draw_overlay(
    image: NDArray[Any],
    encoding: str,
    blobs: Blobs | None,
    detection: WandDetection | None,
    reason: str | None,
    mask: NDArray[np.uint8] | None = None,
) -> NDArray[np.uint8]:
    """A BGR picture: the mask's outlines in magenta, blobs as grey circles, A/B/C in red/green/blue, the
    rejection reason as text. ``mask``: (H, W), non-zero where the detector ignores pixels."""
    try:
        gray = to_gray(image, encoding)
    except ImageError:
        gray = np.zeros((64, 64), np.uint8)
    if gray.dtype != np.uint8:
        gray = np.clip(gray.astype(np.float64) / max(float(gray.max()), 1.0) * 255, 0, 255).astype(np.uint8)
    picture = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    if mask is not None and mask.shape == gray.shape:
        outlines, _ = cv2.findContours((mask > 0).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(picture, outlines, -1, (255, 0, 255), 1)
    if blobs is not None:
        for u, v in blobs.centres:
            cv2.circle(picture, (round(float(u)), round(float(v))), 8, (160, 160, 160), 1)
    if detection is not None and detection.points is not None:
        for label, (u, v) in zip("ABC", detection.points, strict=True):
            centre = (round(float(u)), round(float(v)))
            cv2.circle(picture, centre, 5, _COLOURS[label], 2)
            cv2.putText(
                picture, label, (centre[0] + 7, centre[1] - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.5, _COLOURS[label], 1
            )
    text = reason if reason else ("ambiguous A/C" if detection is not None and detection.ambiguous else "wand")
    cv2.putText(picture, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 255, 255), 1)
    return np.asarray(picture, dtype=np.uint8)
