"""Step 4 around the solver, read from top to bottom in :func:`refine_calibration`: gate the placements,
a robust pass to find the outliers, least squares with the model order the data support, the placements
set aside brought back, the final adjustment, the checks, the result.

Each concern has its module: :mod:`~wand_calib_ros.core.adjust.gating` (outliers),
:mod:`~wand_calib_ros.core.adjust.model_order` (distortion terms and timing parameters kept),
:mod:`~wand_calib_ros.core.judge.degeneracy` (data that cannot determine a calibration) and
:mod:`~wand_calib_ros.core.adjust.assembly` (the result and its warnings).

Works for any number of cameras once every camera has initial intrinsics and
a pose in the reference frame. Cameras that are not synchronised get their time
offsets and readout times estimated with everything else (:mod:`wand_calib_ros.core.adjust.timing`).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.assembly import assemble, free_placements
from wand_calib_ros.core.adjust.brightness_bias import bias_costs, stops_of, unmeasured_bias
from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, bundle_adjust, camera_std
from wand_calib_ros.core.adjust.bundle_problem import (
    INTRINSICS,
    READOUT,
    TIMING,
    BundleProblem,
    BundleState,
    default_free_mask,
)
from wand_calib_ros.core.adjust.correlated_errors import error_correlation, widened
from wand_calib_ros.core.adjust.gating import (
    HUBER_SIGMAS,
    VIEW_GATE_SIGMAS,
    ac_length_errors,
    gate_placements,
    gate_threshold,
    huber_scale,
    readmit,
    rejected_views,
    robust_adjustment,
    subset_state,
)
from wand_calib_ros.core.adjust.model_order import (
    FixedParameters,
    OrderOnAllPlacements,
    Pinned,
    adjust_with_model_selection,
    free_mask,
    held_intrinsics,
    low_order,
    low_order_mask,
)
from wand_calib_ros.core.adjust.narrow_field import (
    MOUNTING_TOLERANCE_MM,
    PRINCIPAL_POINT,
    determined_by_views,
    field_of_view_deg,
    narrow_cameras,
    narrow_pins,
    narrow_start,
    views_std,
)
from wand_calib_ros.core.adjust.placements import fit_placements, triangulate_placements, unprojectable
from wand_calib_ros.core.adjust.timing import (
    ClockModel,
    TimingInput,
    align_views,
    clearly_synchronised,
    reduce_timing,
    refresh_motion,
    start_clocks,
    with_timing,
)
from wand_calib_ros.core.initialise.lens_choice import choose_models
from wand_calib_ros.core.judge.centre_bias import CentreBias, saturated_pull
from wand_calib_ros.core.judge.degeneracy import check_camera_views, check_geometry, check_uncertainty, require
from wand_calib_ros.core.judge.plausibility import check_given_intrinsics
from wand_calib_ros.core.model.brightness import brightness_classes
from wand_calib_ros.core.model.camera_model import (
    CameraModel,
    radius_limit,
    turns_over_in_image,
)
from wand_calib_ros.core.model.geometry import Pose, wand_directions
from wand_calib_ros.core.model.result import CalibrationResult, LensTrial
from wand_calib_ros.core.model.rig import RigSpec, WandSpec, spread_subset
from wand_calib_ros.core.model.views import appended, enough_views, some_views

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: Outliers and the distortion model are decided on at most this many placements (spread over the recording).
COARSE_PLACEMENTS = 1500
#: The final adjustment refits the wand's motion and adjusts again, at most MOTION_ROUNDS times in all,
#: while an adjustment moves a timing parameter by more than MOTION_SETTLED standard deviations.
MOTION_ROUNDS = 3
MOTION_SETTLED = 1.0


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
    saturated: NDArray[np.bool_] | None = None,
    brightness: FloatArray | None = None,
) -> tuple[CalibrationResult, FloatArray]:
    """Gate, bundle-adjust and report (paper Step 4 / Section III-B Step 2).

    Args:
        rig: the rig description (cameras in the order of ``uv``'s axis 1).
        uv: (P, C, 3, 2) observed pixels, NaN where not seen.
        models: initial intrinsics per camera (k3..k5 are reset to zero as in the paper; see
            :data:`~wand_calib_ros.core.adjust.model_order.LOW_ORDER_FIXED` for the pinhole models).
        poses: initial poses per camera in the reference camera's frame.
        reference: index of the reference camera.
        initial_projections: per camera, the Step 1 projection it started from.
        lens_trials: Step 1-3 candidate scores to carry into the result.
        min_placements: fewest placements the bundle adjustment accepts.
        timing: when the cameras saw the placements (None: synchronised cameras, frames in no time order).
        start_uv: (P, C, 3, 2) the views moved to their placements' times (free-running cameras, see
            :func:`wand_calib_ros.core.adjust.timing.align_views`) for the gate and the starting placements;
            None: ``uv``. The adjustments model the timing on the observed pixels.
        saturated: (P, C, 3) which points of ``uv`` the detector measured on saturated spots (None: not known):
            what they pull is checked (:mod:`~wand_calib_ros.core.judge.centre_bias`).
        brightness: (P, C, 3) each point's brightness, stops over full scale (None: not known): a centre bias
            that grows with it is modelled where the data show one (:mod:`~wand_calib_ros.core.model.brightness`).

    Returns:
        The calibration, and (U, K, 3) the markers of the U placements it used, triangulated freely with its
        cameras (:func:`~wand_calib_ros.core.adjust.assembly.free_placements`; reference frame, mm).
    """
    models, full, pinned = _starting_models(rig, models, reference)
    classes = _over_full_scale(brightness)
    points = triangulate_placements(models, poses, uv if start_uv is None else start_uv)
    clocks = start_clocks(rig, timing, points, reference)
    # Coarse to fine: outliers and the distortion model are settled on a spread subset of the placements the
    # gate keeps; the other placements join through the re-admission below and the final adjustment uses all.
    keep = coarse_subset(_gated(rig, uv, models, poses, points, min_placements), len(uv))

    # 1. Robust adjustment (Huber), then views with a point off by more than VIEW_GATE_SIGMAS are rejected.
    # k3..k5 stay at zero here: the robust pass only has to find the outliers, and the
    # low-order model converges in a few iterations even from a rough start. Where it tests or estimates
    # timing, k3 is free too (see _robust_pass).
    robust, sigma, clocks, keep = _robust_pass(rig.wand, uv, points, models, poses, keep, full, clocks)
    used, uv_used, state, clocks = _cleaned(rig.wand, uv, robust, sigma, clocks, keep, min_placements)

    # 2. Least squares on the clean data, dropping the distortion terms (and the timing) the data do not support.
    result, fixed = adjust_with_model_selection(
        rig, uv_used, state, reference, clocks, used, pinned, brightness=classes
    )
    # ... in plumb_bob instead for the conventional cameras whose model the rig leaves open, where the data say so
    result, fixed = choose_models(rig, uv_used, result, fixed, reference, clocks, used, classes)

    # 3. and 4. The placements set aside so far, and the final adjustment of them all.
    result, fixed, clocks, used, uv_used = _every_placement(
        rig, uv, result, fixed, reference, clocks, used, uv_used, classes
    )
    problem = BundleProblem.from_dense(rig.wand, uv_used, clocks.placements(used), None, stops_of(classes, used))
    narrow_notes: list[str] = []
    if fixed.pinned is not None:
        result, fixed, narrow_notes = _narrow_principal_points(rig, problem, result, fixed, reference)
    # (the covariance allows for centre errors that follow one another from image to image)
    correlation = error_correlation(
        result.residuals, problem.camera, problem.point, used[problem.placement], problem.n_cameras
    )
    result = widened(result, correlation)

    # 5. What cannot be right, then the result.
    # (what saturated centres pull is checked where no brightness tells the adjustment which to correct)
    flags = saturated if classes is None else None
    pulls = _checked(rig, uv, uv_used, used, result, clocks, free_mask(len(rig.cameras), reference, fixed), flags)
    systematic = [pull.line() for pull in pulls]
    if classes is not None:  # (a camera whose bright centres could not be measured: nothing tells their bias)
        systematic += unmeasured_bias(problem, rig.camera_names)
    warnings = narrow_notes + _warnings(rig, result, fixed, reference, uv_used) + systematic
    warnings += bias_costs(result.camera_covariance, fixed.bias, rig.camera_names)
    widening = correlation.line()
    warnings += [] if widening is None else [widening]
    views_rejected = (some_views(uv[used]) & ~some_views(uv_used)).sum(axis=0)
    markers = free_placements(result.state, problem, uv_used)  # (the used placements' markers, freely)
    calibration = assemble(
        rig,
        problem,
        result,
        reference,
        fixed,
        initial_projections,
        lens_trials,
        len(uv) - used.size,
        views_rejected,
        warnings,
        clocks,
        tuple(systematic),
        points=markers,
    )
    return calibration, markers


def _over_full_scale(brightness: FloatArray | None) -> FloatArray | None:
    """(P, C, 3) the points' brightness; None where no point is known to reach full scale."""
    if brightness is None or not np.any(brightness_classes(brightness)):
        return None
    return brightness


