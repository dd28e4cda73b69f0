"""A checkerboard baseline like the paper's comparison (Bouguet / Kannala, Tables 1-4).

A 7 x 10 board (inner corners) is shown to the same simulated cameras, its
corners projected with the true models and the same pixel noise, and the
cameras are calibrated with OpenCV's fisheye model (the equidistant model of
this package, so the comparison is about the data, not the model):
``cv2.fisheye.calibrate`` per camera, then ``cv2.fisheye.stereoCalibrate``
from the reference camera to each other camera with the intrinsics fixed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from wand_calib_ros.core.errors import CalibrationFailedError
from wand_calib_ros.core.model.camera_model import CameraModel, from_opencv_fisheye, project
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.rig import CameraSpec
from wand_calib_ros.sim.scenarios import Scenario, visible

FloatArray = NDArray[np.float64]

#: Inner corners of the board (the paper's 7 x 10 board).
BOARD_CORNERS = (7, 10)


@dataclass(frozen=True, eq=False)
class BoardViews:
    """Checkerboard views seen completely by some cameras.

    Attributes:
        object_points: (70, 3) corners in the board frame, mm.
        image_points: (V, K, 70, 2) noisy pixels per view and camera (K cameras asked for).
    """

    object_points: FloatArray
    image_points: FloatArray


def board_points(square_mm: float) -> FloatArray:
    """(70, 3) inner corners of the 7 x 10 board, z = 0, mm."""
    rows, cols = BOARD_CORNERS
    grid = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2)
    return np.column_stack([grid * square_mm, np.zeros(rows * cols)])


def board_square_mm(scenario: Scenario) -> float:
    """A board that fits the scenario: the wand's length over 8 per square (the board spans ~L)."""
    return scenario.wand.L / 8.0


def _sample(
    scenario: Scenario,
    cameras: tuple[int, ...],
    n_views: int,
    noise_px: float,
    rng: np.random.Generator,
    centre_and_target: object,
) -> BoardViews:
    corners = board_points(board_square_mm(scenario))
    middle = corners.mean(axis=0)
    for _ in range(400):
        views = []
        for _ in range(200 * n_views):
            centre, target = centre_and_target()  # type: ignore[operator]
            normal = (target - centre) / np.linalg.norm(target - centre)
            base = Rotation.align_vectors([normal], [[0.0, 0.0, 1.0]])[0]
            tilt = Rotation.from_rotvec(np.append(rng.normal(scale=np.radians(20.0), size=2), 0.0))
            spin = Rotation.from_rotvec([0.0, 0.0, rng.uniform(-np.pi, np.pi)])
            points = (base * tilt * spin).apply(corners - middle) + centre
            chosen = [scenario.cameras[c] for c in cameras]
            if all(visible(camera, points).all() for camera in chosen):
                pixels = np.stack([project(c.model, c.pose.apply(points)) for c in chosen])
                views.append(pixels + rng.normal(scale=noise_px, size=pixels.shape))
            if len(views) == n_views:
                return BoardViews(corners, np.array(views))
        break
    names = ", ".join(scenario.cameras[c].spec.name for c in cameras)
    raise CalibrationFailedError(f"scenario {scenario.name}: {names} rarely see a whole board together")


def intrinsic_views(
    scenario: Scenario, camera: int, n_views: int, noise_px: float, rng: np.random.Generator
) -> BoardViews:
    """Views of the board held close to one camera so it fills a good part of the image."""
    true = scenario.cameras[camera]
    width_mm = board_square_mm(scenario) * (BOARD_CORNERS[1] - 1)
    focal_px = true.spec.nominal_focal_mm * float(true.spec.m[0])
    distance = focal_px * width_mm / (0.5 * true.spec.image_size[0])
    rotation_t = true.pose.rotation.T  # camera axes in the reference frame (columns)

    def place() -> tuple[FloatArray, FloatArray]:
        offset = rng.uniform(-0.6, 0.6, size=2) * distance * true.spec.image_size[0] / (2 * focal_px)
        local = np.array([offset[0], offset[1] * 0.75, distance * rng.uniform(0.8, 1.3)])
        return true.pose.center + rotation_t @ local, true.pose.center

    return _sample(scenario, (camera,), n_views, noise_px, rng, place)


