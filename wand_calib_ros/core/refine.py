"""Step 4 around the solver: gate placements, bundle-adjust, keep r(theta) sane, report.

Works for any number of cameras once every camera has initial intrinsics and
a pose in the reference frame. Cameras that are not synchronised get their time
offsets and readout times estimated with everything else (:mod:`wand_calib_ros.core.timing`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.bundle_adjustment import (
    CAMERA_PARAM_NAMES,
    N_GEOMETRIC,
    BundleProblem,
    BundleResult,
    BundleState,
    PlacementTiming,
    bundle_adjust,
    default_free_mask,
    residuals,
)
from wand_calib_ros.core.camera_model import (
    N_INTRINSIC,
    CameraModel,
    inverse_radius,
    max_image_radius_mm,
    monotonic_limit,
    turns_over_in_image,
)
from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError, ModelError
from wand_calib_ros.core.geometry import Pose, wand_directions
from wand_calib_ros.core.placements import fit_placements, triangulate_placements
from wand_calib_ros.core.result import CalibrationResult, CameraCalibration, LensTrial, TimingSummary
from wand_calib_ros.core.rig import CameraSpec, RigSpec, WandSpec, spread_subset
from wand_calib_ros.core.timing import (
    ClockModel,
    TimingInput,
    align_views,
    reduce_timing,
    refresh_motion,
    start_clocks,
)

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: The paper's gate: placements whose |AC| is off by more than this fraction of L are dropped.
GATE_FRACTION = 0.01
#: ... unless that is within this many robust standard deviations of the |AC| errors (high noise).
GATE_SIGMAS = 5.0
#: Wand points whose second (third) principal spread is below this fraction of the first lie on a line (plane).
DEGENERATE_SPREAD = 0.03
#: Relative focal-length and principal-point (fraction of the image width) standard deviations that make
#: a calibration meaningless.
MAX_FOCAL_STD = 0.05
MAX_CENTRE_STD = 0.1
#: Fewest views a camera must keep in the final bundle adjustment (its 11 parameters need several).
MIN_CAMERA_VIEWS = 5
#: Image coverage: grid cells per side and the fraction that should see the wand.
COVERAGE_GRID = 8
MIN_COVERAGE = 0.25
#: Outliers and the distortion model are decided on at most this many placements (spread over the recording).
COARSE_PLACEMENTS = 1500
#: Floor of the robust noise estimate, px (detections are never better than this).
MIN_SIGMA_PX = 0.02
#: Huber threshold of the robust pass, in robust sigmas.
HUBER_SIGMAS = 2.0
#: A camera view with a point further than this many robust sigmas from its reprojection is an outlier.
VIEW_GATE_SIGMAS = 5.0
#: The highest free radial coefficient is fixed to zero while |k| / std(k) is below this (Wald test).
SIGNIFICANCE = 2.0
#: The final adjustment refits the wand's motion and adjusts again, at most MOTION_ROUNDS times in all,
#: while an adjustment moves a timing parameter by more than MOTION_SETTLED standard deviations.
MOTION_ROUNDS = 3
MOTION_SETTLED = 1.0
#: Uncertainty of r(theta) at the widest observed angle (px) above which a camera gets a warning.
WEAK_CURVE_PX = 0.5
#: A camera whose observations stop below this fraction of the angle its image reaches gets a warning.
COVERAGE_FRACTION = 0.8


def ac_length_errors(points: FloatArray, wand: WandSpec) -> FloatArray:
    """(P,) L - |A^r C^r| in mm (first marker to last)."""
    return wand.L - np.linalg.norm(points[:, -1] - points[:, 0], axis=-1)


def gate_threshold(errors: FloatArray, wand: WandSpec) -> float:
    """The |AC| gate in mm: the paper's 1 % of L, widened to 5 robust sigmas when noise is high."""
    finite = errors[np.isfinite(errors)]
    mad_sigma = 1.4826 * float(np.median(np.abs(finite - np.median(finite)))) if finite.size else 0.0
    return max(GATE_FRACTION * wand.L, GATE_SIGMAS * mad_sigma)


@dataclass(frozen=True, eq=False)
class _Fixed:
    """Radial coefficients held at zero per camera (indices into k1..k5), and the timing estimated.

    Attributes:
        per_camera: per camera the fixed radial indices.
        timing: (C, 2) whether each camera's time offset and readout time are estimated.
        held: (C,) cameras whose given intrinsics are held fixed (all seven).
    """

    per_camera: tuple[tuple[int, ...], ...]
    timing: NDArray[np.bool_]
    held: NDArray[np.bool_]


