"""Outliers: the paper's |AC| gate on placements, the robust (Huber) adjustment, the per-view gate,
and the re-admission of placements set aside once the cameras are solved."""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import DECIDING_SETTLED, BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import BundleProblem, BundleState, PlacementTiming
from wand_calib_ros.core.adjust.linearisation import residuals, squared_norms
from wand_calib_ros.core.adjust.normal_equations import block_starts
from wand_calib_ros.core.adjust.placements import fit_placements
from wand_calib_ros.core.model.rig import RigSpec, WandSpec
from wand_calib_ros.core.model.views import enough_views, observed_points, whole_views

#: Fewest views a camera must keep in the final bundle adjustment (its 11 parameters need several).
MIN_CAMERA_VIEWS = 5

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: The paper's gate: placements whose |AC| is off by more than this fraction of L are dropped.
GATE_FRACTION = 0.01
#: ... unless that is within this many robust standard deviations of the |AC| errors (high noise).
GATE_SIGMAS = 5.0
#: Floor of the robust noise estimate, px (detections are never better than this).
MIN_SIGMA_PX = 0.02
#: Huber threshold of the robust pass, in robust sigmas.
HUBER_SIGMAS = 2.0
#: A camera view with a point further than this many robust sigmas from its reprojection is an outlier.
VIEW_GATE_SIGMAS = 5.0


def ac_length_errors(points: FloatArray, wand: WandSpec) -> FloatArray:
    """(P,) L - |A^r C^r| in mm (first marker to last)."""
    return wand.L - np.linalg.norm(points[:, -1] - points[:, 0], axis=-1)


def gate_threshold(errors: FloatArray, wand: WandSpec) -> float:
    """The |AC| gate in mm: the paper's 1 % of L, widened to 5 robust sigmas when noise is high."""
    finite = errors[np.isfinite(errors)]
    mad_sigma = 1.4826 * float(np.median(np.abs(finite - np.median(finite)))) if finite.size else 0.0
    return max(GATE_FRACTION * wand.L, GATE_SIGMAS * mad_sigma)


