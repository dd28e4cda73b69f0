"""OpenCV FileStorage YAML per camera, as ``cv2.fisheye`` or ``cv2`` takes the parameters.

``<camera>.yaml`` holds ``image_width``, ``image_height``, ``camera_model`` (``fisheye``, or ``pinhole``
for the plumb_bob and rational_polynomial models, then also ``distortion_model`` with that name), ``K``
(3x3), ``D`` (4x1, k1..k4 of cv2.fisheye; 5x1 k1, k2, p1, p2, k3 or 8x1 for the pinhole models), ``R``
(3x3) and ``rvec`` (3x1 Rodrigues), ``T`` (3x1, mm) with X_cam = R X_ref + T, and ``reference_camera``:
``cv2.fisheye.projectPoints(X_ref, rvec, T, K, D)`` (``cv2.projectPoints`` for pinhole cameras) gives
this package's pixels. Written by cv2.FileStorage itself (so any OpenCV reads it).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from wand_calib_ros.core.model.camera_model import EQUIDISTANT, to_opencv
from wand_calib_ros.io.export.cameras import ExportedCamera


def documents(cameras: Sequence[ExportedCamera]) -> dict[str, str]:
    """``<camera>.yaml`` per camera (see the module docstring)."""
    out = {}
    for camera in cameras:
        opencv = to_opencv(camera.model)
        fisheye = opencv.distortion_model == EQUIDISTANT
        kind: list[tuple[str, np.ndarray | str | int]] = (
            [("camera_model", "fisheye")]
            if fisheye
            else [("camera_model", "pinhole"), ("distortion_model", opencv.distortion_model)]
        )
        fields: list[tuple[str, np.ndarray | str | int]] = [
            ("image_width", int(camera.model.image_size[0])),
            ("image_height", int(camera.model.image_size[1])),
            *kind,
            ("K", opencv.camera_matrix),
            ("D", opencv.distortion.reshape(-1, 1)),
            ("R", camera.pose.rotation),
            ("rvec", camera.pose.rotvec.reshape(3, 1)),
            ("T", camera.pose.translation.reshape(3, 1)),
            ("translation_unit", "mm"),
            ("reference_camera", cameras[0].name),
        ]
        out[f"{camera.name}.yaml"] = _file_storage_text(fields)
    return out


def _file_storage_text(fields: list[tuple[str, np.ndarray | str | int]]) -> str:
    """The YAML text cv2.FileStorage writes for ``fields``."""
    storage = cv2.FileStorage(".yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    for key, value in fields:
        if isinstance(value, np.ndarray):
            storage.write(key, np.asarray(value, dtype=np.float64))
        elif isinstance(value, str):
            storage.write(key, value)
        else:
            storage.write(key, int(value))
    return str(storage.releaseAndGetString())