def _held(rig: RigSpec) -> NDArray[np.bool_]:
    """(C,) cameras of the rig whose intrinsics are given and held fixed."""
    return np.array([spec.holds_intrinsics for spec in rig.cameras], dtype=bool)


def _free_mask(n_cameras: int, reference: int, fixed: _Fixed) -> NDArray[np.bool_]:
    free = default_free_mask(n_cameras, reference)
    for camera, indices in enumerate(fixed.per_camera):
        free[camera, list(indices)] = False
    free[fixed.held, :N_INTRINSIC] = False
    free[:, N_GEOMETRIC:] = fixed.timing
    return free


def _zero_fixed(models: tuple[CameraModel, ...], fixed: _Fixed) -> tuple[CameraModel, ...]:
    out = []
    for model, indices in zip(models, fixed.per_camera, strict=True):
        vector = model.intrinsic_vector()
        vector[list(indices)] = 0.0
        out.append(model.with_intrinsic_vector(vector))
    return tuple(out)


def _max_theta(result: BundleResult, problem: BundleProblem) -> FloatArray:
    """(C,) largest off-axis angle (rad) each camera observes at the solution."""
    state = result.state
    points = state.points(problem.wand)[problem.placement, problem.point]
    out = np.zeros(problem.n_cameras)
    for c, pose in enumerate(state.poses):
        in_cam = pose.apply(points[problem.camera == c])
        if in_cam.size:
            out[c] = np.max(np.arctan2(np.hypot(in_cam[:, 0], in_cam[:, 1]), in_cam[:, 2]))
    return out


