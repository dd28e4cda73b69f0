"""pyOpenLPT's wand points (its wand calibration's detections, a CSV).

Its ``WandCalibrator.export_wand_data`` writes ``Frame,Camera,Status,PointIdx,X,Y,Radius,Metric``: a ``Raw``
row for every circle its detector found (``PointIdx`` counts them), then the pairs its filter validated and
its calibration uses, ``Filtered_Small`` (``PointIdx`` 0, the small ball) and ``Filtered_Large`` (1, the large
one). The filtered rows are imported (the small ball is the wand's first marker), the raw ones left out and
counted; a camera's view with one filtered ball is left out and counted. Older files (pyOpenLPT's README) have
``frame,cam_id,pt_idx,x,y,radius,status`` with ``Raw`` rows for the detections and ``Filtered_*`` rows for
those its filter set aside: there the raw rows are imported. Pixels are OpenCV's (top left, 0-based). Camera
ids in ascending order are the rig's cameras in order.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.point_table import PointColumns, PointTable, read_point_table
from wand_calib_ros.io.text import read_text

#: The columns of ``export_wand_data``.
COLUMNS = PointColumns(frame=("Frame",), camera=("Camera",), point=("PointIdx",), x=("X",), y=("Y",))
#: The columns of the older files.
OLD_COLUMNS = PointColumns(frame=("frame",), camera=("cam_id",), point=("pt_idx",), x=("x",), y=("y",))


def read_openlpt_points(path: str | Path, rig: RigSpec) -> PointTable:
    """The observations of a pyOpenLPT wand points CSV: the rows its calibration uses.

    Raises:
        FormatError: naming the file, the row or column and the problem.
    """
    path = Path(path)
    first = next((line for line in read_text(path, "a point table").splitlines() if line.strip()), "")
    if "Status" not in [name.strip() for name in first.split(",")]:
        return read_point_table(
            path, rig, OLD_COLUMNS, keep=lambda row: not row.get("status", "").startswith("Filtered")
        )
    table = read_point_table(path, rig, COLUMNS, keep=lambda row: row["Status"].strip().startswith("Filtered"))
    uv = np.array(table.observations.uv)
    seen = np.isfinite(uv[..., 0])
    alone = seen.sum(axis=2) == 1
    uv[alone] = np.nan
    kept = np.any(np.isfinite(uv), axis=(1, 2, 3))
    if not kept.any():
        raise FormatError(path, "no camera view with both of the wand's balls (Filtered_Small and Filtered_Large)")
    observations = replace(table.observations, frames=table.observations.frames[kept], uv=uv[kept])
    return replace(table, observations=observations, one_marker_views=int(alone.sum()))
