"""The distortion model's order and the timing parameters the data support: adjust, drop what is not
significant (sequential Wald tests on k5, k4, k3 of the fisheye model, on k4, k3 of the pinhole models'
radial polynomial after their rational terms; the timing's own tests), re-adjust; on a coarse subset of
the placements, then the model order again on all of them at the final adjustment's start.

The pinhole models' tangential terms t1, t2 are not tested: they are what those models are chosen for
(:mod:`wand_calib_ros.core.initialise.lens_choice`), estimated wherever their camera's intrinsics are."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.brightness_bias import bias_candidates, class_noise, decide_bias, stops_of
from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, CameraSystem, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import (
    BIAS,
    CAMERA_PARAM_NAMES,
    INTRINSICS,
    LENS,
    N_CAMERA_PARAMS,
    TIMING,
    BundleProblem,
    BundleState,
    default_free_mask,
    parameter_mask,
)
from wand_calib_ros.core.adjust.timing import (
    ClockModel,
    reduce_timing,
)
from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.model.camera_model import (
    EQUIDISTANT,
    N_INTRINSIC,
    RATIONAL_POLYNOMIAL,
    CameraModel,
    turns_over_in_image,
)
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: The highest free radial coefficient is fixed to zero while |k| / std(k) is below this (Wald test).
SIGNIFICANCE = 2.0

#: Per camera model, the terms the model order tests, highest first (indices into the camera's
#: parameter vector, :data:`~wand_calib_ros.core.adjust.bundle_adjustment.CAMERA_PARAM_NAMES`): k5, k4, k3 of
#: the fisheye model's r(theta); k4, k3 of the pinhole models' polynomial in tan(theta) (OpenCV's k3,
#: k2), the rational denominator's d3, d2, d1 first.
ORDER_TERMS = {
    EQUIDISTANT: (4, 3, 2),
    "plumb_bob": (3, 2),
    RATIONAL_POLYNOMIAL: (LENS.start + 4, LENS.start + 3, LENS.start + 2, 3, 2),
}
#: The terms the robust pass (which only finds the outliers) holds at zero: the fisheye model's k3..k5,
#: the pinhole models' k4 (OpenCV's k3) and rational terms. The pinhole polynomial keeps its k3 (OpenCV's
#: k2): a conventional lens's barrel distortion moves the image corners by tens of pixels through it.
LOW_ORDER_FIXED = {
    EQUIDISTANT: (2, 3, 4),
    "plumb_bob": (3,),
    RATIONAL_POLYNOMIAL: (3, LENS.start + 2, LENS.start + 3, LENS.start + 4),
}


def _position(index: int) -> int:
    """Where a camera parameter (an intrinsic one) sits in :func:`intrinsics_of`'s (12,) vector."""
    return index if index < N_INTRINSIC else N_INTRINSIC + index - LENS.start


def intrinsics_of(model: CameraModel) -> FloatArray:
    """(12,) every intrinsic parameter of a model: k1..k5, u0, v0, then its lens terms (t1, t2, d1..d3)."""
    return np.concatenate([model.intrinsic_vector(), model.lens_vector()])


def with_intrinsics(model: CameraModel, vector: FloatArray) -> CameraModel:
    """``model`` with the (12,) intrinsics of :func:`intrinsics_of` (lens terms only where it has them)."""
    return model.with_intrinsic_vector(vector[:N_INTRINSIC], vector[N_INTRINSIC:] if model.is_pinhole else None)


def low_order(models: tuple[CameraModel, ...]) -> tuple[CameraModel, ...]:
    """The models with the terms of :data:`LOW_ORDER_FIXED` at zero (the robust pass's start)."""
    return tuple(zeroed(model, LOW_ORDER_FIXED[model.distortion_model]) for model in models)


def low_order_mask(models: tuple[CameraModel, ...], free: NDArray[np.bool_], *, terms: int = 0) -> NDArray[np.bool_]:
    """``free`` (C, N_CAMERA_PARAMS) with the terms of :data:`LOW_ORDER_FIXED` held, but for the first ``terms`` of them
    (k3 of the fisheye model, k4 of plumb_bob's: ``terms=1``)."""
    out = free.copy()
    for c, model in enumerate(models):
        out[c, list(LOW_ORDER_FIXED[model.distortion_model][terms:])] = False
    return out