def refine_calibration(
    rig: RigSpec,
    uv: FloatArray,
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    *,
    reference: int = 0,
    initial_projections: tuple[str, ...],
    lens_trials: tuple[LensTrial, ...] = (),
    min_placements: int = 10,
    timing: TimingInput | None = None,
    start_uv: FloatArray | None = None,
) -> CalibrationResult:
    """Gate, bundle-adjust and report (paper Step 4 / Section III-B Step 2).

    Args:
        rig: the rig description (cameras in the order of ``uv``'s axis 1).
        uv: (P, C, 3, 2) observed pixels, NaN where not seen.
        models: initial intrinsics per camera (k3..k5 are reset to zero as in the paper).
        poses: initial poses per camera in the reference camera's frame.
        reference: index of the reference camera.
        initial_projections: per camera, the Step 1 projection it started from.
        lens_trials: Step 1-3 candidate scores to carry into the result.
        min_placements: fewest placements the bundle adjustment accepts.
        timing: when the cameras saw the placements (None: synchronised cameras, frames in no time order).
        start_uv: (P, C, 3, 2) the views moved to their placements' times (free-running cameras, see
            :func:`wand_calib_ros.core.timing.align_views`) for the gate and the starting placements;
            None: ``uv``. The adjustments model the timing on the observed pixels.
    """
    wand = rig.wand
    n_cameras = len(rig.cameras)
    full = default_free_mask(n_cameras, reference)
    full[_held(rig), :N_INTRINSIC] = False
    models = tuple(  # given intrinsics start as given; estimated ones from the low-order model
        m if spec.intrinsics is not None else m.with_intrinsic_vector(np.r_[m.k[:2], 0.0, 0.0, 0.0, m.principal_point])
        for m, spec in zip(models, rig.cameras, strict=True)
    )
    points = triangulate_placements(models, poses, uv if start_uv is None else start_uv)
    clocks = start_clocks(rig, timing, points, reference)
    errors = ac_length_errors(points, wand)
    threshold = gate_threshold(errors, wand)
    keep = np.flatnonzero(_gate(rig, uv, errors, threshold))
    log.info("gate |AC| within %.1f mm: %d placements kept, %d set aside", threshold, keep.size, len(uv) - keep.size)
    _require(keep.size, min_placements, f"reconstruct to the wand length within {threshold:.1f} mm")
    # Coarse to fine: outliers and the distortion model are settled on a spread subset; the
    # other placements join through the re-admission below and the final adjustment uses all.
    keep = keep[spread_subset(keep.size, COARSE_PLACEMENTS)]

    # 1. Robust adjustment (Huber), then views with a point off by more than VIEW_GATE_SIGMAS are rejected.
    # k3..k5 stay at zero here: the robust pass only has to find the outliers, and the
    # low-order model converges in a few iterations even from a rough start.
    low_order = full.copy()
    low_order[:, 2:5] = False
    robust, sigma, clocks, keep = _robust_pass(wand, uv, points, models, poses, keep, low_order, clocks)
    clean, rejected = gate_views(uv[keep], robust.residuals, VIEW_GATE_SIGMAS * sigma)
    still = _enough_views(clean)
    log.info("robust pass: sigma %.3f px, %d views rejected, %d placements left", sigma, rejected.sum(), still.sum())
    _require(int(still.sum()), min_placements, "keep two clean views after outlier rejection")
    used, uv_used = keep[still], clean[still]
    state = _subset(robust.state, still)
    if clocks.modelled:  # the motion from where the robust cameras put every placement
        placed = _fitted_points(wand, robust.state, uv, clocks, keep, HUBER_SIGMAS * sigma)
        clocks = refresh_motion(clocks, placed, choose=True)

    # 2. Least squares on the clean data, dropping the distortion terms (and the timing) the data do not support.
    result, fixed = _adjust_with_model_selection(rig, uv_used, state, reference, clocks, used)
    free = _free_mask(n_cameras, reference, fixed)

    # 3. Placements set aside so far come back with their clean views if they fit the solution.
    aside = np.setdiff1d(np.flatnonzero(clocks.placeable(len(uv))), used)
    admitted, admitted_uv, admitted_state = _readmit(rig, uv[aside], result, clocks.placements(aside))
    if admitted.any():
        log.info("%d more placements fit the solution: admitted", admitted.sum())
        used = np.concatenate([used, aside[admitted]])
        uv_used = np.concatenate([uv_used, admitted_uv])
    if admitted.any() or clocks.modelled:  # with timing, the refreshed motion changes the problem
        state = BundleState(
            result.state.models,
            result.state.poses,
            np.concatenate([result.state.wand_a, admitted_state.wand_a]),
            np.concatenate([result.state.wand_direction, admitted_state.wand_direction]),
            result.state.timing,
        )
        result, clocks = _final_adjustment(rig, uv, uv_used, used, state, clocks, free)
    check_geometry(result.state.points(wand))
    check_camera_views(rig, uv, uv_used)
    check_uncertainty(rig, result)
    warnings: list[str] = []
    for model, spec in zip(result.state.models, rig.cameras, strict=True):
        if turns_over_in_image(model, spec.max_view_angle):
            warnings.append(
                f"{spec.name}: r(theta) turns over at {np.degrees(monotonic_limit(model.k)):.0f} deg, inside the "
                f"image and below max_view_angle_deg {spec.max_view_angle_deg:g}: check the rig description"
            )
    seen = np.any(np.isfinite(uv[used]), axis=(2, 3))
    rejected_views = (seen & ~np.any(np.isfinite(uv_used), axis=(2, 3))).sum(axis=0)
    problem = BundleProblem.from_dense(wand, uv_used, clocks.placements(used))
    return _assemble(
        rig,
        uv_used,
        problem,
        result,
        reference,
        fixed,
        initial_projections,
        lens_trials,
        len(uv) - used.size,
        rejected_views,
        warnings,
        clocks,
    )


