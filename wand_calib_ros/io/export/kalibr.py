"""Kalibr camchain YAML (``camchain.yaml``).

Per camera ``camN``: ``camera_model: pinhole`` with ``distortion_model: equidistant`` (Kalibr's name
for OpenCV's fisheye model: the same four coefficients), ``intrinsics: [fu, fv, pu, pv]``,
``distortion_coeffs``, ``resolution``, ``rostopic`` (``/<camera>/image_raw``), ``cam_overlaps``
(every other camera index) and, from the second camera on, ``T_cn_cnm1``: the 4x4 transform taking
points from the previous camera's frame into this one's, in metres (Kalibr's unit).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import yaml

from wand_calib_ros.core.camera_model import to_opencv_fisheye
from wand_calib_ros.io.export import ExportedCamera

FILE = "camchain.yaml"


def documents(cameras: Sequence[ExportedCamera]) -> dict[str, str]:
    """The one ``camchain.yaml`` (see the module docstring)."""
    chain: dict[str, Any] = {}
    for index, camera in enumerate(cameras):
        opencv = to_opencv_fisheye(camera.model)
        k = opencv.camera_matrix
        entry: dict[str, Any] = {
            "camera_model": "pinhole",
            "intrinsics": [float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2])],
            "distortion_model": "equidistant",
            "distortion_coeffs": [float(d) for d in opencv.distortion],
            "resolution": [int(camera.model.image_size[0]), int(camera.model.image_size[1])],
            "rostopic": f"/{camera.name}/image_raw",
            "cam_overlaps": [i for i in range(len(cameras)) if i != index],
        }
        if index > 0:
            entry["T_cn_cnm1"] = relative_transform(cameras[index - 1], camera).tolist()
        chain[f"cam{index}"] = entry
    return {FILE: yaml.safe_dump(chain, sort_keys=False, default_flow_style=None, width=120)}


def relative_transform(previous: ExportedCamera, camera: ExportedCamera) -> np.ndarray:
    """(4, 4) X_camera = T X_previous, translation in metres."""
    rotation = camera.pose.rotation @ previous.pose.rotation.T
    translation = camera.pose.translation - rotation @ previous.pose.translation
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = translation / 1000.0
    return transform
