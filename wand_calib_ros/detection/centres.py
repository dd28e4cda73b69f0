"""The centre of one LED spot: what a calibration can trust to a tenth of a pixel.

A spot is measured in a window around it. Its background is a plane through the medians of
the window's four sides (a lamp's halo or the wall's gradient under the spot, not only its
level), and the centre is the mean of the pixels weighted by how far they stand above the
plane beyond a floor (half the contrast that found the spot, so the noise of the window's
dark pixels adds nothing). The weighting is symmetric, so it is exact for any symmetric
spot: a Gaussian, a saturated flat top with its halo, or a motion streak, whose centre is
where the LED was at mid-exposure when it moved evenly. The same moments give the streak's
length: a uniform streak of length L has variance L^2 / 12 along it beyond the spot's own.
A streak's centre is where the LED was on average over the exposure, weighted by its light:
an LED that sped up moves it by a T^2 / 24 from mid-exposure, one that brightened along the
streak by g L / 12 towards its bright end. It is not corrected: a streak brighter at one end
looks the same whether the LED brightened or slowed down there, and for the second the
weighted mean is already the better estimate (the streak's middle would be off by a T^2 / 8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

Pixels = NDArray[np.floating[Any]]


@dataclass(frozen=True)
class SpotCentre:
    """One spot's measurement.

    Attributes:
        u, v: the centre in the window's pixels (column, row; OpenCV convention: a pixel's centre is integral).
        peak: the brightest pixel above the background plane there, grey levels.
        background: the background plane at the centre, grey levels.
        length_px: the motion streak's length (0 for a still spot).
    """

    u: float
    v: float
    peak: float
    background: float
    length_px: float


def side_plane(window: Pixels) -> tuple[float, float, float]:
    """(level at the window's centre, slope along u, slope along v) of a plane through the medians of the
    window's four sides (grey levels, per px)."""
    height, width = window.shape
    # (sorted Python lists: a side has a few dozen pixels, where numpy's per-call cost is most of the work)
    left, right = (sorted(window[:, k].tolist())[height // 2] for k in (0, -1))  # (a middle value for an even count)
    top, bottom = (sorted(window[k].tolist())[width // 2] for k in (0, -1))
    slope_u = float(right - left) / max(width - 1, 1)
    slope_v = float(bottom - top) / max(height - 1, 1)
    return 0.25 * float(left + right + top + bottom), slope_u, slope_v


def spot_centre(window: Pixels, floor: float, region: NDArray[np.bool_] | None = None) -> SpotCentre | None:
    """The centre of the spot in a window (see the module docstring), or None when nothing stands above the floor.

    Args:
        window: (h, w) pixels around the spot, at least 3x3, the spot inside and the window's sides on background.
        floor: how far above the background plane a pixel must be to count, grey levels.
        region: (h, w) the pixels that may count (one of two spots that touch), or None: all.
    """
    height, width = window.shape
    level, slope_u, slope_v = side_plane(window)
    cols = np.arange(width, dtype=np.float32) - (width - 1) / 2.0
    rows = np.arange(height, dtype=np.float32) - (height - 1) / 2.0
    above = window.astype(np.float32, copy=False) - (level + slope_u * cols[None, :] + slope_v * rows[:, None])
    weights = np.maximum(above - floor, 0.0)
    if region is not None:
        weights = weights * region
    moments = cv2.moments(weights)  # one call for the sums the centre and the spread need
    total = moments["m00"]
    if total <= 0.0:
        return None
    du, dv = moments["m10"] / total - (width - 1) / 2.0, moments["m01"] / total - (height - 1) / 2.0
    suu, svv, suv = moments["mu20"] / total, moments["mu02"] / total, moments["mu11"] / total
    spread = math.sqrt(max((suu - svv) ** 2 + 4.0 * suv**2, 0.0))  # major minus minor variance
    length = math.sqrt(12.0 * spread)
    return SpotCentre(
        du + (width - 1) / 2.0,
        dv + (height - 1) / 2.0,
        float(above.max()),
        level + slope_u * du + slope_v * dv,
        length,
    )