def _robust_pass(
    wand: WandSpec,
    uv: FloatArray,
    points: FloatArray,
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    keep: NDArray[np.int64],
    free: NDArray[np.bool_],
    clocks: ClockModel,
) -> tuple[BundleResult, float, ClockModel, NDArray[np.int64]]:
    """The robust adjustment of the placements ``keep``, with the timing parameters the clock model estimates.

    A tentative model (``auto`` on simultaneous views) is tested first: the pass runs as for
    synchronised cameras, then adjustments from its solution with the timing parameters free tell
    whether the data hold readout times and offsets (:func:`reduce_timing`, finer term first).
    Without them the refinement goes on exactly as for synchronised cameras; with them the pass is
    redone with the timing (outliers are decided with it) on the placements whose motion is known.

    Args:
        uv: (P, C, 3, 2) every placement of the timeline; ``points`` (P, 3, 3) their starting triangulation.
        keep: the placements the gate kept; ``free`` the geometric parameters to estimate.

    Returns:
        The pass, its robust pixel noise, the clock model and the placements it adjusted.
    """

    def start(index: NDArray[np.int64], timing: FloatArray | None) -> BundleState:
        return BundleState(
            models, poses, points[index, 0], wand_directions(points[index, 0], points[index, -1]), timing
        )

    if clocks.tentative:
        robust, sigma = robust_adjustment(start(keep, None), BundleProblem.from_dense(wand, uv[keep]), free)
        problem = BundleProblem.from_dense(wand, uv[keep], clocks.placements(keep))
        timing, tested = clocks.free, replace(robust.state, timing=clocks.start)
        while timing.any():
            test_free = free.copy()
            test_free[:, N_GEOMETRIC:] = timing
            fit = bundle_adjust(tested, problem, test_free, tolerance=1e-5)
            kept = reduce_timing(clocks, fit, timing)
            if np.array_equal(kept, timing):
                break
            values = fit.state.camera_timing.copy()
            values[timing & ~kept] = clocks.start[timing & ~kept]
            tested, timing = replace(fit.state, timing=values), kept
        if not timing.any():
            log.info("the views are synchronised: no time offsets or readout times")
            note = "time offsets and readout times tested: not significant (synchronised global shutters)"
            return robust, sigma, clocks.without_timing(note), keep
        clocks = replace(clocks, free=timing, tentative=False)
    keep = keep[clocks.placeable(len(uv))[keep]]
    with_timing = free.copy()
    with_timing[:, N_GEOMETRIC:] = clocks.free
    problem = BundleProblem.from_dense(wand, uv[keep], clocks.placements(keep))
    robust, sigma = robust_adjustment(start(keep, clocks.start), problem, with_timing)
    return robust, sigma, clocks, keep


def _final_adjustment(
    rig: RigSpec,
    uv: FloatArray,
    uv_used: FloatArray,
    used: NDArray[np.int64],
    state: BundleState,
    clocks: ClockModel,
    free: NDArray[np.bool_],
) -> tuple[BundleResult, ClockModel]:
    """The final adjustment of the placements ``used`` from ``state``; with timing, the wand's motion is
    refitted first to where the adjustments put them, and again while an adjustment moves a timing
    parameter by more than MOTION_SETTLED of its standard deviation (at most MOTION_ROUNDS rounds)."""
    for _ in range(MOTION_ROUNDS if clocks.modelled else 1):
        if clocks.modelled:
            points = np.full((len(uv), uv.shape[2], 3), np.nan)
            rest = np.setdiff1d(np.arange(len(uv)), used)
            rest = rest[_enough_views(uv[rest])]  # the others it can place
            if rest.size:
                aligned = align_views(uv, clocks.line, state.camera_timing, clocks.heights)  # type: ignore[arg-type]
                points[rest] = triangulate_placements(state.models, state.poses, aligned[rest])
            points[used] = state.points(rig.wand)
            clocks = refresh_motion(clocks, points)
        result = bundle_adjust(state, BundleProblem.from_dense(rig.wand, uv_used, clocks.placements(used)), free)
        if not clocks.modelled:
            break
        std = result.camera_std[:, N_GEOMETRIC:]
        moved = np.abs(result.state.camera_timing - state.camera_timing)[std > 0] / std[std > 0]
        log.info("final adjustment: timing moved by %.2f sigma at most", float(np.max(moved, initial=0.0)))
        state = result.state
        if np.all(moved <= MOTION_SETTLED):
            break
    return result, clocks


def _fitted_points(
    wand: WandSpec, cameras: BundleState, uv: FloatArray, clocks: ClockModel, adjusted: NDArray[np.int64], scale: float
) -> FloatArray:
    """(P, 3, 3) every placement where the cameras put it: ``adjusted`` from ``cameras``' state (an
    adjustment of those), the others fitted (Huber ``scale`` px) with the cameras and timing held fixed."""
    points = np.full((uv.shape[0], uv.shape[2], 3), np.nan)
    points[adjusted] = cameras.points(wand)
    others = np.setdiff1d(np.arange(uv.shape[0]), adjusted)
    index, fitted = fit_placements(
        wand, cameras, uv[others], clocks.placements(others), loss_scale=scale, max_iterations=5
    )  # neighbours of the adjusted ones: a few Gauss-Newton steps from the triangulation are plenty
    points[others[index]] = fitted.state.points(wand)
    return points


