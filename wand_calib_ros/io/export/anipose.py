"""aniposelib ``calibration.toml`` (also read by anipose, caliscope and freemocap).

One table per camera, ``[cam_NN]`` (zero-padded: aniposelib loads the tables in sorted key order),
with ``name``, ``size`` [width, height], ``matrix`` (K), ``distortions`` (cv2.fisheye k1..k4),
``rotation`` (Rodrigues vector, rad), ``translation`` (mm) and ``fisheye = true``, so that
aniposelib's FisheyeCamera projects with ``cv2.fisheye.projectPoints(X, rotation, translation,
matrix, distortions)``; then ``[metadata]`` (``adjusted``, ``units``, ``reference_camera``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from wand_calib_ros.core.camera_model import to_opencv_fisheye
from wand_calib_ros.io.export import ExportedCamera

FILE = "calibration.toml"


def documents(cameras: Sequence[ExportedCamera]) -> dict[str, str]:
    """The one ``calibration.toml`` (see the module docstring)."""
    width = max(2, len(str(len(cameras) - 1)))
    lines: list[str] = []
    for index, camera in enumerate(cameras):
        opencv = to_opencv_fisheye(camera.model)
        lines += [
            f"[cam_{index:0{width}d}]",
            f'name = "{_escape(camera.name)}"',
            f"size = [{int(camera.model.image_size[0])}, {int(camera.model.image_size[1])}]",
            f"matrix = [{', '.join(_array(row) for row in opencv.camera_matrix)}]",
            f"distortions = {_array(opencv.distortion)}",
            f"rotation = {_array(camera.pose.rotvec)}",
            f"translation = {_array(camera.pose.translation)}",
            "fisheye = true",
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
