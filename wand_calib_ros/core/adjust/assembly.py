"""The calibration result from the final adjustment: per camera figures and standard deviations, the
plain-language warnings on what the data leave weak, the wand-length statistics, the timing summary."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.brightness_bias import MIN_CLASS_POINTS, class_points
from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult
from wand_calib_ros.core.adjust.bundle_problem import (
    BIAS,
    CAMERA_PARAM_NAMES,
    LENS,
    N_CAMERA_PARAMS,
    BundleProblem,
    BundleState,
)
from wand_calib_ros.core.adjust.gating import VIEW_GATE_SIGMAS
from wand_calib_ros.core.adjust.linearisation import in_pixels, residuals, squared_norms
from wand_calib_ros.core.adjust.model_order import FixedParameters, free_mask
from wand_calib_ros.core.adjust.normal_equations import block_starts
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.adjust.timing import (
    ClockModel,
)
from wand_calib_ros.core.model.brightness import N_BIAS, N_BIAS_CLASSES, SHAPE_NAMES, bias_weights
from wand_calib_ros.core.model.camera_model import (
    CameraModel,
    angle_of_radius,
    max_image_radius_mm,
    radial_basis,
)
from wand_calib_ros.core.model.result import CalibrationResult, CameraCalibration, ClassBias, LensTrial, TimingSummary
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec

FloatArray = NDArray[np.float64]

#: Image coverage: grid cells per side and the fraction that should see the wand.
COVERAGE_GRID = 8


MIN_COVERAGE = 0.25
#: Uncertainty of r(theta) at the widest observed angle (px) above which a camera gets a warning.
WEAK_CURVE_PX = 0.5
#: A camera whose principal point is uncertain by more than this (px, both axes together) gets a warning (the
#: quality grade "acceptable" allows 5 px).
WEAK_PRINCIPAL_PX = 5.0
#: A camera whose observations stop below this fraction of the angle its image reaches gets a warning.
COVERAGE_FRACTION = 0.8
#: A focal length uncertain by more than this (fraction), or an orientation by more than WEAK_ROTATION_DEG
#: (any axis), is said to be weakly determined: another solution that far off fits the views as well.
WEAK_FOCAL = 0.01
WEAK_ROTATION_DEG = 1.0


def weak_parameters(name: str, focal_mm: float, std: dict[str, float]) -> list[str]:
    """The warning naming a camera's focal length and orientation where its views fix them weakly (none
    otherwise).

    Args:
        name: the camera; ``focal_mm`` its focal (k1); ``std`` its parameters' standard deviations
            (:data:`CAMERA_PARAM_NAMES`; only the estimated ones).
    """
    parts = []
    if "k1" in std and std["k1"] > WEAK_FOCAL * focal_mm:
        parts.append(f"focal length (+-{100 * std['k1'] / focal_mm:.1f} %)")
    rotation = max((np.degrees(std[axis]) for axis in ("rx", "ry", "rz") if axis in std), default=0.0)
    if rotation > WEAK_ROTATION_DEG:
        parts.append(f"orientation (+-{rotation:.1f} deg)")
    if not parts:
        return []
    return [
        f"{name}: the views fix its {' and '.join(parts)} only weakly: a calibration that far off fits them as "
        "well; wave the wand through more depth and nearer the image borders, or give its intrinsics"
    ]


def radial_std_px(model: CameraModel, covariance: FloatArray, theta: float) -> float:
    """Standard deviation (px) of the image radius m*r(theta) from the (5, 5) covariance of k1..k5."""
    gradient = float(np.max(model.m)) * radial_basis(model, theta)
    return float(np.sqrt(max(float(gradient @ covariance @ gradient), 0.0)))


def coverage_warnings(
    spec: CameraSpec,
    model: CameraModel,
    max_theta: float,
    result: BundleResult,
    camera: int,
    points: FloatArray,
    pinned: bool = False,
) -> list[str]:
    """Plain-language warnings about what one camera's data leave weak.

    Args:
        points: (N, 2) the camera's image points in the adjustment, px.
        pinned: a narrow camera, its distortion and principal point held (said with them): no warnings
            about its curve and principal point.
    """
    out = []
    width, height = spec.image_size
    cell = np.clip((points / [width, height] * COVERAGE_GRID).astype(np.int64), 0, COVERAGE_GRID - 1)
    cells = np.bincount(cell[:, 0] * COVERAGE_GRID + cell[:, 1], minlength=COVERAGE_GRID**2)
    covered = np.count_nonzero(cells) / COVERAGE_GRID**2
    if covered < MIN_COVERAGE:
        out.append(
            f"{spec.name}: the wand covered only {100 * covered:.0f} % of the image ({COVERAGE_GRID}x{COVERAGE_GRID} "
            "cells); wave it through the rest of the view"
        )
    if spec.holds_intrinsics or pinned:  # given and held: nothing about its lens is extrapolated from these views
        return out
    band = radial_std_px(model, result.camera_block(camera, slice(0, 5)), max_theta)
    if band > WEAK_CURVE_PX:
        out.append(
            f"{spec.name}: the distortion curve is uncertain by {band:.1f} px at {np.degrees(max_theta):.0f} deg, "
            "the widest angle observed; add wand placements near the image border"
        )
    principal = float(np.sqrt(max(float(np.trace(result.camera_block(camera, slice(5, 7)))), 0.0)))
    if principal > WEAK_PRINCIPAL_PX:
        lens = slice(LENS.start, LENS.start + 2)  # t1, t2: estimated where their variance is
        tangential = model.is_pinhole and float(np.trace(result.camera_block(camera, lens))) > 0
        why = (
            " (its tangential terms p1, p2 trade against it: give them with its intrinsics, fixed, if a board "
            "calibration knows them)"
            if tangential
            else ""
        )
        out.append(
            f"{spec.name}: its principal point is uncertain by +-{principal:.1f} px{why}; wave the wand across "
            "more of its image and at more depths"
        )
    image_theta = float(angle_of_radius(model, np.array(max_image_radius_mm(model))))
    reach = min(spec.max_view_angle, image_theta if np.isfinite(image_theta) else spec.max_view_angle)
    if max_theta < COVERAGE_FRACTION * reach:
        out.append(
            f"{spec.name}: the wand was seen only up to {np.degrees(max_theta):.0f} deg off-axis while the image "
            f"reaches {np.degrees(reach):.0f} deg; the distortion beyond is extrapolated (wave the wand near the "
            "image corners)"
        )
    return out


def max_off_axis(result: BundleResult, problem: BundleProblem) -> FloatArray:
    """(C,) largest off-axis angle (rad) each camera observes at the solution (0 for a camera without views)."""
    state = result.state
    points = state.points(problem.wand)[problem.placement, problem.point]
    # the angle between each camera's optical axis (the third row of R) and the ray from its centre to the point
    axes = np.stack([pose.rotation[2] for pose in state.poses])[problem.camera]
    rays = points - np.stack([pose.center for pose in state.poses])[problem.camera]
    along = np.sum(axes * rays, axis=1)
    angles = np.arctan2(np.linalg.norm(rays - along[:, None] * axes, axis=1), along)
    out = np.zeros(problem.n_cameras)
    np.maximum.at(out, problem.camera, angles)
    return out


def assemble(
    rig: RigSpec,
    problem: BundleProblem,
    result: BundleResult,
    reference: int,
    fixed: FixedParameters,
    initial_projections: tuple[str, ...],
    lens_trials: tuple[LensTrial, ...],
    rejected: int,
    rejected_views: NDArray[np.int64],
    warnings: list[str],
    clocks: ClockModel,
    systematic: tuple[str, ...] = (),
    *,
    points: FloatArray,
) -> CalibrationResult:
    """The calibration of an adjustment's ``result`` on the observations ``problem``, ``points`` (P, K, 3) its
    placements' markers as :func:`free_placements` gives them (the wand lengths' statistics)."""
    free = free_mask(problem.n_cameras, reference, fixed)
    reported = free if fixed.pinned is None else free | (fixed.pinned.std > 0)  # (and those held at a prior)
    cameras = _cameras(rig, problem, result, fixed, reported, initial_projections, rejected_views, warnings)
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
        timing=timing_summary(rig, clocks, fixed),
        camera_covariance=result.camera_covariance,
        systematic=systematic,
    )


def _cameras(
    rig: RigSpec,
    problem: BundleProblem,
    result: BundleResult,
    fixed: FixedParameters,
    reported: NDArray[np.bool_],
    initial_projections: tuple[str, ...],
    rejected_views: NDArray[np.int64],
    warnings: list[str],
) -> list[CameraCalibration]:
    """Each camera's calibration in the rig's order, with the ``reported`` (C, N_CAMERA_PARAMS) standard
    deviations; what each camera's coverage, weak parameters and rejected views should say is added to ``warnings``."""
    state = result.state
    max_theta = max_off_axis(result, problem)
    n_cameras = problem.n_cameras
    counts = np.bincount(problem.camera, minlength=n_cameras)
    squares = np.bincount(
        problem.camera, squared_norms(in_pixels(result.residuals, state, problem)), minlength=n_cameras
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        rms_px = np.sqrt(squares / (2 * counts))  # over u and v; NaN for a camera without points
    view_counts = np.bincount(problem.camera[block_starts(problem.placement, problem.camera)], minlength=n_cameras)
    counts_by_class, mean_stops = class_points(problem)
    by_camera = np.argsort(problem.camera, kind="stable")  # each camera's observations, a run each
    bounds = np.searchsorted(problem.camera[by_camera], np.arange(n_cameras + 1))
    cameras = []
    for c, spec in enumerate(rig.cameras):
        std = {  # (the centre bias's with it: :func:`_class_biases`)
            name: float(result.camera_std[c, i])
            for i, name in enumerate(CAMERA_PARAM_NAMES[: BIAS.start])
            if reported[c, i]
        }
        pinned = fixed.pinned is not None and bool(fixed.pinned.cameras()[c])
        mine = problem.uv[by_camera[bounds[c] : bounds[c + 1]]]
        warnings.extend(coverage_warnings(spec, state.models[c], max_theta[c], result, c, mine, pinned))
        warnings.extend(weak_parameters(spec.name, float(state.models[c].k[0]), std))
        views = int(view_counts[c])
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
                float(rms_px[c]),
                int(counts[c]),
                std,
                float(np.degrees(max_theta[c])),
                initial_projections[c],
                tuple(CAMERA_PARAM_NAMES[i] for i in sorted(fixed.per_camera[c])),
                views,
                int(rejected_views[c]),
                result.camera_block(c, slice(0, 5)).copy(),
                float(state.camera_timing[c, 0]),
                float(state.camera_timing[c, 1]),
                "estimated" if spec.intrinsics is None else "given" if spec.intrinsics_fixed else "given_start",
                _class_biases(result, fixed, c, counts_by_class[c], mean_stops[c]),
            )
        )
    return cameras


