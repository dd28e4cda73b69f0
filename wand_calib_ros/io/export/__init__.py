"""A calibration in the formats of the tools users work with.

Each format module turns the cameras of a result (intrinsics in OpenCV's terms: its fisheye model,
which is ROS's ``equidistant``, or its pinhole model with radial-tangential distortion, ROS's
``plumb_bob`` and ``rational_polynomial``; poses X_cam = R X_ref + T in mm) into text documents;
:func:`export` writes them as one set. Every format keeps this package's projection exactly: a point
projected with the exported parameters by the other tool's own code (``cv2.fisheye.projectPoints`` or
``cv2.projectPoints`` for OpenCV, aniposelib, Kalibr's equidistant and radtan models) lands on the
pixel this package computes; a format that has no place for a camera's model refuses it by name.

Formats: ``opencv`` (a FileStorage YAML per camera), ``anipose`` (aniposelib / anipose / caliscope /
freemocap ``calibration.toml``), ``kalibr`` (camchain YAML), ``camera_info`` (ROS, per camera),
``dlt`` (easyWand / Argus / DLTdv coefficients; pinhole cameras only, fisheyes refused).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from wand_calib_ros.io.export.cameras import ExportedCamera
from wand_calib_ros.io.outputs import write_together

#: The format names :func:`export` takes.
FORMATS = ("opencv", "anipose", "kalibr", "camera_info", "dlt")
#: Formats written in the world frame when the result has one: DLT coefficients cannot describe a
#: camera that sits at the frame's origin (the reference camera does).
WORLD_FORMATS = ("dlt",)

#: A format: the cameras (reference first or in the result's order) -> {file name: text}.
Writer = Callable[[Sequence[ExportedCamera]], dict[str, str]]


def formats() -> dict[str, Writer]:
    """Every format by name (their modules imported here: a command that only names them stays light)."""
    from wand_calib_ros.io.export import anipose, camera_info, dlt, kalibr, opencv

    return {
        "opencv": opencv.documents,
        "anipose": anipose.documents,
        "kalibr": kalibr.documents,
        "camera_info": camera_info.documents,
        "dlt": dlt.documents,
    }


def export(cameras: Sequence[ExportedCamera], format_name: str, folder: Path) -> list[Path]:
    """Write the cameras in ``format_name`` into ``folder`` as one set; returns the paths written.

    Raises:
        KeyError: an unknown format (the CLI offers only known ones).
        ExportError: the format cannot express a camera (the message names it).
        OutputError: a file could not be written (none was replaced).
    """
    documents = formats()[format_name](cameras)
    paths = {Path(folder) / name: text for name, text in documents.items()}
    write_together(paths)
    return list(paths)
