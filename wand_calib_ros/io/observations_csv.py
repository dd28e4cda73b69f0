"""The observations CSV: one row per wand point seen by one camera.

Header ``frame,camera,point,u,v`` (extra columns are ignored): ``frame`` an
integer id shared by the cameras' simultaneous images, ``camera`` a name from
the rig description, ``point`` A, B or C, ``u, v`` pixels in the OpenCV
convention ((0, 0) is the centre of the top-left pixel).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable
from pathlib import Path
from typing import TextIO

import numpy as np

from wand_calib_ros.core.rig import POINT_LABELS, WandObservations
from wand_calib_ros.io.errors import FormatError

COLUMNS = ("frame", "camera", "point", "u", "v")


def read_observations(path: str | Path, camera_names: Iterable[str] | None = None) -> WandObservations:
    """Read an observations CSV.

    Args:
        path: the file.
        camera_names: if given, the rig's cameras: rows naming another camera are
            an error, and the result's cameras follow this order.

    Raises:
        FormatError: naming the file, the row (1 = header) and the problem.
    """
    path = Path(path)
    known = list(camera_names) if camera_names is not None else None
    try:
        handle = path.open(newline="")
    except OSError as error:
        raise FormatError(path, f"cannot read: {error.strerror}") from None
    with handle:
        return _parse(handle, path, known)


def _parse(handle: TextIO, path: Path, known: list[str] | None) -> WandObservations:
    reader = csv.reader(handle)
    header = next(reader, None)
    if header is None:
        raise FormatError(path, "empty file; expected the header frame,camera,point,u,v")
    header = [h.strip() for h in header]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise FormatError(
            path, f"missing column(s) {', '.join(missing)}; expected header frame,camera,point,u,v", row=1
        )
    index = [header.index(c) for c in COLUMNS]
    width = max(index) + 1
    label_index = {label: i for i, label in enumerate(POINT_LABELS)}
    frames: dict[int, int] = {}
    cameras: dict[str, int] = {name: i for i, name in enumerate(known)} if known is not None else {}
    entries: list[tuple[int, int, int, float, float]] = []
    seen: set[tuple[int, int, int]] = set()
    for row_number, row in enumerate(reader, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) < width:
            raise FormatError(path, f"expected at least {width} columns, got {len(row)}", row=row_number)
        frame_text, camera, point, u_text, v_text = (row[i].strip() for i in index)
        try:
            frame = int(frame_text)
        except ValueError:
            raise FormatError(path, f"frame must be an integer, got {frame_text!r}", row=row_number) from None
        if point not in label_index:
            raise FormatError(path, f"point must be A, B or C, got {point!r}", row=row_number)
        try:
            u, v = float(u_text), float(v_text)
        except ValueError:
            raise FormatError(path, f"u, v must be numbers, got {u_text!r}, {v_text!r}", row=row_number) from None
        if not (math.isfinite(u) and math.isfinite(v)):
            raise FormatError(
                path,
                f"camera '{camera}' frame {frame} point {point}: u, v must be finite, got {u_text}, {v_text}",
                row=row_number,
            )
        if camera not in cameras:
            if known is not None:
                raise FormatError(path, f"unknown camera '{camera}'; the rig has {', '.join(known)}", row=row_number)
            cameras[camera] = len(cameras)
        key = (frames.setdefault(frame, len(frames)), cameras[camera], label_index[point])
        if key in seen:
            raise FormatError(path, f"camera '{camera}' frame {frame} point {point} appears twice", row=row_number)
        seen.add(key)
        entries.append((*key, u, v))
    if not entries:
        raise FormatError(path, "no observations after the header")
    frame_ids = np.array(sorted(frames, key=frames.__getitem__), dtype=np.int64)
    uv = np.full((len(frames), len(cameras), 3, 2), np.nan)
    table = np.array(entries)
    f, c, p = (table[:, i].astype(np.int64) for i in range(3))
    uv[f, c, p] = table[:, 3:]
    order = np.argsort(frame_ids, kind="stable")
    names = tuple(sorted(cameras, key=cameras.__getitem__))
    return WandObservations(frame_ids[order], names, uv[order])


def write_observations(observations: WandObservations, path: str | Path) -> None:
    """Write every finite point of ``observations`` as CSV rows (frame, camera, A/B/C order)."""
    with Path(path).open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(COLUMNS)
        seen = np.all(np.isfinite(observations.uv), axis=-1)
        for f, c, p in zip(*np.nonzero(seen), strict=True):
            u, v = observations.uv[f, c, p]
            writer.writerow(
                [int(observations.frames[f]), observations.camera_names[c], POINT_LABELS[p], f"{u:.6f}", f"{v:.6f}"]
            )