def _starting_models(
    rig: RigSpec, models: tuple[CameraModel, ...], reference: int
) -> tuple[tuple[CameraModel, ...], NDArray[np.bool_], Pinned | None]:
    """The cameras the adjustments start from, the (C, N_CAMERA_PARAMS) parameters the calibration estimates and
    the narrow cameras' pins: narrow pinholes with their principal point held at the centre (at a prior), given
    intrinsics as given, estimated ones from the low-order model."""
    narrow = narrow_cameras(rig)
    pinned = narrow_pins(rig, narrow) if narrow.any() else None
    models = tuple(narrow_start(m, rig.cameras[c]) if narrow[c] else m for c, m in enumerate(models))
    full = default_free_mask(len(rig.cameras), reference, models)
    full[np.ix_(held_intrinsics(rig), INTRINSICS)] = False
    if pinned is not None:
        full &= ~pinned.mask
    models = tuple(
        m if spec.intrinsics is not None else low
        for m, low, spec in zip(models, low_order(models), rig.cameras, strict=True)
    )
    return models, full, pinned


def _gated(
    rig: RigSpec,
    uv: FloatArray,
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    points: FloatArray,
    min_placements: int,
) -> NDArray[np.int64]:
    """The placements whose starting triangulation ``points`` (P, 3, 3) reconstructs the wand's length (the gate)
    and that the starting cameras can project."""
    errors = ac_length_errors(points, rig.wand)
    threshold = gate_threshold(errors, rig.wand)
    keep = np.flatnonzero(gate_placements(rig, uv, errors, threshold) & ~unprojectable(models, poses, uv, points))
    log.info("gate |AC| within %.1f mm: %d placements kept, %d set aside", threshold, keep.size, len(uv) - keep.size)
    require(keep.size, min_placements, f"reconstruct to the wand length within {threshold:.1f} mm")
    return keep


