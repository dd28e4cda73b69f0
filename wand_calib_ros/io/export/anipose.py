"""aniposelib ``calibration.toml`` (also read by anipose, caliscope and freemocap).

One table per camera, ``[cam_NN]`` (zero-padded: aniposelib loads the tables in sorted key order),
with ``name``, ``size`` [width, height], ``matrix`` (K), ``distortions`` (cv2.fisheye k1..k4),
``rotation`` (Rodrigues vector, rad), ``translation`` (mm) and ``fisheye = true``, so that
aniposelib's FisheyeCamera projects with ``cv2.fisheye.projectPoints(X, rotation, translation,
matrix, distortions)``; a plumb_bob or rational_polynomial camera has ``fisheye = false`` and
OpenCV's 5 or 8 ``distortions`` (k1, k2, p1, p2, k3[, k4, k5, k6]), which aniposelib's Camera projects
with ``cv2.projectPoints``; then ``[metadata]`` (``adjusted``, ``units``, ``reference_camera``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from wand_calib_ros.core.model.camera_model import EQUIDISTANT, to_opencv
from wand_calib_ros.io.export.cameras import ExportedCamera

FILE = "calibration.toml"


def documents(cameras: Sequence[ExportedCamera]) -> dict[str, str]:
    """The one ``calibration.toml`` (see the module docstring)."""
    width = max(2, len(str(len(cameras) - 1)))
    lines: list[str] = []
    for index, camera in enumerate(cameras):
        opencv = to_opencv(camera.model)
        lines += [
            f"[cam_{index:0{width}d}]",
            f'name = "{_escape(camera.name)}"',
            f"size = [{int(camera.model.image_size[0])}, {int(camera.model.image_size[1])}]",
            f"matrix = [{', '.join(_array(row) for row in opencv.camera_matrix)}]",
            f"distortions = {_array(opencv.distortion)}",
            f"rotation = {_array(camera.pose.rotvec)}",
            f"translation = {_array(camera.pose.translation)}",
            f"fisheye = {'true' if opencv.distortion_model == EQUIDISTANT else 'false'}",
            "",
        ]
    lines += [
        "[metadata]",
        "adjusted = false",
        'units = "mm"',
        f'reference_camera = "{_escape(cameras[0].name)}"',
        'calibrated_by = "wand_calib_ros"',
        "",
    ]
    return {FILE: "\n".join(lines)}


def _array(values: Iterable[float]) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def _escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')
