"""The cameras of a result as every export format takes them."""

from __future__ import annotations

from dataclasses import dataclass

from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import CalibrationResult


@dataclass(frozen=True, eq=False)
class ExportedCamera:
    """One camera as the formats need it: name, intrinsics and pose (X_cam = R X_ref + T, mm)."""

    name: str
    model: CameraModel
    pose: Pose


def cameras_of(result: CalibrationResult, *, in_world: bool = False) -> list[ExportedCamera]:
    """A result's cameras, the reference first; poses in the world frame when ``in_world`` and the
    result has one (a floor was given), else relative to the reference camera."""
    order = sorted(result.cameras, key=lambda c: c.name != result.reference_camera)
    world = result.world if in_world else None
    return [ExportedCamera(c.name, c.model, c.pose if world is None else world.camera_in_world(c.pose)) for c in order]