def _cleaned(
    wand: WandSpec,
    uv: FloatArray,
    robust: BundleResult,
    sigma: float,
    clocks: ClockModel,
    keep: NDArray[np.int64],
    min_placements: int,
) -> tuple[NDArray[np.int64], FloatArray, BundleState, ClockModel]:
    """The robust pass's views with its outliers rejected: the placements still seen twice, their views, their
    state, and the clocks with the wand's motion from where the robust cameras put every placement."""
    clean = uv[keep]  # (a copy: its rejected views are set NaN)
    rejected = rejected_views(clean, robust.residuals, VIEW_GATE_SIGMAS * sigma)
    clean[rejected] = np.nan
    still = enough_views(clean)
    log.info("robust pass: sigma %.3f px, %d views rejected, %d placements left", sigma, rejected.sum(), still.sum())
    require(int(still.sum()), min_placements, "keep two clean views after outlier rejection")
    if clocks.modelled:
        placed = _fitted_points(wand, robust.state, uv, clocks, keep, HUBER_SIGMAS * sigma)
        clocks = refresh_motion(clocks, placed, choose=True)
    return keep[still], clean[still], subset_state(robust.state, still), clocks


def _every_placement(
    rig: RigSpec,
    uv: FloatArray,
    result: BundleResult,
    fixed: FixedParameters,
    reference: int,
    clocks: ClockModel,
    used: NDArray[np.int64],
    uv_used: FloatArray,
    brightness: FloatArray | None,
) -> tuple[BundleResult, FixedParameters, ClockModel, NDArray[np.int64], FloatArray]:
    """The placements set aside so far brought back with their clean views where they fit the solution, and the
    final adjustment of them all (with more than the coarse ones, the model order decided again on all of them
    on its way; with timing, on the refreshed motion). Returns the result, its fixed parameters, the clocks,
    the placements used and their views."""
    free = free_mask(len(rig.cameras), reference, fixed)
    decided_on = used.size
    aside = np.setdiff1d(np.flatnonzero(clocks.placeable(len(uv))), used)
    admitted, left_out, admitted_state = readmit(rig, uv, aside, result, clocks.placements(aside), brightness)
    if admitted.any():
        log.info("%d more placements fit the solution: admitted", admitted.sum())
        uv_used = appended(uv_used, uv, aside[admitted])
        uv_used[used.size :][left_out] = np.nan  # (their rejected views)
        used = np.concatenate([used, aside[admitted]])
    if not (admitted.any() or clocks.modelled):  # with timing, the refreshed motion changes the problem
        return result, fixed, clocks, used, uv_used
    state = replace(
        result.state,
        wand_a=np.concatenate([result.state.wand_a, admitted_state.wand_a]),
        wand_direction=np.concatenate([result.state.wand_direction, admitted_state.wand_direction]),
    )
    order = OrderOnAllPlacements(rig, fixed, reference, decided_on) if used.size > decided_on else None
    result, clocks, free = _final_adjustment(rig, uv, uv_used, used, state, clocks, free, order, brightness)
    fixed = order.decision if order is not None else fixed
    held = fixed.timing.copy()
    held[:, 1] &= free[:, READOUT]  # (a readout the bound held at zero)
    return result, replace(fixed, timing=held), clocks, used, uv_used


