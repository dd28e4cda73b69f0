"""Kalibr camchain YAML (``camchain.yaml``).

Per camera ``camN``: ``camera_model: pinhole`` with ``distortion_model: equidistant`` (Kalibr's name
for OpenCV's fisheye model: the same four coefficients) or, for a plumb_bob camera, ``radtan`` (k1, k2,
p1, p2: Kalibr's model has no k3, so a camera whose k3 is not 0 is refused by name, as is a
rational_polynomial one), ``intrinsics: [fu, fv, pu, pv]``,
``distortion_coeffs``, ``resolution``, ``rostopic`` (``/<camera>/image_raw``), ``cam_overlaps``
(every other camera index) and, from the second camera on, ``T_cn_cnm1``: the 4x4 transform taking
points from the previous camera's frame into this one's, in metres (Kalibr's unit).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import yaml

from wand_calib_ros.core.model.camera_model import EQUIDISTANT, PLUMB_BOB, OpenCVCamera, to_opencv
from wand_calib_ros.io.errors import ExportError
from wand_calib_ros.io.export.cameras import ExportedCamera

FILE = "camchain.yaml"


def documents(cameras: Sequence[ExportedCamera]) -> dict[str, str]:
    """The one ``camchain.yaml`` (see the module docstring)."""
    chain: dict[str, Any] = {}
    for index, camera in enumerate(cameras):
        opencv = to_opencv(camera.model)
        k = opencv.camera_matrix
        distortion_model, coefficients = _kalibr_distortion(camera.name, opencv)
        entry: dict[str, Any] = {
            "camera_model": "pinhole",
            "intrinsics": [float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2])],
            "distortion_model": distortion_model,
            "distortion_coeffs": coefficients,
            "resolution": [int(camera.model.image_size[0]), int(camera.model.image_size[1])],
            "rostopic": f"/{camera.name}/image_raw",
            "cam_overlaps": [i for i in range(len(cameras)) if i != index],
        }
        if index > 0:
            entry["T_cn_cnm1"] = relative_transform(cameras[index - 1], camera).tolist()
        chain[f"cam{index}"] = entry
    return {FILE: yaml.safe_dump(chain, sort_keys=False, default_flow_style=None, width=120)}


def _kalibr_distortion(name: str, opencv: OpenCVCamera) -> tuple[str, list[float]]:
    """Kalibr's distortion model name and coefficients of a camera (ExportError where it has none)."""
    d = [float(v) for v in opencv.distortion]
    if opencv.distortion_model == EQUIDISTANT:
        return "equidistant", d
    if opencv.distortion_model == PLUMB_BOB and d[4] == 0.0:
        return "radtan", d[:4]
    what = f"its k3 is {d[4]:.3g}" if opencv.distortion_model == PLUMB_BOB else "it is rational_polynomial"
    raise ExportError(
        f"camera {name}: Kalibr's radtan model has k1, k2, p1, p2 only and {what}: export it as opencv, anipose "
        "or camera_info instead"
    )


def relative_transform(previous: ExportedCamera, camera: ExportedCamera) -> np.ndarray:
    """(4, 4) X_camera = T X_previous, translation in metres."""
    rotation = camera.pose.rotation @ previous.pose.rotation.T
    translation = camera.pose.translation - rotation @ previous.pose.translation
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = translation / 1000.0
    return transform
