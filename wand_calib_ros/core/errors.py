"""Errors of the numerical core."""

from __future__ import annotations

from wand_calib_ros.errors import WandCalibError


class CoreError(WandCalibError):
    """Base class of the core's errors."""


class ModelError(CoreError):
    """A camera model that cannot be used (e.g. r(theta) turns over inside the image)."""


class InsufficientDataError(CoreError):
    """Too few usable wand placements for the requested step."""


class DegenerateDataError(CoreError):
    """The data cannot determine the calibration (e.g. the wand hardly moved)."""


class CalibrationFailedError(CoreError):
    """An optimisation step failed to produce a usable result."""


class TimingError(CoreError):
    """Stamps or time offsets that cannot describe when the cameras saw the wand."""


class PlausibilityError(CoreError):
    """A rig description, its views or a calibration that cannot be physically right."""
