"""A camera's bearings from pixels, fast and approximate: the radius-to-angle curve tabulated once."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.camera_model import CameraModel, monotonic_limit, radius

FloatArray = NDArray[np.float64]


class BearingTable:
    """Fast approximate unprojection for the collinearity test: theta(r) tabulated once per camera."""

    def __init__(self, model: CameraModel, samples: int = 4096) -> None:
        self.model = model
        limit = monotonic_limit(model.k)
        self.theta = np.linspace(0.0, limit, samples)
        self.radius = radius(model.k, self.theta)

    def __call__(self, uv: FloatArray) -> FloatArray:
        """(N, 3) unit bearings of (N, 2) pixels (radii beyond the table are clamped)."""
        xy = (uv - self.model.principal_point) / self.model.m
        r = np.hypot(xy[:, 0], xy[:, 1])
        theta = np.interp(r, self.radius, self.theta)
        scale = np.where(r > 0, np.sin(theta) / np.where(r > 0, r, 1.0), 1.0 / self.model.k[0])
        return np.column_stack([xy * scale[:, None], np.cos(theta)])
