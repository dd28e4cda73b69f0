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

A saturated spot is measured by its outline instead (:func:`saturated_centre`): the light above SATURATED_FLOOR
of the way from its background to full scale, clipped there. Its flat top and the steep edge around it are the
LED's own light (the edge, where the light falls from full scale to the floor, is what places it to a few
hundredths of a pixel); a faint glare halo, another LED's halo or a gradient of the room under it stay below
the floor, a symmetric bloom above it pulls nothing, and the outline of a saturated streak is as symmetric about
its mid-exposure position as the streak. Across a bright edge (a window's, a reflection's) the
LED clips at less of its own light where the room is bright: every pixel is clipped at the least light any of
them can show, and the outline stays symmetric.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

Pixels = NDArray[np.floating[Any]]


#: A saturated spot's outline is its light above this fraction of the way from its background to full scale (at
#: half-way the edge is a quarter of a pixel wide 30x over full scale, and its centre pixel-locked to 0.06 px RMS;
#: here 0.02 px, the light of another LED's glare still below it).
SATURATED_FLOOR = 0.125


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


@functools.cache
def _centred(count: int) -> NDArray[np.float32]:
    """(count,) pixel offsets from a window's middle (float32; kept per size: read only)."""
    offsets = np.arange(count, dtype=np.float32) - np.float32((count - 1) / 2.0)
    offsets.flags.writeable = False
    return offsets


def side_medians(window: Pixels) -> tuple[float, float, float, float]:
    """The medians of a window's (left, right, top, bottom) sides (a middle value for an even count)."""
    height, width = window.shape
    # (sorted Python lists: a side has a few dozen pixels, where numpy's per-call cost is most of the work)
    left, right, top, bottom = window[:, 0].tolist(), window[:, -1].tolist(), window[0].tolist(), window[-1].tolist()
    for side in (left, right, top, bottom):
        side.sort()
    return float(left[height // 2]), float(right[height // 2]), float(top[width // 2]), float(bottom[width // 2])


def side_plane(window: Pixels, sides: tuple[float, float, float, float] | None = None) -> tuple[float, float, float]:
    """(level at the window's centre, slope along u, slope along v) of a plane through the medians of the
    window's four sides (grey levels, per px; ``sides``: those medians when they are known)."""
    height, width = window.shape
    left, right, top, bottom = side_medians(window) if sides is None else sides
    slope_u = (right - left) / max(width - 1, 1)
    slope_v = (bottom - top) / max(height - 1, 1)
    return 0.25 * (left + right + top + bottom), slope_u, slope_v


def spot_centre(
    window: Pixels,
    floor: float,
    region: NDArray[np.bool_] | None = None,
    sides: tuple[float, float, float, float] | None = None,
) -> SpotCentre | None:
    """The centre of the spot in a window (see the module docstring), or None when nothing stands above the floor.

    Args:
        window: (h, w) pixels around the spot, at least 3x3, the spot inside and the window's sides on background.
        floor: how far above the background plane a pixel must be to count, grey levels.
        region: (h, w) the pixels that may count (one of two spots that touch), or None: all.
        sides: the window's :func:`side_medians`, when they are known.
    """
    height, width = window.shape
    level, slope_u, slope_v = side_plane(window, sides)
    # the light above the plane and the floor (float32), from the plane's row and column terms
    weights = window.astype(np.float32, copy=False) - np.add.outer(
        _centred(height) * np.float32(slope_v) + np.float32(level + floor), _centred(width) * np.float32(slope_u)
    )
    peak = float(weights.max()) + floor
    np.maximum(weights, 0.0, out=weights)
    if region is not None:
        weights *= region
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
        peak,
        level + slope_u * du + slope_v * dv,
        length,
    )


def saturated_centre(
    window: Pixels, base: float, ceiling: float, region: NDArray[np.bool_] | None = None, least: float = 0.0
) -> SpotCentre:
    """The centre of a saturated spot (see the module docstring): the mean of its pixels weighted by how far they
    stand above SATURATED_FLOOR of the way from its background to the lowest full scale under it, clipped there.

    Args:
        window: (h, w) the spot's light around it (what the camera gave, less the static structure where it is known).
        base: the background under the spot in ``window``, grey levels.
        ceiling: the most light any of the spot's pixels can show above ``base`` before it clips (full scale less
            the brightest static light under it): every pixel is clipped there, so a spot across a bright edge
            stays symmetric.
        region: (h, w) the pixels that may count (its own, or one of two spots that touch), or None: all.
        least: the outline's floor is at least this far above ``base`` (a few of the noise's sigmas where it is
            highest under the spot: a bright window's noise beside it is not its light).
    """
    low = min(max(SATURATED_FLOOR * ceiling, least), 0.5 * ceiling)
    weights = np.minimum(np.maximum(window.astype(np.float32, copy=False) - np.float32(base + low), 0.0), ceiling - low)
    if region is not None:
        weights *= region
    moments = cv2.moments(weights)
    total = moments["m00"]
    height, width = window.shape
    if total <= 0.0:  # (nothing reaches the floor: the window's centre)
        return SpotCentre((width - 1) / 2.0, (height - 1) / 2.0, ceiling, base, 0.0)
    suu, svv, suv = moments["mu20"] / total, moments["mu02"] / total, moments["mu11"] / total
    spread = math.sqrt(max((suu - svv) ** 2 + 4.0 * suv**2, 0.0))
    return SpotCentre(moments["m10"] / total, moments["m01"] / total, ceiling, base, math.sqrt(12.0 * spread))
