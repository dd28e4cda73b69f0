"""A calibration's quality in plain words: per camera image error, the world error from the wand, a grade.

The grade is the best of :data:`GRADES` whose every limit the calibration meets:

- each camera's image error (its per-coordinate reprojection RMS) against the pixel noise the bundle
  adjustment estimated: a camera fitting worse than the rig's own noise has an error the model does not
  explain (it moved during the take, its timing or lens model is wrong, outliers were kept);
- the pixel noise itself: the detection's accuracy bounds everything downstream;
- the world error: the wand-length RMS (mm) against what the estimated pixel noise alone causes (the
  placements re-triangulated from their own reprojections plus that noise, :func:`noise_wand_error`):
  a calibration error adds to it;
- each camera's parameter uncertainty: focal length (% of it) and principal point (px), one standard
  deviation from the adjustment's covariance (absent where the rig description gave them);
- for "excellent", no systematic error the residuals do not show (``CalibrationResult.systematic``: the
  centres of saturated LEDs pulling a camera, :mod:`~wand_calib_ros.core.judge.centre_bias`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.camera_model import project
from wand_calib_ros.core.model.result import CalibrationResult, CameraCalibration, CameraQuality, Verdict
from wand_calib_ros.core.model.rig import spread_subset

FloatArray = NDArray[np.float64]

#: Noisy re-triangulations of every placement behind the noise's own wand-length error ...
NOISE_DRAWS = 4
#: ... of at most this many placements spread over the take (10,000 draws: the RMS to about 1 %).
NOISE_PLACEMENTS = 2500


@dataclass(frozen=True)
class Limits:
    """The limits of one grade.

    Attributes:
        noise_ratio: a camera's image error over the estimated pixel noise, at most.
        noise_px: the estimated pixel noise (per coordinate), px, at most.
        world_ratio: the wand-length RMS over the noise's own (:func:`noise_wand_error`), at most.
        focal_percent: a camera's focal-length standard deviation, % of the focal length, at most.
        principal_px: a camera's principal-point standard deviation (both axes together), px, at most.
    """

    noise_ratio: float
    noise_px: float
    world_ratio: float
    focal_percent: float
    principal_px: float


#: Grades from best to worst with their limits; a calibration meeting none is "poor".
GRADES: tuple[tuple[str, Limits], ...] = (
    ("excellent", Limits(noise_ratio=1.25, noise_px=0.25, world_ratio=1.25, focal_percent=0.2, principal_px=1.0)),
    ("good", Limits(noise_ratio=1.5, noise_px=0.5, world_ratio=1.5, focal_percent=0.5, principal_px=2.0)),
    ("acceptable", Limits(noise_ratio=2.0, noise_px=1.5, world_ratio=2.0, focal_percent=1.0, principal_px=5.0)),
)
POOR = "poor"


def camera_quality(camera: CameraCalibration, noise_px: float) -> CameraQuality:
    """A calibrated camera's figures against the rig's estimated pixel noise (px, per coordinate)."""
    std = camera.parameter_std
    focal = 100.0 * std.get("k1", 0.0) / float(camera.model.k[0])
    principal = float(np.hypot(std.get("u0", 0.0), std.get("v0", 0.0)))
    ratio = camera.rms_reprojection_px / noise_px if noise_px > 0 else float("inf")
    return CameraQuality(camera.name, camera.rms_reprojection_px, ratio, focal, principal)


def noise_wand_error(result: CalibrationResult, names: tuple[str, ...], uv: FloatArray, seed: int = 0) -> float:
    """The wand-length RMS (mm) the estimated pixel noise alone causes on these placements.

    Each placement of ``uv`` (F, C, K, 2; cameras in ``names`` order, NaN where unseen; at most
    :data:`NOISE_PLACEMENTS` of them, spread over the take) is triangulated
    with the calibration, reprojected into the cameras that saw it, given Gaussian noise of the
    estimated sigma (seeded: the same figure every time) and triangulated again; the RMS of the change
    in its first-to-last marker length over :data:`NOISE_DRAWS` draws is the result.
    """
    models = tuple(result.camera(n).model for n in names)
    poses = tuple(result.camera(n).pose for n in names)
    uv = uv[spread_subset(uv.shape[0], NOISE_PLACEMENTS)]
    points = triangulate_placements(models, poses, uv)
    ok = np.all(np.isfinite(points), axis=(1, 2))
    if not ok.any():
        return float("nan")
    points, seen = points[ok], np.isfinite(uv[ok])
    flat = points.reshape(-1, 3)
    clean = np.stack(
        [project(m, p.apply(flat)).reshape((*points.shape[:2], 2)) for m, p in zip(models, poses, strict=True)], axis=1
    )  # (F, C, K, 2)
    clean = np.where(seen, clean, np.nan)
    length = np.linalg.norm(points[:, -1] - points[:, 0], axis=-1)
    # every draw at once: the draws' placements side by side in one triangulation (the same numbers as one by one)
    drawn = clean + np.random.default_rng(seed).normal(0.0, result.sigma_px, (NOISE_DRAWS, *clean.shape))
    noisy = triangulate_placements(models, poses, drawn.reshape(-1, *clean.shape[1:])).reshape(
        NOISE_DRAWS, *points.shape
    )
    changes = np.linalg.norm(noisy[:, :, -1] - noisy[:, :, 0], axis=-1) - length
    return float(np.sqrt(np.nanmean(np.square(changes))))


def _shortfalls(cameras: tuple[CameraQuality, ...], noise_px: float, world_ratio: float, limits: Limits) -> list[str]:
    """What of a calibration exceeds ``limits``, one phrase each."""
    out = []
    for c in cameras:
        if not c.noise_ratio <= limits.noise_ratio:
            out.append(
                f"{c.name}'s image error {c.image_error_px:.2f} px is {c.noise_ratio:.1f}x the noise "
                f"(at most {limits.noise_ratio:g}x: moved during the take, timing, lens model or outliers?)"
            )
    if not noise_px <= limits.noise_px:
        out.append(f"the pixel noise {noise_px:.2f} px (at most {limits.noise_px:g}: detection accuracy)")
    if not world_ratio <= limits.world_ratio:
        out.append(
            f"the wand-length error, {world_ratio:.1f}x what the noise causes (at most {limits.world_ratio:g}x: "
            "a calibration error, or wand lengths that differ from the rig description's)"
        )
    for c in cameras:
        if not c.focal_std_percent <= limits.focal_percent:
            out.append(
                f"{c.name}'s focal length +- {c.focal_std_percent:.2f} % (at most {limits.focal_percent:g} %: "
                "more views near its image's edges)"
            )
        if not c.principal_std_px <= limits.principal_px:
            out.append(
                f"{c.name}'s principal point +- {c.principal_std_px:.1f} px (at most {limits.principal_px:g}: "
                "more views across its image and depths)"
            )
    return out


def judge(result: CalibrationResult, world_noise_mm: float) -> Verdict:
    """The verdict on a calibration (module docstring), ``world_noise_mm`` from :func:`noise_wand_error`
    (NaN: the world error is not judged)."""
    noise = float(result.sigma_px)
    cameras = tuple(camera_quality(c, noise) for c in result.cameras)
    world_ratio = result.wand_length_rms_mm / world_noise_mm if world_noise_mm > 0 else 1.0
    grade, limited_by = POOR, tuple[str, ...]()
    for name, limits in GRADES[::-1]:  # from the lowest grade up: stop at the first one not met
        missing = _shortfalls(cameras, noise, world_ratio, limits)
        if name == GRADES[0][0]:  # a systematic error the residuals do not show is never excellent
            missing += list(result.systematic)
        if missing:
            limited_by = tuple(missing)
            break
        grade, limited_by = name, ()
    return Verdict(grade, cameras, noise, result.wand_length_rms_mm, world_noise_mm, limited_by)
