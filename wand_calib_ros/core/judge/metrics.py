"""Accuracy measures of the paper (Section IV-A) against a known truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.gating import ac_length_errors
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.camera_model import CameraModel, angle_of_radius, radius_mm
from wand_calib_ros.core.model.geometry import Pose, rotation_error_deg, translation_error
from wand_calib_ros.core.model.rig import WandSpec

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CameraErrors:
    """Errors of one calibrated camera against the truth.

    Attributes:
        focal_px: max |f - f_true| over fx, fy (identifiable focal lengths k1*m), px.
        focal_mm: |k1 - k1_true| in mm (meaningful when m is the true pixel density).
        principal_point_px: distance between estimated and true principal point, px.
        rotation_deg: the paper's E_r (0 for the reference camera).
        translation: the paper's E_t (NaN for the reference camera).
        curve_px: RMS of m (r(theta) - r_true(theta)) over the angles the image's inscribed circle
            reaches (CURVE_SAMPLES angles), px: the distortion curve's error.
    """

    focal_px: float
    focal_mm: float
    principal_point_px: float
    rotation_deg: float
    translation: float
    curve_px: float


#: Angles at which the distortion curves are compared.
CURVE_SAMPLES = 50


def curve_error_px(model: CameraModel, true_model: CameraModel) -> float:
    """RMS (px) of m_u (r(theta) - r_true(theta)) for theta up to where the true image radius reaches half
    the image's shorter side (the inscribed circle: every direction of the image sees it)."""
    inscribed = 0.5 * min(true_model.image_size) / float(true_model.m[0])
    limit = float(angle_of_radius(true_model, np.array(inscribed)))
    theta = np.linspace(0.0, limit if np.isfinite(limit) else 0.5, CURVE_SAMPLES)
    return float(true_model.m[0] * np.sqrt(np.mean((radius_mm(model, theta) - radius_mm(true_model, theta)) ** 2)))


def camera_errors(model: CameraModel, pose: Pose, true_model: CameraModel, true_pose: Pose) -> CameraErrors:
    """Compare one camera with its truth (poses in the same reference frame)."""
    t_norm = float(np.linalg.norm(true_pose.translation))
    return CameraErrors(
        focal_px=float(np.max(np.abs(model.focal_px - true_model.focal_px))),
        focal_mm=abs(float(model.k[0] - true_model.k[0])),
        principal_point_px=float(np.linalg.norm(model.principal_point - true_model.principal_point)),
        rotation_deg=rotation_error_deg(true_pose.rotation, pose.rotation),
        translation=translation_error(true_pose.translation, pose.translation) if t_norm > 1e-6 else float("nan"),
        curve_px=curve_error_px(model, true_model),
    )


def heldout_wand_rms(models: tuple[CameraModel, ...], poses: tuple[Pose, ...], uv: FloatArray, wand: WandSpec) -> float:
    """The paper's D_RMS: RMS of L - |A^r C^r| over placements triangulated linearly.

    Args:
        models, poses: the calibration to judge.
        uv: (P, C, 3, 2) pixels of placements not used in the calibration (NaN = unseen).
        wand: wand lengths.
    """
    errors = ac_length_errors(triangulate_placements(models, poses, uv), wand)
    return float(np.sqrt(np.nanmean(errors**2)))


def rereference(poses: dict[str, Pose], reference: str) -> dict[str, Pose]:
    """Express poses relative to another camera: X_c = R_c' X_ref' + T_c'."""
    inverse = poses[reference].inverse()
    return {name: pose.compose(inverse) for name, pose in poses.items()}
