"""Which camera model each camera is calibrated in, and its start in that model.

A camera is calibrated in the model its rig entry names (``camera_model``), else in the model its given
intrinsics are in, else in the fisheye (Kannala-Brandt) model the paper's initialisation works in, unless
the data choose a pinhole one (:func:`choose_models`). The initialisation's starts are fisheye-model
curves; a camera to be calibrated in a pinhole model starts from the pinhole curve nearest its start
(:func:`pinhole_start`): only a start, which the bundle adjustment then refines, never a result.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.brightness_bias import stops_of
from wand_calib_ros.core.adjust.bundle_adjustment import DECIDING_SETTLED, BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import INTRINSICS, LENS, N_CAMERA_PARAMS, BundleProblem, parameter_mask
from wand_calib_ros.core.adjust.chi_square import chi_square_quantile
from wand_calib_ros.core.adjust.model_order import FixedParameters, adjust_with_model_selection, free_mask
from wand_calib_ros.core.adjust.timing import ClockModel
from wand_calib_ros.core.errors import CoreError
from wand_calib_ros.core.initialise.intrinsics_init import FISHEYE_PROJECTIONS, fit_projection, initial_model
from wand_calib_ros.core.model.camera_model import (
    EQUIDISTANT,
    PINHOLE_MODELS,
    PLUMB_BOB,
    CameraModel,
    angle_of_radius,
    max_image_radius_mm,
    radius_mm,
)
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

#: Conventional cameras are calibrated in plumb_bob rather than the fisheye model when plumb_bob's
#: tangential terms, which the fisheye model does not have, are significant at this confidence (a Wald
#: test, chi-square with 2 degrees of freedom) and move the image's corners by more than the pixel noise:
#: its radial curve in tan(theta) and the fisheye model's in theta both follow a conventional lens, so the
#: tangential terms are what the data can tell them by. (At 99 % a camera of a fisheye-model rig with 3 %
#: of its views corrupted had switched, ring6 seed 3: chi-square 10.4.)
CHOICE_CONFIDENCE = 0.999
TANGENTIAL_THRESHOLD = chi_square_quantile(CHOICE_CONFIDENCE, 2)
#: The test adjustment settles as the passes that decide do (DECIDING_SETTLED), unless a candidate's terms are
#: within this Mahalanobis length (sqrt of chi-square units) of a threshold there: then it is adjusted to the
#: optimum first, so that every decision is the fully converged test's. (sqrt(DECIDING_SETTLED) = 0.32 bounds
#: what is left, with room for a last step's guess. mocap16 seed 4, cam15: chi-square 13.6 settled, 14.1
#: converged, against 13.8. At 64 cameras the test takes 0.45 s settled, 1.03 s converged.)
BORDERLINE = 0.5
#: Lenses whose field (theta_max) is narrower than this are conventional: the data may choose plumb_bob.
CONVENTIONAL_DEG = 80.0

#: The camera parameters that are not intrinsics (pose, timing).
_NOT_INTRINSIC = ~np.isin(np.arange(N_CAMERA_PARAMS), INTRINSICS)

#: A pinhole start is fitted up to this angle at most (rad): the pinhole curve grows without bound at 90
#: degrees.
MAX_PINHOLE_ANGLE = float(np.radians(80.0))
#: Samples of the fitted angles.
N_SAMPLES = 200


def undecided(spec: CameraSpec) -> bool:
    """Whether the data choose the camera's model: a conventional lens (a field under CONVENTIONAL_DEG,
    no fisheye hint) whose rig entry names no model and gives no intrinsics."""
    fisheye = spec.lens == "fisheye" or spec.lens in FISHEYE_PROJECTIONS
    return (
        spec.camera_model is None
        and spec.intrinsics is None
        and spec.max_view_angle_deg < CONVENTIONAL_DEG
        and not fisheye
    )


def choose_models(
    rig: RigSpec,
    uv: FloatArray,
    result: BundleResult,
    fixed: FixedParameters,
    reference: int,
    clocks: ClockModel,
    used: NDArray[np.int64],
    brightness: FloatArray | None = None,
) -> tuple[BundleResult, FixedParameters]:
    """The fisheye-model adjustment ``result`` of the placements ``used`` (their pixels ``uv``; ``brightness`` the
    timeline's points' brightness classes, None: not known) with the
    conventional cameras whose model the rig leaves open (:func:`undecided`) in plumb_bob instead, each where
    the data show its tangential terms (:data:`TANGENTIAL_THRESHOLD`). Each camera's order is then
    decided again in its model.

    Returns:
        The adjustment and its fixed parameters in the chosen models (``result``, ``fixed`` if none changed).
    """
    models = result.state.models  # (a warm start keeps the model an earlier calibration chose)
    candidates = [c for c, spec in enumerate(rig.cameras) if undecided(spec) and not models[c].is_pinhole]
    if not candidates:
        return result, fixed
    starts = list(models)
    for c in candidates:
        starts[c] = pinhole_start(models[c], PLUMB_BOB, rig.cameras[c].max_view_angle)
    state = replace(result.state, models=tuple(starts))
    # The test adjustment: every term of the candidates' plumb_bob free (its whole radial curve, so that
    # what the fisheye curve's shape leaves does not pass for tangential terms), the rest as ``result``.
    free = free_mask(len(rig.cameras), reference, fixed) & parameter_mask(state.models)
    free[candidates] |= parameter_mask(state.models)[candidates] & ~_NOT_INTRINSIC
    problem = BundleProblem.from_dense(rig.wand, uv, clocks.placements(used), None, stops_of(brightness, used))
    try:  # a test: settled as the passes that decide are, unless a camera's statistics are near a threshold
        tested = bundle_adjust(state, problem, free, settled=DECIDING_SETTLED)
        statistics = [_tangential_statistics(tested, c) for c in candidates]
        if any(_borderline(wald, size, tested.sigma) for wald, size in statistics):
            tested = bundle_adjust(tested.state, problem, free)
            statistics = [_tangential_statistics(tested, c) for c in candidates]
    except CoreError as error:  # the alternative did not converge: the fisheye model stays
        log.info("plumb_bob for %s not adjusted (%s)", ", ".join(rig.cameras[c].name for c in candidates), error)
        return result, fixed
    chosen = []
    for c, (wald, size) in zip(candidates, statistics, strict=True):
        log.info(
            "%s: plumb_bob's tangential terms: chi-square %.1f (needs %.1f), %.2f px at the image's corners (needs "
            "the noise, %.2f)", rig.cameras[c].name, wald, TANGENTIAL_THRESHOLD, size, tested.sigma,
        )  # fmt: skip
        if wald > TANGENTIAL_THRESHOLD and size > tested.sigma:
            chosen.append(c)
    if not chosen:
        return result, fixed
    chosen_models = list(result.state.models)
    for c in chosen:
        chosen_models[c] = tested.state.models[c]
    start = replace(tested.state, models=tuple(chosen_models))  # the model order of the chosen decided in plumb_bob
    # (the timing parameters ``fixed`` dropped as insignificant stay dropped: plumb_bob only fits the lenses better)
    return adjust_with_model_selection(
        rig, uv, start, reference, clocks, used, fixed.pinned, fixed.timing, brightness, fixed.bias
    )


def _tangential_statistics(tested: BundleResult, camera: int) -> tuple[float, float]:
    """The Wald statistic (chi-square, 2 degrees of freedom) of a camera's plumb_bob tangential terms in the test
    adjustment ``tested``, and the displacement they make at the image's corners (px, :func:`tangential_px`)."""
    index = camera * N_CAMERA_PARAMS + np.arange(LENS.start, LENS.start + 2)
    covariance = tested.camera_covariance[np.ix_(index, index)]
    terms = tested.state.models[camera].lens_vector()[:2]
    wald = float(terms @ np.linalg.pinv(covariance) @ terms) if np.any(covariance) else 0.0
    return wald, tangential_px(tested.state.models[camera])