def _class_biases(
    result: BundleResult, fixed: FixedParameters, camera: int, counts: NDArray[np.int64], means: FloatArray
) -> tuple[ClassBias, ...]:
    """Where the centres of each brightness class sit in ``camera`` by the bias the adjustment estimated, with
    their standard deviations (none where it has none); ``counts`` and ``means`` (N_BIAS_CLASSES + 1,) its points of
    each class and their mean brightness."""
    if fixed.bias is None or not fixed.bias[camera].any():
        return ()
    shape, start = int(result.state.bias_shapes[camera]), int(result.state.bias_starts[camera])
    values = result.state.camera_bias[camera]
    index = camera * N_CAMERA_PARAMS + BIAS.start + np.arange(N_BIAS)
    covariance = result.camera_covariance[np.ix_(index, index)]
    kept = fixed.bias[camera, ::3]
    out = []
    for k in range(1, N_BIAS_CLASSES + 1):
        one = np.ones(1, dtype=np.int8)
        weights = bias_weights(np.array([means[k]]), shape * one, start * one)[0]  # (terms,)
        if counts[k] < MIN_CLASS_POINTS or not np.any(weights * kept):
            continue
        mix = np.kron(weights, np.eye(3))  # (3, N_BIAS): the class's offsets from the terms
        u, v, r = (float(x) for x in mix @ values)
        std = np.sqrt(np.clip(np.diag(mix @ covariance @ mix.T), 0.0, None))
        spread = (float(std[0]), float(std[1]), float(std[2]))
        out.append(ClassBias(k, (u, v), r, spread, int(counts[k]), SHAPE_NAMES[shape]))
    return tuple(out)