def gate_placements(rig: RigSpec, uv: FloatArray, errors: FloatArray, threshold: float) -> NDArray[np.bool_]:
    """(P,) placements the |AC| gate keeps.

    A camera whose chained start is off (its pair saw a shared camera's intrinsics differently)
    makes every placement it sees reconstruct too long or too short by about the same amount.
    Should the gate leave it fewer than half its views, its placements are gated around their
    own median error instead, so the bundle adjustment can correct the camera rather than drop it.
    """
    keep = np.isfinite(errors) & (np.abs(errors) <= threshold)
    seen = whole_views(uv)
    for c, spec in enumerate(rig.cameras):
        mine = seen[:, c] & np.isfinite(errors)
        if (keep & mine).sum() >= max(MIN_CAMERA_VIEWS, mine.sum() // 2) or not mine.any():
            continue
        centre = float(np.median(errors[mine]))
        local = gate_threshold(errors[mine] - centre, rig.wand)
        rescued = mine & ~keep & (np.abs(errors - centre) <= local)
        log.info(
            "%s: its placements reconstruct %.1f mm off the wand length: %d gated around that instead",
            spec.name,
            -centre,
            rescued.sum(),
        )
        keep |= rescued
    return keep


def robust_sigma(residuals: FloatArray) -> float:
    """Per-coordinate noise from the median 2D residual norm (Rayleigh: median = 1.1774 sigma).

    Never below MIN_SIGMA_PX, so noise-free data do not make every view an outlier.
    """
    return max(float(np.median(np.sqrt(squared_norms(residuals))) / np.sqrt(2 * np.log(2))), MIN_SIGMA_PX)


def rejected_views(
    uv: FloatArray, residuals: FloatArray, threshold_px: float, rows: NDArray[np.int64] | None = None
) -> NDArray[np.bool_]:
    """(P, C) the camera views with a point whose residual exceeds ``threshold_px`` (a caller sets them NaN in its
    copy of the views: ``views[rejected] = np.nan``), or (R, C) those of the placements ``rows``.

    Args:
        uv: (P, C, K, 2) pixels of the adjusted placements (NaN where not seen), or of every placement.
        residuals: (M, 2) residuals of ``BundleProblem.from_dense(wand, uv, rows=rows)``.
        threshold_px: largest 2D residual a view may have.
        rows: (R,) the placements adjusted, where ``uv`` holds others too.
    """
    _, placement, camera, _ = observed_points(uv, rows)
    worst = np.zeros((uv.shape[0] if rows is None else rows.size, uv.shape[1]))
    if placement.size:  # each view's largest residual: a maximum over its run of points
        first = block_starts(placement, camera)
        worst[placement[first], camera[first]] = np.maximum.reduceat(np.sqrt(squared_norms(residuals)), first)
    return worst > threshold_px


def subset_state(state: BundleState, mask: NDArray[np.bool_]) -> BundleState:
    return BundleState(
        state.models, state.poses, state.wand_a[mask], state.wand_direction[mask], state.timing, state.bias
    )


def huber_scale(state: BundleState, problem: BundleProblem) -> float:
    """The Huber threshold (px) of a robust adjustment from ``state``: HUBER_SIGMAS robust sigmas of its
    residuals."""
    return HUBER_SIGMAS * robust_sigma(residuals(state, problem))


def robust_adjustment(
    state: BundleState, problem: BundleProblem, free: NDArray[np.bool_], *, scale_from: BundleState | None = None
) -> tuple[BundleResult, float]:
    """Huber adjustment with the loss scale from the initial state's robust noise estimate.

    Args:
        scale_from: the state whose residuals set the loss scale instead of ``state``'s (a warm
            start that solves the same robust problem as an adjustment from ``scale_from``).

    Returns:
        The result and the robust estimate of the pixel noise: the residuals' robust
        scale corrected for the degrees of freedom the fit absorbs (sqrt(m / (m - p))).
    """
    loss_scale = huber_scale(state if scale_from is None else scale_from, problem)
    # Only outliers are decided here: a loose tolerance is enough, the least-squares passes finish the job.
    result = bundle_adjust(state, problem, free, loss_scale=loss_scale, tolerance=1e-5, settled=DECIDING_SETTLED)
    m, p = result.dof
    return result, robust_sigma(result.residuals) * np.sqrt(m / max(m - p, 1))


def readmit(
    rig: RigSpec,
    uv: FloatArray,
    aside: NDArray[np.int64],
    result: BundleResult,
    timing: PlacementTiming | None,
    brightness: FloatArray | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], BundleState]:
    """The placements set aside that fit the solved cameras once their outlying views are removed.

    Each placement is triangulated with the solved cameras, its five wand
    parameters are fitted robustly (Huber) with the cameras held fixed, views
    with a point beyond VIEW_GATE_SIGMAS sigma are dropped, and the placement
    comes in if two complete views remain.

    Args:
        uv: (P, C, K, 2) every placement's pixels; ``aside`` (S,) the placements to try, ``timing`` theirs.
        brightness: (P, C, K) every placement's points' brightness classes (None: not known).

    Returns:
        (S,) which of ``aside`` come in, (A, C) the views of those A to leave out (rejected), and their fitted
        wand parameters.
    """
    admitted = np.zeros(aside.size, dtype=bool)
    sigma = max(result.sigma, MIN_SIGMA_PX)
    # the fit decides which views fit and starts the final adjustment: converged as the robust pass (1e-5; at 1e-4
    # stage64's final adjustment, its Gauss-Newton step from the chosen model order raising the cost, took two
    # more linearisations: 3.0 -> 5.9 s for 0.9 s saved here). Their views are read in place (no copy: 150 MB
    # at 64 cameras).
    index, fitted = fit_placements(
        rig.wand, result.state, uv, timing, rows=aside, loss_scale=HUBER_SIGMAS * sigma, brightness=brightness
    )
    rows = aside[index]
    rejected = rejected_views(uv, fitted.residuals, VIEW_GATE_SIGMAS * sigma, rows)
    ok = enough_views(uv, rows, left_out=rejected)
    admitted[index[ok]] = True
    return admitted, rejected[ok], subset_state(fitted.state, ok)
