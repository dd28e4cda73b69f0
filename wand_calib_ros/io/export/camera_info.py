"""ROS camera_info YAML per camera (``<camera>.yaml``, ``distortion_model`` the camera's own model), as the
camera_calibration package writes it and camera drivers load it."""

from __future__ import annotations

from collections.abc import Sequence

from wand_calib_ros.io.export.cameras import ExportedCamera
from wand_calib_ros.io.result_yaml import camera_info_dict, yaml_text


def documents(cameras: Sequence[ExportedCamera]) -> dict[str, str]:
    """``<camera>.yaml`` per camera."""
    return {f"{c.name}.yaml": yaml_text(camera_info_dict(c.name, c.model)) for c in cameras}