def timing_summary(rig: RigSpec, clocks: ClockModel, fixed: FixedParameters) -> TimingSummary | None:
    """How the result treated the cameras' timing (None without timing input)."""
    line = clocks.line
    if line is None:
        return None
    return TimingSummary(
        line.unit,
        "estimated" if fixed.timing[:, 0].any() else "fixed",
        {spec.name: "estimated" if fixed.timing[c, 1] else "fixed" for c, spec in enumerate(rig.cameras)},
        line.frame_period,
        clocks.notes,
    )


def free_placements(state: BundleState, problem: BundleProblem, uv: FloatArray) -> FloatArray:
    """(P, K, 3) the markers of the adjusted views ``uv`` (P, C, K, 2, those of ``problem``) triangulated freely (no
    wand constraint) with the adjusted cameras, each placement as one instant saw it (reference frame, mm)."""
    return triangulate_placements(state.models, state.poses, synchronised_pixels(state, problem, uv))


def synchronised_pixels(state: BundleState, problem: BundleProblem, uv: FloatArray) -> FloatArray:
    """(P, C, 3, 2) the observations moved to their placement's time (the modelled motion removed), their centres'
    modelled bias removed.

    Triangulating these gives the wand as one instant saw it; without timing or bias they are ``uv``.
    """
    if problem.timing is None and (problem.brightness is None or state.bias is None):
        return uv
    moved = in_pixels(residuals(state, problem), state, problem)
    shift = moved - residuals(state, replace(problem, timing=None, brightness=None))
    out = np.array(uv, dtype=np.float64)
    out[problem.placement, problem.camera, problem.point] -= shift
    return out
