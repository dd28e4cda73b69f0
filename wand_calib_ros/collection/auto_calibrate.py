"""auto_calibrate: the final calibration started by itself once coverage is ready and the running estimate
converged, without a ``/calibrate`` call.

:class:`AutoCalibrate` decides when, and remembers what it did: not started, calibrating, or failed (a later
round of the running estimate retries). The collection session asks it once a second; the calibrator tells it
when its calibration ended.
"""

from __future__ import annotations

from wand_calib_ros.collection.estimate import Estimate, converged

#: What /diagnostics shows while the calibration it started runs.
CALIBRATING = "calibrating"


class AutoCalibrate:
    """When auto_calibrate starts the final calibration (see the module docstring).

    Args:
        focal_std_percent: every camera's focal-length standard deviation at most this (% of it).
        principal_std_px: every camera's principal-point standard deviation at most this (px).
    """

    def __init__(self, focal_std_percent: float, principal_std_px: float) -> None:
        self.focal_std_percent, self.principal_std_px = focal_std_percent, principal_std_px
        self._state: str | None = None  # None: not started; CALIBRATING; or why it failed
        self._round: Estimate | None = None  # the estimate's round that started it

    def due(self, ready: bool, latest: Estimate | None, calibrated: bool) -> bool:
        """Whether to start now: coverage ``ready``, the ``latest`` round converged, no calibration since the
        take began or running, and after a failed try a newer round than the one that started it."""
        if calibrated or self._state == CALIBRATING:
            return False
        if not ready or latest is None or latest.round.result is None:
            return False
        if not converged(latest.round.result, self.focal_std_percent, self.principal_std_px):
            return False
        return self._state is None or self._round is not latest

    def started(self, latest: Estimate) -> str:
        """The calibration started on the round ``latest``: what to say."""
        self._state, self._round = CALIBRATING, latest
        return (
            f"auto-calibrate: coverage is ready and every camera's focal length is within "
            f"+-{self.focal_std_percent:g} % and principal point within +-{self.principal_std_px:g} px: calibrating"
        )

    def done(self, success: bool, message: str) -> None:
        """The calibration it started ended (the calibrator's thread): a failure lets a later round retry."""
        if not success:
            self._state = f"failed, retrying after the next round: {message}"

    def reset(self) -> None:
        """A new take: not started."""
        self._state = None

    def shown(self, calibrated: bool) -> str | None:
        """Its state for /diagnostics (None: it has not started)."""
        if self._state is None:
            return None
        return "calibrated" if calibrated else self._state
