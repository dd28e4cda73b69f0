"""Typed records of a finished calibration."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.brightness import class_text
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.rig import WandSpec

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class WorldFrame:
    """The world frame a floor fit defines.

    Attributes:
        world_from_reference: X_world = R X_ref + T (mm).
        residual_mm: RMS distance of the floor points from the fitted plane, mm.
        normal_std_deg: standard deviation of the floor normal's direction, degrees (from the residual).
        origin_std_mm: standard deviation of the origin, mm: a point's noise (the residual, triangulation
            noise being largest along the cameras' depth, near the normal) and the plane's offset.
        placements: floor placements used.
    """

    world_from_reference: Pose
    residual_mm: float
    normal_std_deg: float
    origin_std_mm: float
    placements: int

    def camera_in_world(self, camera: Pose) -> Pose:
        """A camera's pose X_cam = R X_world + T from its pose relative to the reference camera."""
        return camera.compose(self.world_from_reference.inverse())


@dataclass(frozen=True)
class ClassBias:
    """Where the centres of one brightness class sit in a camera relative to those of spots below full scale, as
    the adjustment estimated (and corrected) them (:mod:`~wand_calib_ros.core.model.brightness`).

    Attributes:
        klass: the brightness class (1: 1-2x full scale, ... :data:`~wand_calib_ros.core.model.brightness.BIAS_EDGES`).
        offset_px: (u, v) its constant offset, px (OpenCV image axes: u right, v down).
        radial_px: its offset away from the principal point, px (negative: towards it).
        std_px: (u, v, radial) their standard deviations, px.
        points: the camera's points of that class in the adjustment.
        shape: the shape of the camera's bias these come from ("classes", "linear" or "constant",
            :mod:`~wand_calib_ros.core.model.brightness`).
    """

    klass: int
    offset_px: tuple[float, float]
    radial_px: float
    std_px: tuple[float, float, float]
    points: int
    shape: str = "classes"

    def line(self, camera: str) -> str:
        """The statement: ``cam1: centres of LEDs 4-8x full scale sit 0.50 px right, 0.02 px down and 0.01 px
        further out than those below full scale (+-0.03 px; 612 points): corrected``."""
        u, v = self.offset_px
        parts = [
            f"{abs(u):.2f} px {'right' if u >= 0 else 'left'}",
            f"{abs(v):.2f} px {'down' if v >= 0 else 'up'}",
            f"{abs(self.radial_px):.2f} px {'further out' if self.radial_px >= 0 else 'further in'}",
        ]
        return (
            f"{camera}: centres of LEDs {class_text(self.klass)} sit {', '.join(parts[:2])} and {parts[2]} than those "
            f"below full scale (+-{max(self.std_px):.2f} px; {self.points} points; a {self.shape} bias): corrected"
        )


@dataclass(frozen=True, eq=False)
class CameraCalibration:
    """One calibrated camera.

    Attributes:
        name: camera name.
        model: intrinsics (m fixed from the pixel size).
        pose: X_cam = R X_ref + T (mm), reference = the result's reference camera.
        rms_reprojection_px: per-coordinate RMS of its reprojection residuals, px.
        n_observations: wand points it contributed to the bundle adjustment.
        parameter_std: standard deviation of every estimated parameter
            (k1..k5 mm, u0 v0 px, rx ry rz rad as a small rotation, tx ty tz mm);
            fixed parameters are absent.
        max_observed_theta_deg: largest off-axis angle among its observations.
        initial_projection: the classic projection its Step 1 start came from.
        fixed_coefficients: radial coefficients held at zero (e.g. ("k5",)).
        n_views: placements it contributed to the bundle adjustment.
        rejected_views: its views (of used placements) rejected as outliers.
        radial_covariance: (5, 5) covariance of k1..k5 (mm^2; zero rows for fixed coefficients).
        time_offset: exposure = stamp - time_offset, relative to the reference camera, in the
            result's time unit (:class:`TimingSummary`); 0 when held fixed.
        readout: rolling-shutter readout time of the whole image in the time unit (0: global shutter).
        intrinsics: "estimated", "given" (the rig description's, held fixed) or "given_start" (the
            rig description's, refined).
        centre_bias: the brightness classes whose centres the adjustment found biased, and corrected (empty:
            none, or brightness not known).
    """

    name: str
    model: CameraModel
    pose: Pose
    rms_reprojection_px: float
    n_observations: int
    parameter_std: dict[str, float]
    max_observed_theta_deg: float
    initial_projection: str
    fixed_coefficients: tuple[str, ...]
    n_views: int
    rejected_views: int
    radial_covariance: FloatArray
    time_offset: float = 0.0
    readout: float = 0.0
    intrinsics: str = "estimated"
    centre_bias: tuple[ClassBias, ...] = ()


@dataclass(frozen=True)
class LensTrial:
    """One Step 1 candidate combination and how well Steps 2-3 fitted it."""

    projections: tuple[str, ...]
    wand_rms_mm: float
    failure: str | None = None


#: How time offsets and readout times are treated: decided by the data, always estimated, or held fixed.
TIMING_MODES = ("auto", "estimate", "fixed")


@dataclass(frozen=True)
class TimingSummary:
    """How the calibration treated when each camera saw the wand.

    Attributes:
        unit: "s" (the observations carried stamps) or "frames" (frame ids only).
        time_offsets: "estimated" or "fixed" (held at zero: synchronised cameras).
        rolling_shutter: per camera name "estimated" or "fixed" (at zero or the rig description's readout_ms).
        frame_period: the recording's frame period in the unit (1 for frames).
        notes: why something was not estimated, in plain words.
        clocks: the cameras whose clocks disagreed by more than a frame or two, as the wand's motion lined them up
            (their ``time_offset`` holds the whole offset), in plain words.
    """

    unit: str
    time_offsets: str
    rolling_shutter: dict[str, str]
    frame_period: float
    notes: tuple[str, ...] = ()
    clocks: tuple[str, ...] = ()