@dataclass(frozen=True, eq=False)
class Pinned:
    """Camera parameters held at their start whatever the model order decides (a narrow field's principal
    point and distortion, :mod:`~wand_calib_ros.core.adjust.narrow_field`).

    Attributes:
        mask: (C, N_CAMERA_PARAMS) the parameters held.
        std: (C, N_CAMERA_PARAMS) the standard deviation of the prior they are held at (0: held exactly); the
            reported covariance includes it.
    """

    mask: NDArray[np.bool_]
    std: FloatArray

    def cameras(self) -> NDArray[np.bool_]:
        """(C,) the cameras with a parameter held."""
        return np.asarray(self.mask.any(axis=1))


@dataclass(frozen=True, eq=False)
class FixedParameters:
    """Distortion terms held at zero per camera (indices into the camera parameter vector: k1..k5 are
    0..4, the lens terms from :data:`~wand_calib_ros.core.adjust.bundle_adjustment.LENS` on), and the timing
    estimated.

    Attributes:
        per_camera: per camera the fixed terms.
        timing: (C, 2) whether each camera's time offset and readout time are estimated.
        held: (C,) cameras whose given intrinsics are held fixed (all of them).
        exists: (C, N_CAMERA_PARAMS) the parameters each camera's model has (None: the fisheye model's, every
            camera).
        pinned: parameters held at their start whatever the order (None: none).
        bias: (C, N_BIAS) the centre-bias terms estimated (:mod:`~wand_calib_ros.core.adjust.brightness_bias`;
            None: none).
    """

    per_camera: tuple[tuple[int, ...], ...]
    timing: NDArray[np.bool_]
    held: NDArray[np.bool_]
    exists: NDArray[np.bool_] | None = None
    pinned: Pinned | None = None
    bias: NDArray[np.bool_] | None = None

    def ordered(self) -> NDArray[np.bool_]:
        """(C,) the cameras whose model order is decided (neither given and held nor pinned)."""
        return ~self.held if self.pinned is None else ~self.held & ~self.pinned.cameras()


def held_intrinsics(rig: RigSpec) -> NDArray[np.bool_]:
    """(C,) cameras of the rig whose intrinsics are given and held fixed."""
    return np.array([spec.holds_intrinsics for spec in rig.cameras], dtype=bool)


def free_mask(n_cameras: int, reference: int, fixed: FixedParameters) -> NDArray[np.bool_]:
    """(C, N_CAMERA_PARAMS) the parameters an adjustment with ``fixed`` estimates."""
    free = default_free_mask(n_cameras, reference)
    for camera, indices in enumerate(fixed.per_camera):
        free[camera, list(indices)] = False
    free[np.ix_(fixed.held, INTRINSICS)] = False
    free[:, TIMING] = fixed.timing
    if fixed.bias is not None:
        free[:, BIAS] = fixed.bias
    if fixed.pinned is not None:
        free &= ~fixed.pinned.mask
    if fixed.exists is None:
        free[:, LENS] = False
        return free
    return free & fixed.exists


def zero_fixed(models: tuple[CameraModel, ...], fixed: FixedParameters) -> tuple[CameraModel, ...]:
    return tuple(zeroed(model, indices) for model, indices in zip(models, fixed.per_camera, strict=True))


def zeroed(model: CameraModel, indices: tuple[int, ...] | list[int]) -> CameraModel:
    """``model`` with the distortion terms ``indices`` (into the camera parameter vector) at zero."""
    vector = intrinsics_of(model)
    vector[[_position(i) for i in indices]] = 0.0
    return with_intrinsics(model, vector)


