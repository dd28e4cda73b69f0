"""easyWand / Argus / DLTdv point files (``*xypts.csv``): the wand's markers per frame and camera.

One header row names the columns ``pt<P>_cam<C>_x`` and ``pt<P>_cam<C>_y`` (P = marker, C = camera,
1-based; DLTdv writes ``X``/``Y``); every further row is one frame (frame id = row index from 0),
NaN (or an empty cell) where a camera did not see a marker. Pixels have the origin at the image's
bottom left with y up (Argus flips y from top-left tools as y = height - y; DLTdv likewise):
v = height - y in the OpenCV convention this package uses; ``origin="top-left"`` takes them as they
are. Camera C is the rig description's C-th camera.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.text import finite_number, read_text

_COLUMN = re.compile(r"^pt(\d+)_cam(\d+)_([xy])$", re.IGNORECASE)
#: Pixel origins the files may use.
ORIGINS = ("bottom-left", "top-left")


def read_xypts(path: str | Path, rig: RigSpec, *, origin: str = "bottom-left") -> WandObservations:
    """The observations of a point file, cameras and markers as the rig describes them.

    Raises:
        FormatError: naming the file, the row or column and the problem.
    """
    path = Path(path)
    if origin not in ORIGINS:
        raise ValueError(f"origin must be one of {ORIGINS}")
    text = read_text(path, "a point file")
    # a row of empty cells is a frame in which nothing was seen (it keeps the later frames' ids); only
    # blank lines are not rows
    rows = [row for row in csv.reader(text.splitlines()) if row]
    if not rows:
        raise FormatError(path, "empty file; expected a header pt1_cam1_x,pt1_cam1_y,...")
    columns = []
    for index, name in enumerate(rows[0]):
        found = _COLUMN.match(name.strip())
        if found is None:
            raise FormatError(path, f"column {index + 1} is {name!r}, not pt<P>_cam<C>_x or _y", row=1)
        if int(found[1]) == 0 or int(found[2]) == 0:
            raise FormatError(
                path,
                f"column {index + 1} is {name!r}: markers and cameras count from 1 (pt1_cam1_x is the first)",
                row=1,
            )
        columns.append((int(found[1]) - 1, int(found[2]) - 1, found[3].lower() == "y"))
    n_points = max(p for p, _, _ in columns) + 1
    n_cameras = max(c for _, c, _ in columns) + 1
    if n_cameras != len(rig.cameras):
        raise FormatError(
            path, f"{n_cameras} cameras in the file, {len(rig.cameras)} in the rig description (camera C = its C-th)"
        )
    if n_points != rig.wand.n_points:
        raise FormatError(path, f"{n_points} markers per frame, the rig's wand has {rig.wand.n_points}")
    if len(set(columns)) != len(columns) or len(columns) != 2 * n_points * n_cameras:
        raise FormatError(path, "every pt<P>_cam<C> needs one _x and one _y column", row=1)
    uv = np.full((len(rows) - 1, n_cameras, n_points, 2), np.nan)
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(columns):
            raise FormatError(path, f"{len(row)} cells where the header has {len(columns)}", row=number)
        for cell, (p, c, is_y) in zip(row, columns, strict=True):
            uv[number - 2, c, p, int(is_y)] = _value(path, number, cell)
    if origin == "bottom-left":
        uv = from_bottom_left(uv, rig)
    seen_partly = np.isfinite(uv[..., 0]) != np.isfinite(uv[..., 1])
    if seen_partly.any():
        f, c, p = (int(i[0]) for i in np.nonzero(seen_partly))
        raise FormatError(path, f"pt{p + 1}_cam{c + 1} has x or y only", row=f + 2)
    seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
    if not seen.any():
        raise FormatError(path, "no marker is seen in any frame")
    return WandObservations(np.flatnonzero(seen), rig.camera_names, uv[seen])


def from_bottom_left(uv: NDArray[np.float64], rig: RigSpec) -> NDArray[np.float64]:
    """(F, C, K, 2) pixels with the origin at the bottom left, y up, in OpenCV's convention: v = height - y
    (each camera's height, the rig's camera order)."""
    heights = np.array([spec.image_size[1] for spec in rig.cameras], dtype=np.float64)
    out = np.array(uv, dtype=np.float64)
    out[..., 1] = heights[None, :, None] - out[..., 1]
    return out


def _value(path: Path, row: int, cell: str) -> float:
    if cell.strip() == "" or cell.strip().lower() == "nan":
        return math.nan
    return finite_number(path, row, cell, "a pixel coordinate", hint=" (write NaN where a marker was not seen)")
