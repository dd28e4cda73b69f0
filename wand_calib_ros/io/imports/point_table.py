"""Point tables: a row per image point (frame, camera, point, x, y), as caliscope and pyOpenLPT write them.

Camera ids in ascending order are the rig description's cameras in order, point ids in ascending order its
wand's markers; frames are the table's frame ids. Pixels are taken as written (OpenCV's top-left origin).
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.text import finite_number, read_text


@dataclass(frozen=True)
class PointColumns:
    """The names a point table may give each of its columns (the first found is used)."""

    frame: tuple[str, ...]
    camera: tuple[str, ...]
    point: tuple[str, ...]
    x: tuple[str, ...]
    y: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class PointTable:
    """What a point table holds.

    Attributes:
        observations: its points, cameras and markers as the rig describes them.
        skipped: rows the table itself marks as not to use (``keep`` said no).
        camera_ids: the table's camera id of each rig camera.
        one_marker_views: camera views left out because they show one of the wand's markers only (where the
            tool calibrates from whole views).
    """

    observations: WandObservations
    skipped: int
    camera_ids: tuple[int, ...]
    one_marker_views: int = 0


def read_point_table(
    path: Path, rig: RigSpec, columns: PointColumns, *, keep: Callable[[dict[str, str]], bool] | None = None
) -> PointTable:
    """The observations of a point table.

    Args:
        columns: the names of its columns.
        keep: whether a row (by column name) is to be used (None: every row).

    Raises:
        FormatError: naming the file, the row or column and the problem.
    """
    text = read_text(path, "a point table")
    rows = [row for row in csv.reader(text.splitlines()) if row]
    if not rows:
        raise FormatError(path, f"empty file; expected a header with {_names(columns)}")
    header = [name.strip() for name in rows[0]]
    index = [_column(path, header, names) for names in (columns.frame, columns.camera, columns.point)]
    xy = [_column(path, header, names) for names in (columns.x, columns.y)]
    ids, pixels, skipped = [], [], 0
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise FormatError(path, f"{len(row)} cells where the header has {len(header)}", row=number)
        if keep is not None and not keep(dict(zip(header, row, strict=True))):
            skipped += 1
            continue
        ids.append([_integer(path, number, header[i], row[i]) for i in index])
        pixels.append([finite_number(path, number, row[i], "a pixel coordinate", header[i]) for i in xy])
    if not ids:
        raise FormatError(path, "no image points to use")
    table = np.array(ids, dtype=np.int64)
    camera_ids, camera = np.unique(table[:, 1], return_inverse=True)
    point_ids, point = np.unique(table[:, 2], return_inverse=True)
    frames, frame = np.unique(table[:, 0], return_inverse=True)
    if camera_ids.size != len(rig.cameras):
        raise FormatError(
            path,
            f"{camera_ids.size} cameras ({', '.join(map(str, camera_ids))}) in the table, {len(rig.cameras)} in "
            "the rig description (its cameras in ascending id order are the rig's in order)",
        )
    if point_ids.size != rig.wand.n_points:
        raise FormatError(
            path,
            f"{point_ids.size} point ids ({', '.join(map(str, point_ids))}), the rig's wand has {rig.wand.n_points}",
        )
    cell = (frame * camera_ids.size + camera) * point_ids.size + point
    unique, first = np.unique(cell, return_index=True)
    if unique.size != cell.size:
        twice = np.setdiff1d(np.arange(cell.size), first)[0]
        raise FormatError(
            path, f"frame {table[twice, 0]}, camera {table[twice, 1]}, point {table[twice, 2]} comes twice", row=None
        )
    uv = np.full((frames.size, camera_ids.size, point_ids.size, 2), np.nan)
    uv[frame, camera, point] = np.array(pixels, dtype=np.float64)
    observations = WandObservations(frames, rig.camera_names, uv)
    return PointTable(observations, skipped, tuple(int(i) for i in camera_ids))


def _names(columns: PointColumns) -> str:
    return ", ".join(names[0] for names in (columns.frame, columns.camera, columns.point, columns.x, columns.y))


def _column(path: Path, header: list[str], names: tuple[str, ...]) -> int:
    for name in names:
        if name in header:
            return header.index(name)
    raise FormatError(path, f"no column {' or '.join(names)} in the header ({', '.join(header)})", row=1)


def _integer(path: Path, row: int, column: str, cell: str) -> int:
    try:
        return int(cell.strip())
    except ValueError:
        raise FormatError(path, f"{column} is {cell!r}, not a whole number", row=row) from None