def _gate(rig: RigSpec, uv: FloatArray, errors: FloatArray, threshold: float) -> NDArray[np.bool_]:
    """(P,) placements the |AC| gate keeps.

    A camera whose chained start is off (its pair saw a shared camera's intrinsics differently)
    makes every placement it sees reconstruct too long or too short by about the same amount.
    Should the gate leave it fewer than half its views, its placements are gated around their
    own median error instead, so the bundle adjustment can correct the camera rather than drop it.
    """
    keep = np.isfinite(errors) & (np.abs(errors) <= threshold)
    seen = np.all(np.isfinite(uv), axis=(2, 3))
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


def _require(count: int, needed: int, what: str) -> None:
    if count < needed:
        raise InsufficientDataError(f"only {count} placements {what}; need at least {needed}")


def robust_sigma(residuals: FloatArray) -> float:
    """Per-coordinate noise from the median 2D residual norm (Rayleigh: median = 1.1774 sigma).

    Never below MIN_SIGMA_PX, so noise-free data do not make every view an outlier.
    """
    return max(float(np.median(np.linalg.norm(residuals, axis=1)) / np.sqrt(2 * np.log(2))), MIN_SIGMA_PX)


def gate_views(uv: FloatArray, residuals: FloatArray, threshold_px: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Remove every camera view with a point whose residual exceeds ``threshold_px``.

    Args:
        uv: (P, C, 3, 2) pixels of the adjusted placements (NaN where not seen).
        residuals: (M, 2) residuals of ``BundleProblem.from_dense(wand, uv)``.
        threshold_px: largest 2D residual a view may have.

    Returns:
        The pixels with rejected views set to NaN, and the (P, C) mask of rejected views.
    """
    placement, camera, _ = np.nonzero(np.all(np.isfinite(uv), axis=-1))
    worst = np.zeros(uv.shape[:2])
    np.maximum.at(worst, (placement, camera), np.linalg.norm(residuals, axis=1))
    rejected = worst > threshold_px
    return np.where(rejected[..., None, None], np.nan, uv), rejected


def _enough_views(uv: FloatArray) -> NDArray[np.bool_]:
    """(P,) placements seen completely by at least two cameras."""
    return np.all(np.isfinite(uv), axis=(2, 3)).sum(axis=1) >= 2


def _subset(state: BundleState, mask: NDArray[np.bool_]) -> BundleState:
    return BundleState(state.models, state.poses, state.wand_a[mask], state.wand_direction[mask], state.timing)


def robust_adjustment(
    state: BundleState, problem: BundleProblem, free: NDArray[np.bool_]
) -> tuple[BundleResult, float]:
    """Huber adjustment with the loss scale from the initial state's robust noise estimate.

    Returns:
        The result and the robust estimate of the pixel noise: the residuals' robust
        scale corrected for the degrees of freedom the fit absorbs (sqrt(m / (m - p))).
    """
    sigma = robust_sigma(residuals(state, problem))
    # Only outliers are decided here: a loose tolerance is enough, the least-squares passes finish the job.
    result = bundle_adjust(state, problem, free, loss_scale=HUBER_SIGMAS * sigma, tolerance=1e-5)
    m, p = result.dof
    return result, robust_sigma(result.residuals) * np.sqrt(m / max(m - p, 1))


def _adjust_with_model_selection(
    rig: RigSpec, uv: FloatArray, initial: BundleState, reference: int, clocks: ClockModel, used: NDArray[np.int64]
) -> tuple[BundleResult, _Fixed]:
    """Bundle-adjust with every k3..k5 (and the timing) free, then drop what the data do not support and re-adjust.

    Per camera the highest free coefficient among k3..k5 is fixed to zero while it
    is insignificant (|k| < SIGNIFICANCE sigma) or makes r(theta) turn over inside
    the image. The decisions are made on the linearised problem: fixing k_h = 0
    moves the other parameters to their conditional mean
    ``x - cov[:, h] / cov[h, h] * x[h]`` and shrinks the covariance accordingly, so
    one re-adjustment (from that better start) usually settles the model. Time
    offsets and readout times under ``auto`` are kept only when significant
    (:func:`wand_calib_ros.core.timing.reduce_timing`).

    Args:
        uv: (P, C, 3, 2) the placements to adjust, ``used`` (P,) their indices in the timeline.
    """
    problem = BundleProblem.from_dense(rig.wand, uv, clocks.placements(used))
    fixed = _Fixed(tuple(() for _ in rig.cameras), clocks.free.copy(), _held(rig))
    start = initial
    while True:
        result = bundle_adjust(start, problem, _free_mask(len(rig.cameras), reference, fixed))
        log.info("bundle adjustment: %d iterations, sigma %.3f px", result.iterations, result.sigma)
        per_camera = list(fixed.per_camera)
        models = list(result.state.models)
        for c, spec in enumerate(rig.cameras):
            if not fixed.held[c]:  # given intrinsics held fixed have no model order to decide
                per_camera[c], models[c] = _reduce_radial(spec, result, c, per_camera[c])
        timing = reduce_timing(clocks, result, fixed.timing)
        if tuple(per_camera) == fixed.per_camera and np.array_equal(timing, fixed.timing):
            return result, fixed
        state = result.state
        values = state.camera_timing.copy()
        values[fixed.timing & ~timing] = clocks.start[fixed.timing & ~timing]
        fixed = _Fixed(tuple(per_camera), timing, fixed.held)
        start = BundleState(_zero_fixed(tuple(models), fixed), state.poses, state.wand_a, state.wand_direction, values)


def _reduce_radial(
    spec: CameraSpec, result: BundleResult, camera: int, fixed: tuple[int, ...]
) -> tuple[tuple[int, ...], CameraModel]:
    """Sequential Wald tests on k5, k4, k3 of one camera (see _adjust_with_model_selection).

    Returns:
        The camera's fixed radial indices and its intrinsics moved to the conditional estimate.
    """
    model = result.state.models[camera]
    estimate = model.intrinsic_vector()
    covariance = result.camera_block(camera, slice(0, 7)).copy()
    fixed_now = list(fixed)
    for highest in (4, 3, 2):
        if highest in fixed_now:
            continue
        variance = covariance[highest, highest]
        significance = abs(estimate[highest]) / np.sqrt(variance) if variance > 0 else 0.0
        current = model.with_intrinsic_vector(estimate)
        if turns_over_in_image(current, spec.max_view_angle):
            log.info("%s: r(theta) turns over inside the image with k%d free: fixed to 0", spec.name, highest + 1)
        elif significance < SIGNIFICANCE:
            log.info(
                "%s: k%d = %.3g is not significant (%.1f sigma): fixed to 0",
                spec.name,
                highest + 1,
                estimate[highest],
                significance,
            )
        else:
            break
        if variance > 0:
            gain = covariance[:, highest] / variance
            estimate = estimate - gain * estimate[highest]
            covariance = covariance - np.outer(gain, covariance[highest])
        estimate[highest] = 0.0
        fixed_now.append(highest)
    try:
        return tuple(fixed_now), model.with_intrinsic_vector(estimate)
    except ModelError:  # the linearised shift leaves the camera model (k1 <= 0): re-adjust from the zeros instead
        vector = model.intrinsic_vector()
        vector[fixed_now] = 0.0
        return tuple(fixed_now), model.with_intrinsic_vector(vector)


def _readmit(
    rig: RigSpec, uv: FloatArray, result: BundleResult, timing: PlacementTiming | None
) -> tuple[NDArray[np.bool_], FloatArray, BundleState]:
    """Placements outside the adjustment that fit the solved cameras once their outlying views are removed.

    Each placement is triangulated with the solved cameras, its five wand
    parameters are fitted robustly (Huber) with the cameras held fixed, views
    with a point beyond VIEW_GATE_SIGMAS sigma are dropped, and the placement
    comes in if two complete views remain.

    Returns:
        (S,) mask over the given placements, the admitted ones' clean pixels
        (A, C, 3, 2) and their fitted wand parameters.
    """
    admitted = np.zeros(uv.shape[0], dtype=bool)
    sigma = max(result.sigma, MIN_SIGMA_PX)
    # only deciding which views fit: a loose tolerance; the final adjustment refines everything
    index, fitted = fit_placements(rig.wand, result.state, uv, timing, loss_scale=HUBER_SIGMAS * sigma)
    clean, _ = gate_views(uv[index], fitted.residuals, VIEW_GATE_SIGMAS * sigma)
    ok = _enough_views(clean)
    admitted[index[ok]] = True
    return admitted, clean[ok], _subset(fitted.state, ok)


def radial_std_px(model: CameraModel, covariance: FloatArray, theta: float) -> float:
    """Standard deviation (px) of the image radius m*r(theta) from the (5, 5) covariance of k1..k5."""
    gradient = float(np.max(model.m)) * theta ** (2 * np.arange(5) + 1)
    return float(np.sqrt(max(float(gradient @ covariance @ gradient), 0.0)))


def check_geometry(points: FloatArray) -> None:
    """Refuse wand motion that cannot determine a calibration.

    Args:
        points: (P, 3, 3) wand points A, B, C of the adjusted placements, mm.

    Raises:
        DegenerateDataError: every wand point lies on (nearly) one line or one plane.
    """
    flat = points.reshape(-1, 3)
    spread = np.linalg.svd(flat - flat.mean(axis=0), compute_uv=False) / np.sqrt(flat.shape[0])
    if spread[1] < DEGENERATE_SPREAD * spread[0]:
        raise DegenerateDataError(
            f"the wand moved along a single line (spread {spread[0]:.0f} mm along it, {spread[1]:.0f} mm across): "
            "move and turn it through the whole volume"
        )
    if spread[2] < DEGENERATE_SPREAD * spread[0]:
        raise DegenerateDataError(
            f"the wand moved only in a plane ({spread[2]:.0f} mm thick over {spread[0]:.0f} mm): the calibration "
            "is not determined; move it towards and away from the cameras too"
        )


def check_camera_views(rig: RigSpec, uv_seen: FloatArray, uv_used: FloatArray) -> None:
    """Refuse a solution in which a camera kept fewer than MIN_CAMERA_VIEWS views.

    Args:
        rig: the rig description.
        uv_seen: (P, C, 3, 2) every placement as observed.
        uv_used: (P', C, 3, 2) the placements and views the solution uses (rejected views NaN).

    Raises:
        InsufficientDataError: naming the camera and how many of its views were left.
    """
    views = np.all(np.isfinite(uv_used), axis=(2, 3)).sum(axis=0)
    seen = np.all(np.isfinite(uv_seen), axis=(2, 3)).sum(axis=0)
    for c, spec in enumerate(rig.cameras):
        if views[c] < MIN_CAMERA_VIEWS:
            raise InsufficientDataError(
                f"camera '{spec.name}': only {views[c]} of its {seen[c]} views fit the solution "
                f"(need {MIN_CAMERA_VIEWS}); "
                "the others failed the wand-length gate or were outliers. Wave the wand where it and the "
                "other cameras see it together, through more of its view"
            )


def check_uncertainty(rig: RigSpec, result: BundleResult) -> None:
    """Refuse a solution whose focal lengths or principal points the data do not determine.

    Raises:
        DegenerateDataError: naming the camera and its uncertainties.
    """
    for c, (spec, model) in enumerate(zip(rig.cameras, result.state.models, strict=True)):
        focal = result.camera_std[c, 0] / model.k[0]
        centre = float(np.max(result.camera_std[c, 5:7]))
        if not (focal <= MAX_FOCAL_STD and centre <= MAX_CENTRE_STD * spec.image_size[0]):  # NaN: undetermined
            raise DegenerateDataError(
                f"camera '{spec.name}': the data do not determine its intrinsics (focal length +-{100 * focal:.0f} %, "
                f"principal point +-{centre:.0f} px); wave the wand through more of its view, nearer and farther"
            )


def _coverage_warnings(
    spec: CameraSpec, model: CameraModel, max_theta: float, result: BundleResult, camera: int, uv: FloatArray
) -> list[str]:
    """Plain-language warnings about what one camera's data leave weak.

    Args:
        uv: (P, 3, 2) the camera's points in the adjustment (NaN where not seen).
    """
    out = []
    points = uv.reshape(-1, 2)
    points = points[np.all(np.isfinite(points), axis=1)]
    width, height = spec.image_size
    cells = np.unique(
        np.clip((points / [width, height] * COVERAGE_GRID).astype(np.int64), 0, COVERAGE_GRID - 1), axis=0
    )
    covered = cells.shape[0] / COVERAGE_GRID**2
    if covered < MIN_COVERAGE:
        out.append(
            f"{spec.name}: the wand covered only {100 * covered:.0f} % of the image ({COVERAGE_GRID}x{COVERAGE_GRID} "
            "cells); wave it through the rest of the view"
        )
    band = radial_std_px(model, result.camera_block(camera, slice(0, 5)), max_theta)
    if band > WEAK_CURVE_PX:
        out.append(
            f"{spec.name}: the distortion curve is uncertain by {band:.1f} px at {np.degrees(max_theta):.0f} deg, "
            "the widest angle observed; add wand placements near the image border"
        )
    image_theta = float(inverse_radius(model.k, np.array(max_image_radius_mm(model))))
    reach = min(spec.max_view_angle, image_theta if np.isfinite(image_theta) else spec.max_view_angle)
    if max_theta < COVERAGE_FRACTION * reach:
        out.append(
            f"{spec.name}: the wand was seen only up to {np.degrees(max_theta):.0f} deg off-axis while the image "
            f"reaches {np.degrees(reach):.0f} deg; the distortion beyond is extrapolated (wave the wand near the "
            "image corners)"
        )
    return out


def _assemble(
    rig: RigSpec,
    uv: FloatArray,
    problem: BundleProblem,
    result: BundleResult,
    reference: int,
    fixed: _Fixed,
    initial_projections: tuple[str, ...],
    lens_trials: tuple[LensTrial, ...],
    rejected: int,
    rejected_views: NDArray[np.int64],
    warnings: list[str],
    clocks: ClockModel,
) -> CalibrationResult:
    state = result.state
    max_theta = _max_theta(result, problem)
    free = _free_mask(problem.n_cameras, reference, fixed)
    cameras = []
    for c, spec in enumerate(rig.cameras):
        mine = problem.camera == c
        rms = float(np.sqrt(np.mean(result.residuals[mine] ** 2))) if mine.any() else float("nan")
        std = {name: float(result.camera_std[c, i]) for i, name in enumerate(CAMERA_PARAM_NAMES) if free[c, i]}
        warnings.extend(_coverage_warnings(spec, state.models[c], max_theta[c], result, c, uv[:, c]))
        views = int(np.unique(problem.placement[mine]).size)
        if rejected_views[c]:
            warnings.append(
                f"{spec.name}: {rejected_views[c]} of {views + rejected_views[c]} views rejected as outliers "
                f"(a point more than {VIEW_GATE_SIGMAS:g} sigma = {VIEW_GATE_SIGMAS * result.sigma:.1f} px off)"
            )
        cameras.append(
            CameraCalibration(
                spec.name,
                state.models[c],
                state.poses[c],
                rms,
                int(mine.sum()),
                std,
                float(np.degrees(max_theta[c])),
                initial_projections[c],
                tuple(f"k{i + 1}" for i in sorted(fixed.per_camera[c])),
                views,
                int(rejected_views[c]),
                result.camera_block(c, slice(0, 5)).copy(),
                float(state.camera_timing[c, 0]),
                float(state.camera_timing[c, 1]),
                "estimated" if spec.intrinsics is None else "given" if spec.intrinsics_fixed else "given_start",
            )
        )
    points = triangulate_placements(state.models, state.poses, synchronised_pixels(state, problem, uv))
    lengths = np.linalg.norm(points[:, -1] - points[:, 0], axis=-1)
    lengths = lengths[np.isfinite(lengths)]
    order = [reference] + [c for c in range(len(cameras)) if c != reference]
    return CalibrationResult(
        reference_camera=rig.cameras[reference].name,
        cameras=tuple(cameras[c] for c in order),
        wand=rig.wand,
        wand_length_rms_mm=float(np.sqrt(np.mean((rig.wand.L - lengths) ** 2))),
        wand_length_mean_mm=float(np.mean(lengths)),
        wand_length_std_mm=float(np.std(lengths)),
        sigma_px=result.sigma,
        dof=result.dof,
        placements_used=problem.n_placements,
        placements_rejected=rejected,
        iterations=result.iterations,
        lens_trials=lens_trials,
        warnings=tuple(warnings),
        timing=_timing_summary(rig, clocks, fixed),
    )


def _timing_summary(rig: RigSpec, clocks: ClockModel, fixed: _Fixed) -> TimingSummary | None:
    """How the result treated the cameras' timing (None without timing input)."""
    line = clocks.line
    if line is None:
        return None
    return TimingSummary(
        line.unit,
        "estimated" if fixed.timing[:, 0].any() else "fixed",
        {spec.name: "estimated" if fixed.timing[c, 1] else "fixed" for c, spec in enumerate(rig.cameras)},
        line.period,
        clocks.notes,
    )


def synchronised_pixels(state: BundleState, problem: BundleProblem, uv: FloatArray) -> FloatArray:
    """(P, C, 3, 2) the observations moved to their placement's time (the modelled motion removed).

    Triangulating these gives the wand as one instant saw it; without timing they are ``uv``.
    """
    if problem.timing is None:
        return uv
    shift = residuals(state, problem) - residuals(state, replace(problem, timing=None))
    out = np.array(uv, dtype=np.float64)
    out[problem.placement, problem.camera, problem.point] -= shift
    return out
