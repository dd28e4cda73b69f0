"""caliscope's files: its camera array (``camera_array.toml``) as given intrinsics, and its point table.

``camera_array.toml`` has a ``[cameras.N]`` table per camera (N its ``cam_id``) with ``size``, ``matrix`` (K)
and ``distortions`` (OpenCV's k1, k2, p1, p2, k3; cv2.fisheye's k1..k4 where ``fisheye = true``); its
``rotation`` and ``translation`` are caliscope's own calibration of the poses and are not read.

The point table (``xy_*.csv``) has a row per image point: ``sync_index`` (the frame), ``cam_id`` (older
versions: ``port``), ``keypoint_id`` (older: ``point_id``), ``img_loc_x``, ``img_loc_y`` (pixels, OpenCV's
top-left origin), and further columns that are not read. Camera ids in ascending order are the rig's cameras
in order; keypoint ids in ascending order its wand's markers.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.anipose import opencv_camera
from wand_calib_ros.io.imports.given import GivenIntrinsics
from wand_calib_ros.io.imports.point_table import PointColumns, PointTable, read_point_table


def read_camera_array(path: Path, document: dict[str, Any]) -> list[GivenIntrinsics]:
    """The cameras of a ``camera_array.toml`` (already read: ``document``), by ``cam_id``.

    Raises:
        FormatError: naming the file, the table and the key at fault.
    """
    cameras = document["cameras"]
    if not isinstance(cameras, dict) or not cameras:
        raise FormatError(path, "[cameras] has no camera tables ([cameras.0], [cameras.1], ...)")
    out = []
    for key in sorted(cameras, key=lambda k: (len(k), k)):
        table = cameras[key]
        if not isinstance(table, dict):
            raise FormatError(path, f"cameras.{key} is not a table")
        if "matrix" not in table:
            raise FormatError(path, f"[cameras.{key}] has no matrix: caliscope has not calibrated its intrinsics")
        out.append(opencv_camera(path, f"cameras.{key}", table, f"cam_{table.get('cam_id', key)}"))
    return out


#: The point table's columns, the older names after the current ones.
COLUMNS = PointColumns(
    frame=("sync_index",),
    camera=("cam_id", "port"),
    point=("keypoint_id", "point_id"),
    x=("img_loc_x",),
    y=("img_loc_y",),
)


def read_caliscope_points(path: str | Path, rig: RigSpec) -> PointTable:
    """The observations of a caliscope point table.

    Raises:
        FormatError: naming the file, the row or column and the problem.
    """
    return read_point_table(Path(path), rig, COLUMNS)