def _borderline(wald: float, size: float, sigma: float) -> bool:
    """Whether a camera's statistics, read at a test settled to DECIDING_SETTLED (its cameras within about
    sqrt(DECIDING_SETTLED) standard deviations of the optimum, so its terms' Mahalanobis length within that of
    the optimum's), could lie on the other side of a threshold at the optimum (:data:`BORDERLINE`)."""
    length = float(np.sqrt(wald))
    near_wald = abs(length - np.sqrt(TANGENTIAL_THRESHOLD)) <= BORDERLINE
    passes = length + BORDERLINE > np.sqrt(TANGENTIAL_THRESHOLD)  # (the size decides only then)
    return near_wald or (passes and abs(size / sigma - 1.0) <= BORDERLINE / max(length, 1.0))


def tangential_px(model: CameraModel) -> float:
    """The largest image displacement (px) the model's tangential terms make at the image's corners."""
    width, height = model.image_size
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [-0.5, height - 0.5], [width - 0.5, height - 0.5]])
    a, b = ((corners - model.principal_point) / model.focal_px).T  # normalised, distortion aside
    t1, t2 = model.lens_vector()[:2]
    s2 = a * a + b * b
    du = model.m[0] * (2 * t1 * a * b + t2 * (s2 + 2 * a * a))
    dv = model.m[1] * (t1 * (s2 + 2 * b * b) + 2 * t2 * a * b)
    return float(np.max(np.hypot(du, dv)))