def _checked(
    rig: RigSpec,
    uv: FloatArray,
    uv_used: FloatArray,
    used: NDArray[np.int64],
    result: BundleResult,
    clocks: ClockModel,
    free: NDArray[np.bool_],
    saturated: NDArray[np.bool_] | None,
) -> tuple[CentreBias, ...]:
    """The result checked for what cannot determine a calibration (raised), and what the saturated points pull."""
    check_geometry(result.state.points(rig.wand))
    check_camera_views(rig, uv, uv_used)
    check_uncertainty(rig, result)
    if saturated is None:
        return ()
    return tuple(saturated_pull(rig, uv_used, saturated[used], clocks.placements(used), result, free))


def _warnings(
    rig: RigSpec, result: BundleResult, fixed: FixedParameters, reference: int, uv_used: FloatArray
) -> list[str]:
    """What the result should say of given intrinsics that do not fit, and of lens curves that turn over."""
    points = np.isfinite(uv_used[..., 0]).sum(axis=(0, 2))  # (C,) image points per camera
    warnings = check_given_intrinsics(rig, result, free_mask(len(rig.cameras), reference, fixed), points)
    for model, spec in zip(result.state.models, rig.cameras, strict=True):
        if turns_over_in_image(model, spec.max_view_angle):
            warnings.append(
                f"{spec.name}: r(theta) turns over at {np.degrees(radius_limit(model)):.0f} deg, inside the "
                f"image and below max_view_angle_deg {spec.max_view_angle_deg:g}: check the rig description"
            )
    return warnings


