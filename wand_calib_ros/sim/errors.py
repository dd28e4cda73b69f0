"""Errors of the simulations."""

from __future__ import annotations

from wand_calib_ros.errors import WandCalibError


class SimulationError(WandCalibError):
    """A simulated take that cannot be made or written as asked."""