@dataclass(frozen=True)
class ClockOffset:
    """Estimated timing error of one camera relative to the others.

    Attributes:
        camera: camera name.
        offset_frames: dt in frames (positive: the camera sees the wand late).
        correlation: |correlation| between residuals and image velocity (1 = pure timing error).
        rms_px: RMS of the leave-one-out residuals (per coordinate), px.
        rms_corrected_px: the same after removing dt * velocity.
        points: points used (frames with both neighbours present).
    """

    camera: str
    offset_frames: float
    correlation: float
    rms_px: float
    rms_corrected_px: float
    points: int


@dataclass(frozen=True)
class CameraQuality:
    """One camera's figures.

    Attributes:
        name: the camera.
        image_error_px: per-coordinate reprojection RMS over its used views, px.
        noise_ratio: ``image_error_px`` over the estimated pixel noise.
        focal_std_percent: standard deviation of its focal length, % (0: given, not estimated).
        principal_std_px: standard deviation of its principal point (hypot of u0's and v0's), px (0: given).
    """

    name: str
    image_error_px: float
    noise_ratio: float
    focal_std_percent: float
    principal_std_px: float


@dataclass(frozen=True)
class Verdict:
    """A calibration judged.

    Attributes:
        grade: "excellent", "good", "acceptable" or "poor".
        cameras: each camera's figures.
        noise_px: the pixel noise the bundle adjustment estimated (per coordinate), px.
        world_error_mm: the wand-length RMS, mm.
        world_noise_mm: the wand-length RMS the pixel noise alone causes, mm (NaN: not computed).
        limited_by: what keeps the grade from the next better one, in plain words (empty: excellent).
    """

    grade: str
    cameras: tuple[CameraQuality, ...]
    noise_px: float
    world_error_mm: float
    world_noise_mm: float
    limited_by: tuple[str, ...]

    def line(self) -> str:
        """One line: the grade, the world error and the worst image error, and what limits the grade."""
        worst = max(self.cameras, key=lambda c: c.noise_ratio)
        text = (
            f"quality {self.grade}: world error {self.world_error_mm:.2f} mm (the noise's {self.world_noise_mm:.2f}), "
            f"image error up to {worst.image_error_px:.2f} px ({worst.name}; noise {self.noise_px:.2f} px)"
        )
        return text + (f"; limited by {'; '.join(self.limited_by)}" if self.limited_by else "")


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """A complete calibration.

    Attributes:
        reference_camera: name of the camera whose frame is the reference.
        cameras: calibrated cameras (the reference first).
        wand: wand lengths used.
        wand_length_rms_mm: RMS of L - |A^r C^r| over the used placements,
            each placement triangulated linearly with the final calibration.
        wand_length_mean_mm: mean reconstructed |AC| over the used placements.
        wand_length_std_mm: its standard deviation.
        sigma_px: pixel noise estimated from the bundle adjustment residuals.
        dof: (m, p) residual scalars and free parameters of the bundle adjustment.
        placements_used: placements in the bundle adjustment.
        placements_rejected: placements dropped by the |AC| gate before it.
        iterations: bundle adjustment iterations.
        lens_trials: Step 1 candidates tried and their Step 3 wand-length RMS.
        warnings: plain-language remarks on weakly determined parameters.
        clock_offsets: per camera timing diagnostics (empty when frames are not a time series or the
            offsets were estimated).
        timing: how the cameras' timing was treated (None: not modelled, as for simultaneous views).
        world: the world frame of a floor fit (None: no floor given; poses stay relative to the
            reference camera).
        quality: the verdict in plain words (:mod:`wand_calib_ros.core.judge.quality`; None: not judged).
        camera_covariance: (C*N, C*N) covariance of the camera parameters of the final adjustment, cameras
            in the rig's order, N (N_CAMERA_PARAMS) per camera in the bundle adjustment's order
            (CAMERA_PARAM_NAMES: k1..k5 mm, u0, v0 px, a left rotation vector rad, the translation mm, timing,
            t1, t2, d1..d3, the centre bias px); zero rows for fixed parameters (None: not kept, e.g. a result
            read from a file).
        systematic: systematic errors the residuals do not show, in plain words (the centres of saturated LEDs
            pulling a camera's focal length, :mod:`~wand_calib_ros.core.judge.centre_bias`): they keep the grade
            from "excellent".
    """

    reference_camera: str
    cameras: tuple[CameraCalibration, ...]
    wand: WandSpec
    wand_length_rms_mm: float
    wand_length_mean_mm: float
    wand_length_std_mm: float
    sigma_px: float
    dof: tuple[int, int]
    placements_used: int
    placements_rejected: int
    iterations: int
    lens_trials: tuple[LensTrial, ...]
    warnings: tuple[str, ...]
    clock_offsets: tuple[ClockOffset, ...] = ()
    timing: TimingSummary | None = None
    world: WorldFrame | None = None
    quality: Verdict | None = None
    camera_covariance: FloatArray | None = None
    systematic: tuple[str, ...] = ()

    def camera(self, name: str) -> CameraCalibration:
        for camera in self.cameras:
            if camera.name == name:
                return camera
        raise KeyError(name)