def _narrow_principal_points(
    rig: RigSpec, problem: BundleProblem, result: BundleResult, fixed: FixedParameters, reference: int
) -> tuple[BundleResult, FixedParameters, list[str]]:
    """The narrow cameras' principal points: estimated where the views determine them better than the
    mounting tolerance (the adjustment repeated with them free), else held at the image centre with the
    tolerance as a prior in the covariance. Returns the result, its fixed parameters and what each narrow
    camera held, in words."""
    assert fixed.pinned is not None and result.system is not None  # narrow cameras have estimated intrinsics
    n_cameras = len(rig.cameras)
    pinned = fixed.pinned
    views = views_std(result.system, free_mask(n_cameras, reference, fixed), result.sigma, pinned)
    freed = determined_by_views(views, pinned)
    if freed.any():
        mask, std = pinned.mask.copy(), pinned.std.copy()
        mask[np.ix_(freed, PRINCIPAL_POINT)] = False
        std[np.ix_(freed, PRINCIPAL_POINT)] = 0.0
        pinned = Pinned(mask, std)
        fixed = replace(fixed, pinned=pinned)
        result = bundle_adjust(result.state, problem, free_mask(n_cameras, reference, fixed))
    assert result.system is not None
    covariance = result.system.covariance(free_mask(n_cameras, reference, fixed), result.sigma, pinned.std)
    result = replace(result, camera_covariance=covariance, camera_std=camera_std(covariance))
    notes = []
    for c in np.flatnonzero(pinned.cameras()):
        spec, model = rig.cameras[c], result.state.models[c]
        across = field_of_view_deg(spec, float(model.k[0]))  # as calibrated
        field = f"{spec.name}: a narrow field of view ({across:.1f} deg across)"
        given = spec.intrinsics is not None  # given as a start: its lens and principal point are the ones held
        lens = "its distortion held as given" if given else "calibrated as a pinhole, its distortion held at zero"
        if freed[c]:
            notes.append(f"{field}: {lens}" + ("" if given else " (the field shows none)"))
            continue
        u, v = model.principal_point
        where = f"as given ({u:.1f}, {v:.1f})" if given else "at the image centre"
        notes.append(
            f"{field}: {lens} and its principal point {where} +-{pinned.std[c, PRINCIPAL_POINT[0]]:.0f} px (a lens "
            f"mount's tolerance of {MOUNTING_TOLERANCE_MM:g} mm; the views alone fix it only to "
            f"+-{float(np.max(views[c])):.0f} px, and the standard deviations of its pose include that)"
            + ("" if given else ": give its intrinsics (a board calibration) for a measured one")
        )
    return result, fixed, notes


def coarse_subset(keep: NDArray[np.int64], n_placements: int) -> NDArray[np.int64]:
    """The placements ``keep`` (of ``n_placements``) that outliers and the model order are decided on.

    The placements evenly spread over the whole recording that the gate kept: which they are does not
    shift when the gate (whose threshold comes from the starting cameras) keeps a placement more or
    less, so starts a little apart settle on the same data. Should the gate have kept fewer than half
    of them, COARSE_PLACEMENTS spread over the kept ones instead.
    """
    spread = np.intersect1d(keep, spread_subset(n_placements, COARSE_PLACEMENTS))
    return (
        spread
        if 2 * spread.size >= min(COARSE_PLACEMENTS, n_placements)
        else keep[spread_subset(keep.size, COARSE_PLACEMENTS)]
    )


