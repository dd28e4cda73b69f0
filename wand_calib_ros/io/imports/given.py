"""Intrinsics other tools calibrated, given to the rig: one record for every tool's file, matched to the rig's
cameras, and the rig file that holds them (the files are read by :mod:`~wand_calib_ros.io.imports.intrinsics`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.io.errors import FormatError


@dataclass(frozen=True)
class GivenIntrinsics:
    """One camera's intrinsics from another tool's file.

    Attributes:
        name: the camera's name there.
        image_size: (width, height) px.
        camera_matrix: 3x3 K (OpenCV pixel convention), rows.
        distortion: D in ``distortion_model``'s order.
        distortion_model: ``equidistant``, ``plumb_bob`` or ``rational_polynomial``.
        size_tolerance: how far (fraction) the file's image size may be from the rig's (0: exactly; a
            camera profile writes twice the principal point instead of the size; inf: the file does not write
            it, ``image_size`` is then twice the principal point).
    """

    name: str
    image_size: tuple[int, int]
    camera_matrix: tuple[tuple[float, float, float], ...]
    distortion: tuple[float, ...]
    distortion_model: str
    size_tolerance: float = 0.0


def matched(path: Path, rig: RigSpec, given: Sequence[GivenIntrinsics]) -> tuple[list[GivenIntrinsics], str]:
    """The file's cameras in the rig's order: by name where every rig camera has one, else in order.

    Returns:
        The cameras and how they were matched, in words.

    Raises:
        FormatError: neither matches, or a camera's image size is not the rig's.
    """
    by_name = {camera.name: camera for camera in given}
    if all(name in by_name for name in rig.camera_names):
        cameras, how = [by_name[name] for name in rig.camera_names], "by name"
    elif len(given) == len(rig.cameras):
        cameras, how = list(given), "in order (its names are not the rig's)"
    else:
        raise FormatError(
            path,
            f"its cameras {', '.join(by_name)} are neither the rig's ({', '.join(rig.camera_names)}) nor as many "
            f"({len(given)} against {len(rig.cameras)})",
        )
    for spec, camera in zip(rig.cameras, cameras, strict=True):
        off = max(abs(a - b) / b for a, b in zip(camera.image_size, spec.image_size, strict=True))
        if off > camera.size_tolerance:
            raise FormatError(
                path,
                f"camera '{camera.name}' is {camera.image_size[0]}x{camera.image_size[1]}, the rig's '{spec.name}' "
                f"{spec.image_size[0]}x{spec.image_size[1]}: intrinsics are for one image size",
            )
    return cameras, how


def with_given(document: dict[str, Any], cameras: Sequence[GivenIntrinsics], *, fixed: bool) -> dict[str, Any]:
    """The rig file's ``document`` (as read) with each camera's ``intrinsics`` entry set from ``cameras``
    (the rig's order), held fixed or as a start."""
    for item, camera in zip(document["cameras"], cameras, strict=True):
        item["intrinsics"] = {
            "K": [list(row) for row in camera.camera_matrix],
            "D": list(camera.distortion),
            "distortion_model": camera.distortion_model,
            "fixed": fixed,
        }
    return document
