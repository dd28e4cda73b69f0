"""Point files of Argus, DLTdv and easyWand (``*-xypts.csv``): the wand's markers per frame and camera.

One header row, one row per frame (frame id = row index from 0), NaN (or an empty cell) where a camera did
not see a marker; commas, or tabs (Argus's ``-xypts.tsv``). The header tells the writer:

- ``<track>_cam_<N>_x`` / ``_y``: Argus's Clicker (pandas, its columns sorted by name, so ``cam_10`` comes
  before ``cam_2``): a track per marker (the tracks in the order they first appear are the wand's markers in
  order), bottom-left origin with y up and pixel edges at whole numbers
  (:data:`~wand_calib_ros.io.imports.pixels.ARGUS_CLICKER`).
- ``pt<P>_cam<C>_X`` / ``_Y``: DLTdv: MATLAB's 1-based pixels, the origin not written (DLTdv 8: top left,
  up to 7: bottom left).
- ``pt<P>_cam<C>_x`` / ``_y``: Argus's paired points (its ChArUco and wand exports): 0-based pixels, top left
  or, exported with its y flip, y = height - v; the origin not written.

P and C count from 1; camera C (or N) is the rig description's C-th camera.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np

from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.pixels import ARGUS_CLICKER, MATLAB, PixelFrame, WrittenPoints
from wand_calib_ros.io.text import finite_number, read_text

_NUMBERED = re.compile(r"^pt(\d+)_cam(\d+)_([xyXY])$")
_TRACKS = re.compile(r"^(.+)_cam_(\d+)_([xy])$")
#: Argus's paired points: 0-based pixels; from the bottom its y flip writes height - v (first centre at 1).
ARGUS_PAIRED = PixelFrame(None, (0.0, 0.0), first_from_bottom=1.0)


def read_xypts(path: str | Path, rig: RigSpec) -> WrittenPoints:
    """The points of a point file as written, cameras and markers as the rig describes them.

    Raises:
        FormatError: naming the file, the row or column and the problem.
    """
    path = Path(path)
    text = read_text(path, "a point file")
    lines = text.splitlines()
    delimiter = "\t" if lines and "\t" in lines[0] and "," not in lines[0] else ","
    # a row of empty cells is a frame in which nothing was seen (it keeps the later frames' ids); only
    # blank lines are not rows
    rows = [row for row in csv.reader(lines, delimiter=delimiter) if row]
    if not rows:
        raise FormatError(path, "empty file; expected a header pt1_cam1_x,pt1_cam1_y,... or <track>_cam_1_x,...")
    columns, pixels, writer = _header(path, [name.strip() for name in rows[0]])
    n_points = max(p for p, _, _ in columns) + 1
    n_cameras = max(c for _, c, _ in columns) + 1
    if n_cameras != len(rig.cameras):
        raise FormatError(
            path, f"{n_cameras} cameras in the file, {len(rig.cameras)} in the rig description (camera C = its C-th)"
        )
    if n_points != rig.wand.n_points:
        raise FormatError(path, f"{n_points} markers per frame, the rig's wand has {rig.wand.n_points}")
    if len(set(columns)) != len(columns) or len(columns) != 2 * n_points * n_cameras:
        raise FormatError(path, "every marker and camera needs one x and one y column", row=1)
    xy = np.full((len(rows) - 1, n_cameras, n_points, 2), np.nan)
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(columns):
            raise FormatError(path, f"{len(row)} cells where the header has {len(columns)}", row=number)
        for cell, (p, c, is_y) in zip(row, columns, strict=True):
            xy[number - 2, c, p, int(is_y)] = _value(path, number, cell)
    seen_partly = np.isfinite(xy[..., 0]) != np.isfinite(xy[..., 1])
    if seen_partly.any():
        f, c, p = (int(i[0]) for i in np.nonzero(seen_partly))
        raise FormatError(path, f"marker {p + 1} in camera {c + 1} has x or y only", row=f + 2)
    seen = np.any(np.isfinite(xy), axis=(1, 2, 3))
    if not seen.any():
        raise FormatError(path, "no marker is seen in any frame")
    return WrittenPoints(np.flatnonzero(seen), xy[seen], pixels, writer)


def _header(path: Path, names: list[str]) -> tuple[list[tuple[int, int, bool]], PixelFrame, str]:
    """Each column's (marker, camera, is y), 0-based, the writer's pixel frame and its name."""
    if names and all(_NUMBERED.match(name) for name in names):
        found = [_NUMBERED.match(name) for name in names]
        columns = []
        for index, match in enumerate(found):
            assert match is not None
            if int(match[1]) == 0 or int(match[2]) == 0:
                raise FormatError(
                    path,
                    f"column {index + 1} is {names[index]!r}: markers and cameras count from 1 (pt1_cam1_x is the "
                    "first)",
                    row=1,
                )
            columns.append((int(match[1]) - 1, int(match[2]) - 1, match[3].lower() == "y"))
        if all(match is not None and match[3].isupper() for match in found):
            return columns, MATLAB, "DLTdv's points (pt<P>_cam<C>_X)"
        return columns, ARGUS_PAIRED, "Argus's paired points (pt<P>_cam<C>_x)"
    tracks: list[str] = []
    columns = []
    for index, name in enumerate(names):
        match = _TRACKS.match(name)
        if match is None:
            raise FormatError(
                path, f"column {index + 1} is {name!r}, not pt<P>_cam<C>_x (DLTdv, Argus) or <track>_cam_<N>_x "
                "(Argus's Clicker)", row=1,
            )  # fmt: skip
        if int(match[2]) == 0:
            raise FormatError(path, f"column {index + 1} is {name!r}: Argus's cameras count from 1", row=1)
        if match[1] not in tracks:
            tracks.append(match[1])
        columns.append((tracks.index(match[1]), int(match[2]) - 1, match[3] == "y"))
    return columns, ARGUS_CLICKER, "Argus Clicker's points (<track>_cam_<N>_x)"


def _value(path: Path, row: int, cell: str) -> float:
    if cell.strip() == "" or cell.strip().lower() == "nan":
        return math.nan
    return finite_number(path, row, cell, "a pixel coordinate", hint=" (write NaN where a marker was not seen)")