def target_model(spec: CameraSpec) -> str:
    """The camera model a camera is calibrated in, as its rig entry says (``equidistant`` where it says
    nothing)."""
    if spec.camera_model is not None:
        return spec.camera_model
    return spec.intrinsics.distortion_model if spec.intrinsics is not None else EQUIDISTANT


def nominal_model(spec: CameraSpec) -> CameraModel:
    """The data sheet's lens as a start: the perspective projection of the nominal focal for a conventional
    lens (under 80 degrees, no fisheye hint), else the equidistant one (or the ``lens`` projection named)."""
    if spec.lens not in (None, "fisheye", "conventional"):
        projection = str(spec.lens)
    elif spec.lens != "fisheye" and spec.max_view_angle < MAX_PINHOLE_ANGLE:
        projection = "perspective"
    else:
        projection = "equidistant"
    return initial_model(spec, fit_projection(projection, spec.nominal_focal_mm, spec.max_view_angle))


def pinhole_start(model: CameraModel, distortion_model: str, max_angle: float) -> CameraModel:
    """The pinhole model (``plumb_bob`` or ``rational_polynomial``) whose radial curve is nearest ``model``'s
    over the angles its image reaches (at most ``max_angle`` and :data:`MAX_PINHOLE_ANGLE`), without
    tangential or rational terms: k1..k3 of r(s) = k1 s + k2 s^3 + k3 s^5, s = tan(theta).

    Args:
        model: the start (any model).
        distortion_model: one of :data:`~wand_calib_ros.core.model.camera_model.PINHOLE_MODELS`.
        max_angle: the lens's theta_max, rad.
    """
    reach = float(angle_of_radius(model, np.array(max_image_radius_mm(model))))
    limit = min(max_angle, MAX_PINHOLE_ANGLE, reach if np.isfinite(reach) else MAX_PINHOLE_ANGLE)
    theta = np.linspace(0.0, limit, N_SAMPLES + 1)[1:]
    s = np.tan(theta)
    design = np.stack([s, s**3, s**5], axis=1)
    scale = np.max(np.abs(design), axis=0)
    coefficients = np.linalg.lstsq(design / scale, radius_mm(model, theta), rcond=None)[0] / scale
    k = np.r_[coefficients, 0.0, 0.0]
    return CameraModel(k, model.m, model.principal_point, model.image_size, distortion_model)


def model_starts(rig: RigSpec, models: tuple[CameraModel, ...]) -> tuple[CameraModel, ...]:
    """Each camera's start in the model it is calibrated in: its given intrinsics as given, else the
    initialisation's start (converted to the pinhole curve nearest it where the camera's model is one)."""
    starts = []
    for spec, model in zip(rig.cameras, models, strict=True):
        target = target_model(spec)
        if spec.intrinsics is not None:
            starts.append(spec.intrinsics)
        elif target in PINHOLE_MODELS and model.distortion_model != target:
            starts.append(pinhole_start(model, target, spec.max_view_angle))
        else:
            starts.append(model)
    return tuple(starts)
