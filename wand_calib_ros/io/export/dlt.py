"""DLT coefficients for easyWand, Argus and DLTdv (``dlt_coefficients.csv``), pinhole cameras only.

The 11 coefficients L1..L11 of each camera map a point X (mm; the world frame of a calibration with a
floor, see :data:`wand_calib_ros.io.export.WORLD_FORMATS`) to
u = (L1 X + L2 Y + L3 Z + L4) / (L9 X + L10 Y + L11 Z + 1) and v likewise with L5..L8, in those
tools' pixel convention: origin at the image's bottom left, v up (v_dlt = height - v_opencv, as
Argus converts DeepLabCut's top-left points). The file has one column per camera (the reference
first) and 11 rows, no header, as Argus writes ``*-dlt-coefficients.csv``.

A DLT camera has no lens distortion: a camera is exported only when its model stays within
:data:`MAX_PINHOLE_ERROR_PX` of the best distortion-free pinhole over its whole image; a fisheye
(or a strongly distorting lens) is refused with the deviation, naming the camera.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.camera_model import CameraModel, angle_of_radius, unproject
from wand_calib_ros.io.errors import ExportError
from wand_calib_ros.io.export.cameras import ExportedCamera

FILE = "dlt_coefficients.csv"
#: Largest image distance (px) between a camera and the pinhole its DLT coefficients describe.
MAX_PINHOLE_ERROR_PX = 0.5

FloatArray = NDArray[np.float64]


def _image_grid(model: CameraModel, n: int = 25) -> FloatArray:
    """(n*n, 2) pixels spread over the whole image (OpenCV convention)."""
    width, height = model.image_size
    u, v = np.meshgrid(np.linspace(-0.5, width - 0.5, n), np.linspace(-0.5, height - 0.5, n))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def pinhole_focal(model: CameraModel) -> tuple[FloatArray, float]:
    """The distortion-free pinhole closest to ``model`` over its image: ((2,) fx, fy in px, the largest
    image distance in px between the two), or (NaN, inf) when the image reaches 90 deg off axis."""
    pixels = _image_grid(model)
    rays = unproject(model, pixels)
    if not np.all(rays[:, 2] > 1e-6):
        return np.full(2, np.nan), float("inf")
    plane = rays[:, :2] / rays[:, 2:]  # tan(theta) (cos phi, sin phi)
    offsets = pixels - model.principal_point
    # u - u0 = fx * x: one least-squares focal per axis over the image
    focal = np.array([np.dot(plane[:, i], offsets[:, i]) / np.dot(plane[:, i], plane[:, i]) for i in (0, 1)])
    error = float(np.max(np.linalg.norm(plane * focal + model.principal_point - pixels, axis=1)))
    return focal, error


def coefficients(camera: ExportedCamera) -> FloatArray:
    """(11,) DLT coefficients of one camera (bottom-left pixel origin).

    Raises:
        ExportError: the camera's lens is too far from a pinhole (see the module docstring).
    """
    model = camera.model
    focal, error = pinhole_focal(model)
    if not error <= MAX_PINHOLE_ERROR_PX:
        reach = float(np.degrees(angle_of_radius(model, np.array(0.5 * np.hypot(*model.image_size) / model.m[0]))))
        how = "reaches 90 deg off axis" if not np.isfinite(error) else f"differs from any pinhole by {error:.1f} px"
        raise ExportError(
            f"camera {camera.name}: DLT coefficients describe distortion-free pinhole cameras; its lens {how} "
            f"in the image (corner at {reach:.0f} deg; at most {MAX_PINHOLE_ERROR_PX} px): export it as opencv, "
            "anipose or kalibr instead"
        )
    height = model.image_size[1]
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, height], [0.0, 0.0, 1.0]])  # v_dlt = height - v
    K = np.array([[focal[0], 0.0, model.principal_point[0]], [0.0, focal[1], model.principal_point[1]], [0, 0, 1]])
    P = flip @ K @ np.hstack([camera.pose.rotation, camera.pose.translation[:, None]])
    if abs(P[2, 3]) < 1e-6 * max(1.0, float(np.linalg.norm(camera.pose.translation))):  # L12 = 1 impossible
        raise ExportError(
            f"camera {camera.name}: DLT coefficients cannot describe a camera whose focal plane holds the frame's "
            "origin (the reference camera of a calibration without a floor): calibrate with --floor to export "
            "in the world frame"
        )
    return (P.ravel() / P[2, 3])[:11]


def documents(cameras: Sequence[ExportedCamera]) -> dict[str, str]:
    """The one ``dlt_coefficients.csv`` (11 rows, a column per camera)."""
    table = np.stack([coefficients(camera) for camera in cameras], axis=1)
    return {FILE: "\n".join(",".join(f"{v:.17g}" for v in row) for row in table) + "\n"}