def adjust_with_model_selection(
    rig: RigSpec,
    uv: FloatArray,
    initial: BundleState,
    reference: int,
    clocks: ClockModel,
    used: NDArray[np.int64],
    pinned: Pinned | None = None,
    timing: NDArray[np.bool_] | None = None,
    brightness: FloatArray | None = None,
    bias: NDArray[np.bool_] | None = None,
) -> tuple[BundleResult, FixedParameters]:
    """Bundle-adjust with every k3..k5 (and the timing) free, then drop what the data do not support and re-adjust.

    Per camera the highest free coefficient among k3..k5 is fixed to zero while it
    is insignificant (|k| < SIGNIFICANCE sigma) or makes r(theta) turn over inside
    the image. The first decision is made on the adjustment's first linearisation
    (:class:`OrderOnAllPlacements` at SIGNIFICANCE: the full model's linearised estimate from
    the low-order start), so the adjustment runs on the order it chose instead of converging
    the full model first. At its solution the same tests run again on the linearised problem:
    fixing k_h = 0 moves the other parameters to their conditional mean
    ``x - cov[:, h] / cov[h, h] * x[h]`` and shrinks the covariance accordingly, so
    one re-adjustment (from that better start) settles a term fixed only then. Time
    offsets and readout times under ``auto`` are kept only when significant
    (:func:`wand_calib_ros.core.adjust.timing.reduce_timing`), and a centre bias only where significant
    (:func:`~wand_calib_ros.core.adjust.brightness_bias.reduce_bias`).

    Args:
        uv: (P, C, 3, 2) the placements to adjust, ``used`` (P,) their indices in the timeline.
        pinned: parameters held at their start (no order decided for their cameras).
        timing: (C, 2) the timing parameters to estimate, ``clocks.free`` or fewer (None: ``clocks.free``): a
            decision made before, whose dropped parameters ``initial`` holds at ``clocks.start``, is not made again.
        brightness: (T, C, 3) the brightness of the timeline's points, stops over full scale (None: not known).
        bias: (C, N_BIAS) the bias terms to estimate, of the candidates or fewer (None: every candidate): a
            decision made before, in the shapes ``initial`` has (:func:`~wand_calib_ros.core.adjust.
            brightness_bias.decide_bias`).
    """
    problem = BundleProblem.from_dense(rig.wand, uv, clocks.placements(used), None, stops_of(brightness, used))
    exists = parameter_mask(initial.models)
    free_timing = clocks.free if timing is None else clocks.free & timing
    free_bias = bias_candidates(problem) if bias is None else bias
    fixed = FixedParameters(
        tuple(() for _ in rig.cameras), free_timing.copy(), held_intrinsics(rig), exists, pinned, free_bias
    )
    start = initial
    choose: OrderOnAllPlacements | None = OrderOnAllPlacements(rig, fixed, reference, len(uv))
    while True:
        result = bundle_adjust(start, problem, free_mask(len(rig.cameras), reference, fixed), choose=choose)
        log.info("bundle adjustment: %d iterations, sigma %.3f px", result.iterations, result.sigma)
        if choose is not None:  # the order chosen at the start is the one this adjustment ran with
            fixed, choose = choose.decision, None
        per_camera = list(fixed.per_camera)
        models = list(result.state.models)
        for c, spec in enumerate(rig.cameras):
            if fixed.ordered()[c]:  # given intrinsics held fixed, or pinned, have no model order to decide
                covariance = intrinsic_covariance(result.camera_covariance, c)
                per_camera[c], models[c] = reduce_radial(spec, models[c], covariance, per_camera[c])
        timing = reduce_timing(clocks, result, fixed.timing)
        kept, centre, weighed = fixed.bias, result.state.bias, False
        if fixed.bias is not None:
            kept, centre = decide_bias(result, fixed.bias, problem, rig.camera_names)
            if centre.noise is None:  # (the first adjustment's residuals tell each class's noise: weighed from now)
                centre, weighed = replace(centre, noise=class_noise(result, problem)), True
        if (
            not weighed
            and tuple(per_camera) == fixed.per_camera
            and np.array_equal(timing, fixed.timing)
            and (kept is None or fixed.bias is None or np.array_equal(kept, fixed.bias))
            and (centre is None or np.array_equal(centre.shapes, result.state.bias_shapes))
        ):
            log.info("model order on %d placements: %s", len(uv), _orders_text(rig, fixed))
            return result, fixed
        state = result.state
        values = state.camera_timing.copy()
        values[fixed.timing & ~timing] = clocks.start[fixed.timing & ~timing]
        fixed = replace(fixed, per_camera=tuple(per_camera), timing=timing, bias=kept)
        start = replace(state, models=zero_fixed(tuple(models), fixed), timing=values, bias=centre)