def stereo_views(
    scenario: Scenario, cameras: tuple[int, int], n_views: int, noise_px: float, rng: np.random.Generator
) -> BoardViews:
    """Views of the board in the wand's volume that both cameras see whole, facing between them."""
    target = np.mean([scenario.cameras[c].pose.center for c in cameras], axis=0)

    def place() -> tuple[FloatArray, FloatArray]:
        return rng.uniform(scenario.volume[0], scenario.volume[1]), target

    return _sample(scenario, cameras, n_views, noise_px, rng, place)


@dataclass(frozen=True, eq=False)
class BaselineResult:
    """Checkerboard calibration of every camera, poses relative to camera 0."""

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    rms_px: tuple[float, ...]


def _fisheye_calibrate(
    true_spec: CameraSpec, views: BoardViews, criteria: tuple[int, int, float]
) -> tuple[FloatArray, FloatArray, float]:
    objects = [views.object_points[None, :, :].astype(np.float64)] * views.image_points.shape[0]
    images = [v[0][None, :, :].astype(np.float64) for v in views.image_points]
    guess = np.array(
        [
            [true_spec.nominal_focal_mm * true_spec.m[0], 0, true_spec.image_center[0]],
            [0, true_spec.nominal_focal_mm * true_spec.m[1], true_spec.image_center[1]],
            [0, 0, 1.0],
        ]
    )
    flags = cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW | cv2.fisheye.CALIB_USE_INTRINSIC_GUESS
    try:
        error, k, d, _, _ = cv2.fisheye.calibrate(
            objects, images, true_spec.image_size, guess, np.zeros(4), flags=flags, criteria=criteria
        )
    except cv2.error as failure:
        raise CalibrationFailedError(f"OpenCV fisheye calibration of {true_spec.name} failed: {failure}") from None
    return (
        np.asarray(k, dtype=float),
        np.asarray(d, dtype=float),
        float(error) / np.sqrt(2.0),
    )  # OpenCV's RMS is 2D; report per coordinate


def calibrate_checkerboard(
    scenario: Scenario, noise_px: float, rng: np.random.Generator, *, intrinsic: int = 15, stereo: int = 15
) -> BaselineResult:
    """Checkerboard calibration of the scenario's cameras with OpenCV's fisheye model.

    Each camera gets ``intrinsic`` views of the board held close to it
    (cv2.fisheye.calibrate); each other camera is then placed relative to camera 0
    from ``stereo`` views both see in the wand's volume (cv2.fisheye.stereoCalibrate
    with the intrinsics fixed).

    Raises:
        CalibrationFailedError: OpenCV could not calibrate, or the cameras share no board view.
    """
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    intrinsics, models, rms = [], [], []
    for c, camera in enumerate(scenario.cameras):
        k, d, error = _fisheye_calibrate(camera.spec, intrinsic_views(scenario, c, intrinsic, noise_px, rng), criteria)
        intrinsics.append((k, d))
        models.append(from_opencv_fisheye(k, d.ravel(), camera.spec.m, camera.spec.image_size))
        rms.append(error)
    poses = [Pose.identity()]
    for c in range(1, len(scenario.cameras)):
        views = stereo_views(scenario, (0, c), stereo, noise_px, rng)
        objects = [views.object_points[None, :, :].astype(np.float64)] * views.image_points.shape[0]
        first = [v[0][None, :, :].astype(np.float64) for v in views.image_points]
        second = [v[1][None, :, :].astype(np.float64) for v in views.image_points]
        try:
            result = cv2.fisheye.stereoCalibrate(
                objects,
                first,
                second,
                intrinsics[0][0],
                intrinsics[0][1],
                intrinsics[c][0],
                intrinsics[c][1],
                scenario.cameras[0].spec.image_size,
                flags=cv2.fisheye.CALIB_FIX_INTRINSIC,
                criteria=criteria,
            )
        except cv2.error as failure:
            raise CalibrationFailedError(f"OpenCV stereo calibration cam0-{c} failed: {failure}") from None
        poses.append(Pose(np.asarray(result[5], dtype=float), np.asarray(result[6], dtype=float).ravel()))
    return BaselineResult(tuple(models), tuple(poses), tuple(rms))