def _robust_pass(
    wand: WandSpec,
    uv: FloatArray,
    points: FloatArray,
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    keep: NDArray[np.int64],
    full: NDArray[np.bool_],
    clocks: ClockModel,
) -> tuple[BundleResult, float, ClockModel, NDArray[np.int64]]:
    """The robust adjustment of the placements ``keep``, with the timing parameters the clock model estimates.

    A tentative model (``auto`` on simultaneous views) is tested first: the pass runs as for
    synchronised cameras, then robust adjustments from its solution with the timing parameters free
    tell whether the data hold readout times and offsets (:func:`_test_timing`). Without them the
    refinement goes on exactly as for synchronised cameras; with them the test's last adjustment is
    the pass (outliers are decided with the timing), redone from its solution on the placements whose
    motion is known should that leave some out.

    Args:
        uv: (P, C, 3, 2) every placement of the timeline; ``points`` (P, 3, 3) their starting triangulation.
        keep: the placements the gate kept; ``full`` the geometric parameters the calibration estimates, of which
            the pass estimates the low order (:func:`low_order_mask`), and one radial term more beside timing
            parameters (tested or estimated). The low order's misfit otherwise passes for readout times and offsets
            where the noise is low (a 4-camera live buffer at 0.02 px: readout times of -1 ms at 10 sigma, offsets
            34 us at 9, where k3 free gives -10 us and offsets within their noise).

    Returns:
        The pass, its robust pixel noise, the clock model and the placements it adjusted.
    """

    def start(index: NDArray[np.int64], timing: FloatArray | None) -> BundleState:
        return BundleState(
            models, poses, points[index, 0], wand_directions(points[index, 0], points[index, -1]), timing
        )

    free, timed_free = low_order_mask(models, full), low_order_mask(models, full, terms=1)
    warm: BundleState | None = None  # the timing test's solution, on the placements it can place
    placeable = clocks.placeable(len(uv))[keep]
    if clocks.tentative:
        robust, sigma = robust_adjustment(start(keep, None), BundleProblem.from_dense(wand, uv[keep]), free)
        problem = BundleProblem.from_dense(wand, uv[keep], clocks.placements(keep))
        scale = start(keep, clocks.start)
        absent = _clearly_synchronised(problem, clocks, robust.state, timed_free, scale)
        test = None if absent else _test_timing(problem, clocks, robust.state, timed_free, scale)
        if test is None:
            log.info("the views are synchronised: no time offsets or readout times")
            note = "time offsets and readout times tested: not significant (synchronised global shutters)"
            return robust, sigma, clocks.without_timing(note), keep
        fit, fit_sigma, timing = test
        clocks = replace(clocks, free=timing, tentative=False)
        if placeable.all():  # the test's last adjustment is the pass with the timing it kept
            return fit, fit_sigma, clocks, keep
        warm = subset_state(fit.state, placeable)
    keep = keep[placeable]
    problem = BundleProblem.from_dense(wand, uv[keep], clocks.placements(keep))
    cold = start(keep, clocks.start)  # the robust problem of a pass from the start, from the test's solution if any
    timed = with_timing(timed_free if clocks.free.any() else free, clocks.free)
    robust, sigma = robust_adjustment(cold if warm is None else warm, problem, timed, scale_from=cold)
    return robust, sigma, clocks, keep


def _clearly_synchronised(
    problem: BundleProblem, clocks: ClockModel, synchronised: BundleState, free: NDArray[np.bool_], scale: BundleState
) -> bool:
    """Whether the tentative timing parameters clearly stay out (:func:`clearly_synchronised`), on one
    linearisation at the synchronised pass's solution with them carried, Huber-weighted as :func:`_test_timing`'s
    adjustments are (the scale ``scale``'s): no adjustment of them when the data plainly hold none."""
    at = bundle_adjust(replace(synchronised, timing=clocks.start), problem, with_timing(free, clocks.free),
                       loss_scale=huber_scale(scale, problem), max_iterations=0)  # fmt: skip
    return at.system is not None and clearly_synchronised(clocks, at.system, at.sigma, free)


