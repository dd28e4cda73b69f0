"""Errors of live collection and of calibrating what was collected."""

from __future__ import annotations

from wand_calib_ros.errors import WandCalibError


class CollectionError(WandCalibError):
    """Base class of this subpackage's errors."""


class CoverageError(CollectionError):
    """The collected wand data does not yet cover what a calibration needs.

    Attributes:
        missing: one plain line per problem (e.g. "cam2: corners top-left, bottom-right uncovered").
    """

    def __init__(self, missing: list[str]) -> None:
        super().__init__("coverage insufficient: " + " | ".join(missing))
        self.missing = tuple(missing)
