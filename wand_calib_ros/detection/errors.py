"""Errors of the detection package."""

from __future__ import annotations

from wand_calib_ros.errors import WandCalibError


class DetectionError(WandCalibError):
    """Base class of the detection errors."""


class ImageError(DetectionError):
    """An image that cannot be used (unknown encoding, wrong size, empty)."""


class UnsupportedWandError(DetectionError):
    """A wand the LED detector cannot find (it finds the paper's three collinear LEDs)."""


class MaskError(DetectionError):
    """A mask that cannot be used (not an image, not the camera's size)."""
