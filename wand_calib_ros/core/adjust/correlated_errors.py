"""Centre errors that follow one another from image to image, and the covariance that allows for them.

The adjustment's covariance (sigma^2 S^-1) takes every residual as an independent draw. A detector's centre
errors need not be: a spot that changes slowly as the wand moves (its size, its brightness, the lamp beside it)
is measured wrong by nearly as much in the next image, and a camera's parameters then learn less from a take
than its count of views says. In a room rendered near the cameras, the same LED's centre errors in one camera
are correlated by about 0.4 one image apart and 0.2 two apart: the information is overstated about twice and
the standard deviations come out about 1.5 times too small.

The residuals tell it: for each camera and LED, residuals of placements k apart (in the order of the views'
rows: their frames) are correlated by rho_k, each camera's residuals scaled by their own RMS and the cameras
pooled. A parameter estimated from n such residuals has the variance of n / (1 + 2 sum rho_k) independent ones
(the effective sample size of a correlated series), so the covariance is widened by that factor. Only lags whose
correlation stands out of what independent residuals show (SIGNIFICANT standard errors, 1 / sqrt(pairs)) count,
from lag 1 up to the first that does not: independent errors leave the covariance exactly as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import camera_std
from wand_calib_ros.core.adjust.linearisation import squared_norms

if TYPE_CHECKING:
    from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: The longest lag looked at (placements): the lags counted stop at the first that does not stand out, and a real
#: recording's (eWand's four cameras) still do at 39 (0.62 one view apart, 0.15 twenty apart).
MAX_LAG = 50
#: A lag's correlation counts when it is this many standard errors (1 / sqrt(its pairs)) above zero.
SIGNIFICANT = 3.0


@dataclass(frozen=True)
class ErrorCorrelation:
    """How a take's residuals follow one another from placement to placement (every camera's LEDs pooled).

    Attributes:
        lags: (K,) the correlation of residuals 1..K placements apart, up to the first lag that does not stand out
            (K = 0: none does).
        factor: the variance factor 1 + 2 sum(lags) the covariance is widened by (1: independent errors).
    """

    lags: tuple[float, ...]
    factor: float

    @property
    def std_factor(self) -> float:
        """How much wider the standard deviations are: sqrt(factor)."""
        return float(np.sqrt(self.factor))

    def line(self) -> str | None:
        """What the result says of it, in plain words (None: the errors are independent)."""
        if not self.lags:
            return None
        return (
            f"the centres' errors follow one another from view to view (correlated {self.lags[0]:.2f} between "
            f"neighbours, over {len(self.lags)} view{'s' if len(self.lags) > 1 else ''}): the views hold less than "
            f"their count says, and the standard deviations are widened {self.std_factor:.2f}x for it"
        )


def error_correlation(
    residuals: FloatArray, camera: IntArray, point: IntArray, time: IntArray, n_cameras: int
) -> ErrorCorrelation:
    """The residuals' correlation from placement to placement (see the module docstring).

    Args:
        residuals: (M, 2) reprojection residuals, px.
        camera: (M,) each one's camera.
        point: (M,) its point of the wand (0..N-1).
        time: (M,) its placement's row in the views (their frame order: neighbouring rows are views one after the
            other; rows in no time order show no correlation, and nothing is widened).
        n_cameras: C.
    """
    if residuals.shape != (camera.size, 2) or not camera.size == point.size == time.size:
        raise ValueError(f"residuals {residuals.shape} and indices of {camera.size}, {point.size}, {time.size}")
    if not residuals.size:
        return ErrorCorrelation((), 1.0)
    counts = np.bincount(camera, minlength=n_cameras)
    scale = np.sqrt(np.bincount(camera, squared_norms(residuals), n_cameras) / np.maximum(2 * counts, 1))
    scaled = residuals / np.where(scale > 0, scale, 1.0)[camera, None]
    n_points = int(point.max()) + 1
    start = int(time.min())
    series = np.full((int(time.max()) - start + 1, n_cameras * n_points, 2), np.nan)
    series[time - start, camera * n_points + point] = scaled
    lags: list[float] = []
    for lag in range(1, min(MAX_LAG, series.shape[0] - 1) + 1):
        first, then = series[:-lag], series[lag:]
        both = np.isfinite(first) & np.isfinite(then)
        pairs = int(both.sum())
        if pairs < 2:
            break
        a, b = first[both], then[both]
        rho = float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))
        if rho <= SIGNIFICANT / np.sqrt(pairs):
            break
        lags.append(rho)
    return ErrorCorrelation(tuple(lags), 1.0 + 2.0 * float(np.sum(lags)))


def widened(result: BundleResult, correlation: ErrorCorrelation) -> BundleResult:
    """``result`` with its camera covariance and standard deviations widened by the correlation's factor (its
    normal equations, ``result.system``, stay the adjustment's own)."""
    if correlation.factor == 1.0:
        return result
    covariance = result.camera_covariance * correlation.factor
    return replace(result, camera_covariance=covariance, camera_std=camera_std(covariance))
