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
        model = self.model
        xy = (uv - model.principal_point) / model.m
        r = np.hypot(xy[:, 0], xy[:, 1])
        theta = np.interp(r, self.radius, self.theta)
        off_axis = r > 0  # (on the axis: sin(theta) / r's limit, 1 / k1)
        scale = (
            np.sin(theta) / r
            if off_axis.all()
            else np.where(off_axis, np.sin(theta) / np.where(off_axis, r, 1.0), 1.0 / model.k[0])
        )
        bearings = np.empty((r.shape[0], 3))  # (filled in place: a few points' column_stack costs more than its maths)
        np.multiply(xy, scale[:, None], out=bearings[:, :2])
        np.cos(theta, out=bearings[:, 2])
        return bearings
