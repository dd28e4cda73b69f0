"""Repair a calibration after a camera moved: re-estimate only the moved cameras from new wand views.

Every other camera stays as calibrated. The new placements are triangulated by the unmoved cameras,
then one robust bundle adjustment frees the moved cameras' poses (and, if asked, their intrinsics)
with the placements; the reference frame is the unmoved cameras' (also when the reference camera is
the one that moved).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.bundle_adjustment import (
    N_CAMERA_PARAMS,
    N_GEOMETRIC,
    BundleProblem,
    BundleState,
    bundle_adjust,
)
from wand_calib_ros.core.camera_model import N_INTRINSIC, CameraModel
from wand_calib_ros.core.errors import InsufficientDataError
from wand_calib_ros.core.geometry import Pose, wand_directions
from wand_calib_ros.core.placements import triangulate_placements
from wand_calib_ros.core.refine import robust_adjustment
from wand_calib_ros.core.rig import WandSpec

FloatArray = NDArray[np.float64]

#: Fewest new placements (seen whole by two unmoved cameras and by the moved one) a repair needs.
MIN_PLACEMENTS = 10


@dataclass(frozen=True, eq=False)
class Repair:
    """A repaired calibration.

    Attributes:
        models, poses: every camera (the unmoved ones unchanged).
        moved: indices of the re-estimated cameras.
        rms_px: (C,) per-coordinate RMS of each camera's residuals on the new views, px.
        camera_std: (C, 15) standard deviations of the re-estimated parameters (0 where held).
        placements: new placements used.
    """

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    moved: tuple[int, ...]
    rms_px: FloatArray
    camera_std: FloatArray
    placements: int


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
    return Repair(result.state.models, result.state.poses, tuple(moved), rms, result.camera_std, int(rows.size))