def intrinsic_covariance(covariance: FloatArray, camera: int) -> FloatArray:
    """(12, 12) the covariance of one camera's :func:`intrinsics_of` from the (C*N_CAMERA_PARAMS, C*N_CAMERA_PARAMS)
    camera covariance."""
    index = camera * N_CAMERA_PARAMS + INTRINSICS
    return covariance[np.ix_(index, index)]


@dataclass(eq=False)
class OrderOnAllPlacements:
    """The radial model order decided on all of an adjustment's placements at its start (a
    :data:`~wand_calib_ros.core.adjust.bundle_adjustment.ChooseFree` for :func:`bundle_adjust`, on its
    first linearisation), with the effect size of SIGNIFICANCE on ``coarse_placements`` placements.

    k3..k5 are released on the normal equations (:meth:`CameraSystem.step`: the linearised estimate
    of the full model) and the sequential tests of :func:`reduce_radial` keep a term from
    ``|k| / std(k) >= SIGNIFICANCE * sqrt(P / coarse_placements)`` on, P the adjustment's placements.
    Two uses:

    - :func:`adjust_with_model_selection`'s first adjustment (``coarse_placements`` = P, nothing
      fixed yet): from the low-order start it runs on the order chosen here, not the full model.
    - The final adjustment, on more placements than that coarse subset, where a term near the
      threshold was kept or dropped by the luck of the subset drawn (which cameras keep k4, or
      lose k3, changes from one subset to the next). Its decision is the coarse rule's on
      average, without the subset's sampling noise.

    Attributes:
        rig, fixed, reference: the rig, the order so far, the reference camera.
        coarse_placements: the placements the effect size refers to (how many the coarse decision was made on).
        decision: the order: ``fixed`` until a call changes it.
    """

    rig: RigSpec
    fixed: FixedParameters
    reference: int
    coarse_placements: int
    decision: FixedParameters = field(init=False)

    def __post_init__(self) -> None:
        self.decision = self.fixed

    def __call__(
        self, state: BundleState, system: CameraSystem, sigma: float
    ) -> tuple[NDArray[np.bool_], FloatArray] | None:
        """The parameters to estimate and the steps of the radial terms fixed now; None: the order stands."""
        fixed, n_cameras, n_placements = self.fixed, len(self.rig.cameras), state.wand_a.shape[0]
        significance = SIGNIFICANCE * np.sqrt(max(n_placements / self.coarse_placements, 1.0))
        release = free_mask(n_cameras, self.reference, fixed)
        ordered = fixed.ordered()
        for c, model in enumerate(state.models):  # k3..k5 (the pinhole models' k3, k4 and rational terms)
            if ordered[c]:
                release[c, list(ORDER_TERMS[model.distortion_model])] = True
        delta = system.step(release)
        covariance = system.covariance(release, sigma)
        values = np.array([intrinsics_of(model) for model in state.models])  # (C, 12)
        per_camera = list(fixed.per_camera)
        for c, spec in enumerate(self.rig.cameras):
            if not ordered[c]:
                continue
            try:
                released = with_intrinsics(state.models[c], values[c] + delta[c, INTRINSICS])
            except ModelError:  # the linearised step leaves the camera model: no evidence to change the order
                continue
            decided, _ = reduce_radial(spec, released, intrinsic_covariance(covariance, c), (), significance)
            if set(decided) != set(per_camera[c]):  # (the order the tests fix them in aside)
                per_camera[c] = decided
        if per_camera == list(fixed.per_camera):
            return None
        self.decision = replace(fixed, per_camera=tuple(per_camera))
        log.info(
            "model order chosen on all %d placements at the adjustment's start: %s",
            n_placements,
            _orders_text(self.rig, self.decision),
        )
        moves = np.zeros_like(delta)  # terms fixed now go to zero (those fixed before are)
        for c, model in enumerate(state.models):
            terms = list(ORDER_TERMS[model.distortion_model])
            moves[c, terms] = -values[c, [_position(i) for i in terms]]
        moves[~ordered] = 0.0
        return free_mask(n_cameras, self.reference, self.decision), moves