def _test_timing(
    problem: BundleProblem, clocks: ClockModel, synchronised: BundleState, free: NDArray[np.bool_], scale: BundleState
) -> tuple[BundleResult, float, NDArray[np.bool_]] | None:
    """The tentative timing parameters tested: robust adjustments from the synchronised pass's solution
    with them free (the Huber scale ``scale``'s, that of a pass from the start with the timing), dropping
    what :func:`reduce_timing` finds insignificant (finer term first) until what is left stands.

    Returns:
        The last adjustment, its robust pixel noise and the (C, 2) timing parameters kept; None: none.
    """
    timing, tested = clocks.free, replace(synchronised, timing=clocks.start)
    while timing.any():
        fit, sigma = robust_adjustment(tested, problem, with_timing(free, timing), scale_from=scale)
        kept = reduce_timing(clocks, fit, timing)
        if np.array_equal(kept, timing):
            return fit, sigma, timing
        values = fit.state.camera_timing.copy()
        values[timing & ~kept] = clocks.start[timing & ~kept]
        tested, timing = replace(fit.state, timing=values), kept
    return None


def _final_adjustment(
    rig: RigSpec,
    uv: FloatArray,
    uv_used: FloatArray,
    used: NDArray[np.int64],
    state: BundleState,
    clocks: ClockModel,
    free: NDArray[np.bool_],
    order: OrderOnAllPlacements | None,
    brightness: FloatArray | None,
) -> tuple[BundleResult, ClockModel, NDArray[np.bool_]]:
    """The final adjustment of the placements ``used`` from ``state``, the model order decided again on
    its first linearisation (``order``, if any); with timing, the wand's motion is refitted first to where the
    adjustments put them, and again while an adjustment moves a timing parameter by more than
    MOTION_SETTLED of its standard deviation (at most MOTION_ROUNDS rounds). A readout time that comes out
    negative is held at zero (its bound) and the adjustment repeated. Returns the result, the clocks and the
    (C, N_CAMERA_PARAMS) parameters it estimated."""
    choose = order  # on the first round's first linearisation; later rounds keep what it decided
    for _ in range(MOTION_ROUNDS if clocks.modelled else 1):
        if clocks.modelled:
            points = np.full((len(uv), uv.shape[2], 3), np.nan)
            rest = np.setdiff1d(np.arange(len(uv)), used)
            rest = rest[enough_views(uv[rest])]  # the others it can place
            if rest.size:
                aligned = align_views(uv, clocks.line, state.camera_timing, clocks.heights)  # type: ignore[arg-type]
                points[rest] = triangulate_placements(state.models, state.poses, aligned[rest])
            points[used] = state.points(rig.wand)
            clocks = refresh_motion(clocks, points)
        problem = BundleProblem.from_dense(rig.wand, uv_used, clocks.placements(used), None, stops_of(brightness, used))
        result = bundle_adjust(state, problem, free, choose=choose)
        if choose is not None:
            free, choose = free_mask(len(rig.cameras), choose.reference, choose.decision), None
        negative = free[:, READOUT] & (result.state.camera_timing[:, 1] < 0)
        if negative.any():  # a readout is never negative: held at its bound, the rest adjusted again
            log.info("readout times %s are negative: held at zero", result.state.camera_timing[negative, 1])
            free = free.copy()
            free[negative, READOUT] = False
            values = result.state.camera_timing.copy()
            values[negative, 1] = 0.0
            result = bundle_adjust(replace(result.state, timing=values), problem, free)
        if not clocks.modelled:
            break
        std = result.camera_std[:, TIMING]
        moved = np.abs(result.state.camera_timing - state.camera_timing)[std > 0] / std[std > 0]
        log.info("final adjustment: timing moved by %.2f sigma at most", float(np.max(moved, initial=0.0)))
        state = result.state
        if np.all(moved <= MOTION_SETTLED):
            break
    return result, clocks, free


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
