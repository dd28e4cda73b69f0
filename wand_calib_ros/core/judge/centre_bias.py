"""Systematic centre errors the reprojection residual does not show: the centres of saturated LEDs against the rest.

A detector's centres can be biased for one kind of spot (a saturated one: blooming to one side, a lens's coma off
axis) in a way the cameras' models absorb: the residuals stay at the noise while the calibration is pulled. What
the models cannot absorb is a difference between the kinds in the same views: per camera, the mean residual of the
saturated points minus that of the others, along the direction away from the principal point (a radial bias) and
along u and v (a constant one), each against its standard error from the pixel noise. Where one stands beyond
BIAS_SIGMAS, the saturated points are moved by it and the adjustment made again (ALTERNATIONS times: the first
difference is only the part the models did not absorb); the cameras' parameters that move by more than their own
standard deviation are what the saturated centres pull, said per camera ("cam2: centres of saturated LEDs sit
0.48 px further out than the others ...: they pull its focal length by 0.9 % ..."), and they keep the grade from
"excellent".
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import GEOMETRY_PARTS, BundleProblem, PlacementTiming
from wand_calib_ros.core.errors import CoreError
from wand_calib_ros.core.model.geometry import rotvec_from_rotation
from wand_calib_ros.core.model.rig import RigSpec

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: A difference between saturated and other points beyond this many standard errors is a bias ...
BIAS_SIGMAS = 5.0
#: ... counted in a camera with at least this many points of each kind.
MIN_POINTS = 30
#: The saturated points are moved by the difference and the adjustment made again this many times.
ALTERNATIONS = 3
_UNITS = {"focal length": "%", "principal point": "px", "orientation": "deg", "position": "mm"}


@dataclass(frozen=True)
class CentreBias:
    """The centres of saturated LEDs in one camera, against its other points.

    Attributes:
        camera: the camera's name.
        radial_px: how much further from the principal point they sit than the others (the bias, px; negative:
            nearer).
        offset_px: (u, v) their constant offset from the others, px.
        sigmas: the largest of the three over its standard error.
        pulls: (parameter, how far, its standard deviations) that moved beyond one standard deviation when the
            bias was taken out: "focal length" (%), "principal point" (px), "orientation" (deg), "position" (mm).
    """

    camera: str
    radial_px: float
    offset_px: tuple[float, float]
    sigmas: float
    pulls: tuple[tuple[str, float, float], ...]

    def line(self) -> str:
        """The statement, with what to do."""
        side = "further from" if self.radial_px > 0 else "nearer to"
        where = f"sit {abs(self.radial_px):.2f} px {side} its centre than its other points"
        if abs(self.offset_px[0]) + abs(self.offset_px[1]) > abs(self.radial_px):
            where = f"sit ({self.offset_px[0]:+.2f}, {self.offset_px[1]:+.2f}) px off its other points"
        pulled = ", ".join(
            f"its {name} by {size:.2g} {_UNITS[name]} ({std:.1f} sigma)" for name, size, std in self.pulls
        )
        return (
            f"{self.camera}: centres of saturated LEDs {where} ({self.sigmas:.0f} sigma) and pull {pulled}: a "
            "detection bias of saturated spots; shorten the exposure or dim the LEDs"
        )


def saturated_pull(
    rig: RigSpec,
    uv: FloatArray,
    saturated: NDArray[np.bool_],
    timing: PlacementTiming | None,
    full: BundleResult,
    free: NDArray[np.bool_],
) -> tuple[CentreBias, ...]:
    """What the saturated points pull (module docstring); empty when they pull nothing beyond the parameters'
    standard deviations, or are too few to tell.

    Args:
        rig: the rig (cameras in the order of ``uv``'s axis 1).
        uv: (P, C, K, 2) the views of the full adjustment (NaN where none), as its problem was made from them.
        saturated: (P, C, K) which of their points were saturated spots.
        timing: the placements' timing in the full adjustment (None: synchronised).
        full: the full adjustment: its state, residuals (in ``BundleProblem.from_dense`` order), camera parameters
            and their standard deviations.
        free: (C, N_CAMERA_PARAMS) the camera parameters it estimated.
    """
    problem = BundleProblem.from_dense(rig.wand, uv, timing)
    if problem.n_observations != full.residuals.shape[0]:
        return ()
    flags = saturated[problem.placement, problem.camera, problem.point]
    bias = _differences(problem, flags, full)
    tested = np.flatnonzero(np.max(np.abs(bias[:, :3]) / bias[:, 3:], axis=1) > BIAS_SIGMAS)
    if not tested.size:
        return ()
    corrected, moved = uv.copy(), np.zeros((problem.n_cameras, 3))
    result = full
    try:
        for _ in range(ALTERNATIONS):  # the first difference is only what the models did not absorb
            moved[tested] += bias[tested, :3]
            corrected = _moved(uv, saturated, moved, full)
            again = BundleProblem.from_dense(rig.wand, corrected, timing)
            result = bundle_adjust(result.state, again, free)
            bias = _differences(again, flags, result)
    except CoreError as error:
        log.info("saturated centres: the adjustment without their bias failed (%s)", error)
        return ()
    found = []
    for c in tested:
        pulls = _pulls(full, result, free, int(c))
        if pulls:
            sigmas = float(np.max(np.abs(moved[c]) / np.maximum(_differences(problem, flags, full)[c, 3:], 1e-12)))
            offset = (-float(moved[c, 1]), -float(moved[c, 2]))
            found.append(CentreBias(rig.cameras[c].name, -float(moved[c, 0]), offset, sigmas, pulls))
    return tuple(found)


def _differences(problem: BundleProblem, flags: NDArray[np.bool_], result: BundleResult) -> FloatArray:
    """(C, 6) per camera the mean residual of its saturated points minus that of its others, (radial, u, v) px, and
    the standard errors of the three (inf where a kind has fewer than MIN_POINTS points)."""
    out = np.zeros((problem.n_cameras, 6))
    out[:, 3:] = np.inf
    radial = _radial(problem, result)
    for c in range(problem.n_cameras):
        mine = problem.camera == c
        sat, other = mine & flags, mine & ~flags
        if sat.sum() < MIN_POINTS or other.sum() < MIN_POINTS:
            continue
        res = result.residuals
        components = np.column_stack([np.sum(res * radial, axis=1), res])  # (M, 3)
        out[c, :3] = components[sat].mean(axis=0) - components[other].mean(axis=0)
        out[c, 3:] = result.sigma * np.sqrt(1.0 / sat.sum() + 1.0 / other.sum())
    return out


def _radial(problem: BundleProblem, result: BundleResult) -> FloatArray:
    """(M, 2) the unit direction away from its camera's principal point at each observation."""
    centres = np.array([m.principal_point for m in result.state.models])[problem.camera]
    away = problem.uv - centres
    return np.asarray(away / np.maximum(np.linalg.norm(away, axis=1, keepdims=True), 1e-9))


def _moved(uv: FloatArray, saturated: NDArray[np.bool_], moved: FloatArray, full: BundleResult) -> FloatArray:
    """(P, C, K, 2) the views with each camera's saturated points moved by (radial, u, v) ``moved`` (C, 3): the
    residual difference they showed (projected minus observed), so that they lose it."""
    centres = np.array([m.principal_point for m in full.state.models])  # (C, 2)
    away = uv - centres[None, :, None, :]
    radial = away / np.maximum(np.linalg.norm(away, axis=-1, keepdims=True), 1e-9)
    shift = moved[None, :, None, :1] * radial + moved[None, :, None, 1:]
    return np.where(saturated[..., None], uv + shift, uv)


def _pulls(
    full: BundleResult, corrected: BundleResult, free: NDArray[np.bool_], c: int
) -> tuple[tuple[str, float, float], ...]:
    """(parameter, how far, in its standard deviations) of camera ``c`` that the bias moved beyond one standard
    deviation of the full adjustment."""
    shift = np.zeros(20)
    mine, theirs = full.state.models[c], corrected.state.models[c]
    shift[0:5] = mine.k - theirs.k
    shift[5:7] = mine.principal_point - theirs.principal_point
    shift[7:10] = rotvec_from_rotation(full.state.poses[c].rotation @ corrected.state.poses[c].rotation.T)
    shift[10:13] = full.state.poses[c].translation - corrected.state.poses[c].translation
    out = []
    for name, columns in GEOMETRY_PARTS:  # (what a bias pulls)
        index = list(columns)
        std = full.camera_std[c, index]
        estimated = free[c, index] & (std > 0)
        if not estimated.any():
            continue
        sigmas = float(np.max(np.abs(shift[index])[estimated] / std[estimated]))
        if sigmas > 1.0:
            size = shift[index]
            value = (
                100.0 * abs(size[0]) / float(mine.k[0])
                if name == "focal length"
                else float(np.degrees(np.linalg.norm(size)))
                if name == "orientation"
                else float(np.linalg.norm(size))
            )
            out.append((name, value, sigmas))
    return tuple(out)