def _orders_text(rig: RigSpec, fixed: FixedParameters) -> str:
    """The radial terms fixed at zero, cameras grouped (``radial terms fixed at 0: k4, k5 (14 cameras); k5
    (cam01, cam04)``)."""
    groups: dict[tuple[int, ...], list[str]] = {}
    for spec, order, decided in zip(rig.cameras, fixed.per_camera, fixed.ordered(), strict=True):
        if decided:
            groups.setdefault(tuple(sorted(order)), []).append(spec.name)
    parts = []
    for order, names in sorted(groups.items(), key=lambda item: -len(item[1])):
        terms = ", ".join(CAMERA_PARAM_NAMES[i] for i in order) or "none"
        who = f"{len(names)} cameras" if len(names) > 3 else ", ".join(names)
        parts.append(f"{terms} ({who})")
    return (
        "radial terms fixed at 0: " + "; ".join(parts)
        if parts
        else "no order to decide (every camera's intrinsics given or held)"
    )


def reduce_radial(
    spec: CameraSpec,
    model: CameraModel,
    covariance: FloatArray,
    fixed: tuple[int, ...],
    significance: float = SIGNIFICANCE,
) -> tuple[tuple[int, ...], CameraModel]:
    """Sequential Wald tests on the model's :data:`ORDER_TERMS` (k5, k4, k3 of the fisheye model) of one
    camera (see adjust_with_model_selection).

    Args:
        model: the camera's estimate; ``covariance`` (12, 12) that of its :func:`intrinsics_of` (or (7, 7)
            that of k1..k5, u0, v0 alone: no lens terms estimated).
        fixed: the terms already fixed at zero (indices into the camera parameter vector).
        significance: a term is kept from ``significance`` standard deviations on.

    Returns:
        The camera's fixed terms and its intrinsics moved to the conditional estimate.
    """
    estimate = intrinsics_of(model)
    full = np.zeros((estimate.size, estimate.size))
    full[: covariance.shape[0], : covariance.shape[1]] = covariance
    covariance = full
    fixed_now = list(fixed)
    for highest in ORDER_TERMS[model.distortion_model]:
        if highest in fixed_now:
            continue
        at = _position(highest)
        variance = covariance[at, at]
        z = abs(estimate[at]) / np.sqrt(variance) if variance > 0 else 0.0
        # The curve the test judges: where the conditional shifts so far put it, or, should they leave
        # the camera model (k1 <= 0), the estimate with the fixed terms at zero.
        try:
            current = with_intrinsics(model, estimate)
        except ModelError:
            current = zeroed(model, fixed_now)
        name = CAMERA_PARAM_NAMES[highest]
        if turns_over_in_image(current, spec.max_view_angle):
            log.debug("%s: r(theta) turns over inside the image with %s free: fixed to 0", spec.name, name)
        elif z < significance:
            log.debug(
                "%s: %s = %.3g is %.1f sigma, under %.1f: fixed to 0", spec.name, name, estimate[at], z, significance
            )
        else:
            break
        if variance > 0:
            gain = covariance[:, at] / variance
            estimate = estimate - gain * estimate[at]
            covariance = covariance - np.outer(gain, covariance[at])
        estimate[at] = 0.0
        fixed_now.append(highest)
    try:
        return tuple(fixed_now), with_intrinsics(model, estimate)
    except ModelError:  # the linearised shift leaves the camera model (k1 <= 0): re-adjust from the zeros instead
        return tuple(fixed_now), zeroed(model, fixed_now)
