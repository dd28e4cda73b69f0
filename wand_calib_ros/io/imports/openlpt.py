"""pyOpenLPT's wand points (its wand calibration's detections, a CSV).

A header ``frame,cam_id,pt_idx,x,y,radius,status`` and a row per detected ball: the frame, the camera id
(0, 1, ...), the ball (``pt_idx`` 0 or 1 of its two-ball wand), its centre in pixels (OpenCV's top-left
origin), its radius (not read) and ``status``: ``Raw`` for a detection, ``Filtered_Small`` /
``Filtered_Large`` for one its filter set aside (not imported, counted). Camera ids in ascending order are
the rig's cameras in order, ``pt_idx`` 0 and 1 its wand's two markers.
"""

from __future__ import annotations

from pathlib import Path

from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.io.imports.point_table import PointColumns, PointTable, read_point_table

COLUMNS = PointColumns(frame=("frame",), camera=("cam_id",), point=("pt_idx",), x=("x",), y=("y",))


def read_openlpt_points(path: str | Path, rig: RigSpec) -> PointTable:
    """The observations of a pyOpenLPT wand points CSV, the rows its filter set aside left out.

    Raises:
        FormatError: naming the file, the row or column and the problem.
    """
    return read_point_table(Path(path), rig, COLUMNS, keep=lambda row: not row.get("status", "").startswith("Filtered"))
