"""Repair a calibration after a camera moved: re-estimate only the moved cameras from new wand views.

Every other camera stays as calibrated. The new placements are triangulated by the unmoved cameras,
then one robust bundle adjustment frees the moved cameras' poses (and, if asked, their intrinsics)
with the placements; the reference frame is the unmoved cameras' (also when the reference camera is
the one that moved).

Live, the views since the calibration also hold the frames from before the move: :func:`since_move`
finds where the moved cameras began to disagree, so only the views after it are used.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import (
    CAMERA_PARAM_NAMES,
    N_CAMERA_PARAMS,
    N_GEOMETRIC,
    BundleProblem,
    BundleState,
)
from wand_calib_ros.core.adjust.gating import robust_adjustment
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.after.bumps import WINDOW, BumpMonitor, noise_levels, pair_dof, pair_squares
from wand_calib_ros.core.errors import InsufficientDataError
from wand_calib_ros.core.initialise.vision_graph import covisibility
from wand_calib_ros.core.model.camera_model import N_INTRINSIC, CameraModel
from wand_calib_ros.core.model.geometry import Pose, wand_directions
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import WandSpec

FloatArray = NDArray[np.float64]

#: Fewest new placements (seen whole by two unmoved cameras and by the moved one) a repair needs.
MIN_PLACEMENTS = 10
#: Fewest new views of the whole wand a camera pair must share for its agreement to be judged.
MIN_JUDGED = 20
#: How much better (log-likelihood, in units of the fits' chi-square) a start after the first frame must
#: explain the frames than the first: below it, every frame counts as after the move.
CHANGE_EVIDENCE = 10.0


@dataclass(frozen=True, eq=False)
class Repair:
    """A repaired calibration.

    Attributes:
        models, poses: every camera (the unmoved ones unchanged).
        moved: indices of the re-estimated cameras.
        rms_px: (C,) per-coordinate RMS of each camera's residuals on the new views, px.
        camera_std: (C, 15) standard deviations of the re-estimated parameters (0 where held).
        placements: new placements used.
        wand_lengths: (P,) their |first - last marker| triangulated with the repaired cameras, mm.
    """

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    moved: tuple[int, ...]
    rms_px: FloatArray
    camera_std: FloatArray
    placements: int
    wand_lengths: FloatArray

    def parameter_std(self, c: int) -> dict[str, float]:
        """Camera ``c``'s re-estimated parameters' standard deviations by name (k1..k5 mm, u0 v0 px,
        rx ry rz rad, tx ty tz mm)."""
        return {k: float(self.camera_std[c, i]) for i, k in enumerate(CAMERA_PARAM_NAMES) if self.camera_std[c, i] > 0}


def judge_moved(
    names: tuple[str, ...],
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    wand: WandSpec,
    sigma_px: float,
    uv: FloatArray,
) -> tuple[tuple[int, ...], list[str]]:
    """Which cameras the views ``uv`` (F, C, K, 2) show moved since a calibration of pixel noise
    ``sigma_px`` (per coordinate): their indices and one message each (:class:`BumpMonitor`); a camera
    no pair of which shares MIN_JUDGED views of the whole wand cannot be judged, and is named.

    Raises:
        InsufficientDataError: no camera pair shares MIN_JUDGED views, or ``sigma_px`` is not a noise.
    """
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise InsufficientDataError(
            f"the calibration's pixel noise is {sigma_px}: new views cannot be judged against it"
        )
    complete = np.all(np.isfinite(uv), axis=(2, 3))
    shared = covisibility(complete)
    np.fill_diagonal(shared, 0)
    if shared.max(initial=0) < MIN_JUDGED:
        raise InsufficientDataError(
            f"only {int((complete.sum(axis=1) >= 2).sum())} placements show the whole wand to two cameras in the new "
            f"views; judging whether a camera moved needs {MIN_JUDGED} that a camera pair shares ({WINDOW} best): "
            "wave the wand longer, or name the camera that moved (--moved)"
        )
    unjudged = [names[c] for c in range(len(names)) if shared[c].max(initial=0) < MIN_JUDGED]
    monitor = BumpMonitor(names, models, poses, wand, noise_levels(sigma_px, len(names)))
    monitor.add(uv)
    notes = [
        f"{name}: not judged, it shares fewer than {MIN_JUDGED} whole-wand views with any camera" for name in unjudged
    ]
    return monitor.moved(), [*monitor.messages(), *notes]


def since_move(
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    wand: WandSpec,
    sigma_px: float,
    uv: FloatArray,
    moved: tuple[int, ...],
) -> int:
    """The first of the frames ``uv`` (F, C, K, 2, in time order) taken after the ``moved`` cameras moved.

    A frame's ratio r is the mean square per degree of freedom of the moved cameras' two-view wand fits
    with unmoved cameras over the noise's (``sigma_px`` per coordinate): 1 on average before the move,
    a larger m after it. The start is the maximum-likelihood change point of that scaled chi-square: the
    frame k maximising d/2 (m - 1 - log m) over the frames from k on (d their degrees of freedom, m their
    mean ratio), unless it
    beats k = 0 by less than :data:`CHANGE_EVIDENCE` (then 0: no frame before the move is evident).
    """
    squares = pair_squares(models, poses, wand, uv)
    still = [c for c in range(len(models)) if c not in moved]
    pairs = squares[:, list(moved)][:, :, still].reshape(uv.shape[0], -1)
    counts = np.isfinite(pairs).sum(axis=1)
    frames = np.flatnonzero(counts > 0)
    if frames.size < 2:
        return 0
    dof = pair_dof(wand) * counts[frames]
    ratio = np.nansum(pairs[frames], axis=1) / (dof * float(sigma_px) ** 2)
    n = np.arange(frames.size, 0, -1)  # frames from k on
    mean = np.maximum(np.cumsum(ratio[::-1])[::-1] / n, 1.0)
    score = 0.5 * np.cumsum(dof[::-1])[::-1] * (mean - 1.0 - np.log(mean))  # gamma log-likelihood ratio
    best = int(np.argmax(score))
    return int(frames[best]) if score[best] - score[0] >= CHANGE_EVIDENCE else 0


def repair(
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    wand: WandSpec,
    uv: FloatArray,
    moved: tuple[int, ...],
    *,
    intrinsics: bool = False,
    names: tuple[str, ...] | None = None,
) -> Repair:
    """Re-estimate the ``moved`` cameras from new views ``uv`` (F, C, K, 2), everything else held.

    Raises:
        InsufficientDataError: every camera moved, or too few new placements tie a moved camera to
            two unmoved ones (the message names the camera).
    """
    n_cameras = len(models)
    names = names or tuple(f"#{c}" for c in range(n_cameras))
    still = [c for c in range(n_cameras) if c not in moved]
    if len(still) < 2:
        raise InsufficientDataError("a repair keeps at least two cameras as calibrated; recalibrate instead")
    whole = np.all(np.isfinite(uv), axis=(2, 3))
    anchored = whole[:, still].sum(axis=1) >= 2
    for c in moved:
        count = int(np.sum(anchored & whole[:, c]))
        if count < MIN_PLACEMENTS:
            raise InsufficientDataError(
                f"camera '{names[c]}': only {count} new placements show the whole wand to it and to two unmoved "
                f"cameras; wave the wand where they overlap (at least {MIN_PLACEMENTS})"
            )
    rows = np.flatnonzero(anchored)
    fixed_only = uv[rows].copy()
    fixed_only[:, list(moved)] = np.nan
    points = triangulate_placements(models, poses, fixed_only)
    ok = np.all(np.isfinite(points), axis=(1, 2))
    rows, points = rows[ok], points[ok]
    state = BundleState(models, poses, points[:, 0], wand_directions(points[:, 0], points[:, -1]))
    problem = BundleProblem.from_dense(wand, uv[rows])
    free = np.zeros((n_cameras, N_CAMERA_PARAMS), dtype=bool)
    for c in moved:
        free[c, N_INTRINSIC:N_GEOMETRIC] = True
        if intrinsics:
            free[c, :N_INTRINSIC] = True
            free[c, 2:5] = False  # k3..k5 as calibrated: a repair has too few views for the full curve
    robust, _ = robust_adjustment(state, problem, free)  # outliers down-weighted ...
    result = bundle_adjust(robust.state, problem, free)  # ... then the least-squares optimum from there
    rms = np.array(
        [
            float(np.sqrt(np.mean(result.residuals[problem.camera == c] ** 2)))
            if np.any(problem.camera == c)
            else np.nan
            for c in range(n_cameras)
        ]
    )
    models, poses = result.state.models, result.state.poses
    ends = triangulate_placements(models, poses, uv[rows])
    lengths = np.linalg.norm(ends[:, -1] - ends[:, 0], axis=-1)
    lengths = lengths[np.isfinite(lengths)]
    return Repair(models, poses, tuple(moved), rms, result.camera_std, int(rows.size), lengths)


def repair_moved(
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    wand: WandSpec,
    sigma_px: float,
    uv: FloatArray,
    moved: tuple[int, ...],
    *,
    intrinsics: bool = False,
    names: tuple[str, ...] | None = None,
) -> tuple[int, Repair]:
    """:func:`repair` from the views after the move: the first frame of ``uv`` (F, C, K, 2, in time order)
    taken after it (:func:`since_move`; 0 when the calibration's noise ``sigma_px`` is unknown) and the
    repair from there."""
    first = since_move(models, poses, wand, sigma_px, uv, moved) if np.isfinite(sigma_px) else 0
    return first, repair(models, poses, wand, uv[first:], moved, intrinsics=intrinsics, names=names)


def repaired_result(result: CalibrationResult, fixed: Repair, names: tuple[str, ...], note: str) -> CalibrationResult:
    """``result`` with the cameras ``fixed`` re-estimated replaced (model, pose, RMS on the new views, the
    re-estimated parameters' standard deviations), the wand-length statistics of the new views, ``note``
    among its warnings; all else as calibrated.
    ``names`` are the cameras in the order of ``fixed``'s indices (the rig's)."""
    cameras = list(result.cameras)
    order = [camera.name for camera in cameras]
    for c in fixed.moved:
        i = order.index(names[c])
        cameras[i] = replace(
            cameras[i],
            model=fixed.models[c],
            pose=fixed.poses[c],
            rms_reprojection_px=float(fixed.rms_px[c]),
            parameter_std={**cameras[i].parameter_std, **fixed.parameter_std(c)},
        )
    lengths = fixed.wand_lengths
    return replace(
        result,
        cameras=tuple(cameras),
        wand_length_rms_mm=float(np.sqrt(np.mean((result.wand.L - lengths) ** 2))),
        wand_length_mean_mm=float(np.mean(lengths)),
        wand_length_std_mm=float(np.std(lengths)),
        warnings=(*result.warnings, note),
    )
