"""The observations CSV: one row per wand point seen by one camera.

Header ``frame,camera,point,u,v[,stamp][,saturated][,brightness]`` (extra columns are ignored): ``frame`` an
integer id, ``camera`` a name from the rig description, ``point`` A, B or C,
``u, v`` pixels in the OpenCV convention ((0, 0) is the centre of the top-left
pixel), ``stamp`` (optional) the capture stamp of that camera's image in seconds
(the image's header stamp), ``saturated`` (optional) 1 where the point was measured on a
saturated spot, else 0, ``brightness`` (optional) how bright its spot was, in stops over the image's full
scale (log2 of its peak over full scale: 0 at full scale, 3 at 8x, negative below; ``nan`` or empty: not
measured). The detector writes both; the calibration models a centre bias that grows with the brightness.
Without stamps, rows sharing ``frame`` are simultaneous and consecutive ids are consecutive frames
of one recording at a constant rate; with stamps, rows sharing ``frame`` are a grouping of images
close in time, and each image is placed at its own stamp.
"""

from __future__ import annotations

import csv
import io
import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.rig import ALL_POINT_LABELS, POINT_LABELS, RigSpec, WandObservations
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.outputs import write_text

COLUMNS = ("frame", "camera", "point", "u", "v")
log = logging.getLogger(__name__)

#: The optional column of per-image capture stamps (seconds).
STAMP = "stamp"
#: The optional column of per-point saturation flags (1: measured on a saturated spot, 0: not).
SATURATED = "saturated"
#: The optional column of per-point brightness, stops over full scale (:mod:`~wand_calib_ros.core.model.brightness`).
BRIGHTNESS = "brightness"
#: A brightness beyond this many stops (either way) is not one (a column of another kind).
MAX_STOPS = 40.0
#: How far (px) beyond its image's border a point may lie: real detections never do, but simulated
#: pixel noise (up to 1 px, about 5 sigma over a large take) pushes points near the border out;
#: a wrong image_size or a wrong camera is off by tens of pixels or more.
IMAGE_MARGIN_PX = 10.0
#: Stamps above this (seconds: year 5138) are surely in another unit (nanoseconds).
MAX_STAMP_S = 1e11


def read_rig_observations(path: str | Path, rig: RigSpec) -> WandObservations:
    """:func:`read_observations` of a rig's cameras (in its order, image sizes checked) and wand labels."""
    return read_observations(path, rig.camera_names, image_sizes=rig.image_sizes, labels=rig.wand.labels)


def read_observations(
    path: str | Path,
    camera_names: Iterable[str] | None = None,
    *,
    image_sizes: Mapping[str, tuple[int, int]] | None = None,
    labels: tuple[str, ...] = POINT_LABELS,
) -> WandObservations:
    """Read an observations CSV.

    Args:
        path: the file.
        camera_names: if given, the rig's cameras: rows naming another camera are
            an error, and the result's cameras follow this order.
        image_sizes: if given, each camera's (width, height) in px: a point more than
            IMAGE_MARGIN_PX outside its image is an error.
        labels: the wand's marker labels (``WandSpec.labels``; default the three-LED wand's A, B, C).

    Raises:
        FormatError: naming the file, the row (1 = header) and the problem.
    """
    path = Path(path)
    known = list(camera_names) if camera_names is not None else None
    try:
        raw = path.read_bytes()
    except OSError as error:
        raise FormatError(path, f"cannot read: {error.strerror}") from None
    fast = _parse_plain(raw, known, dict(image_sizes or {}), labels)
    if fast is not None:
        if not raw.endswith(b"\n"):
            _warn_torn(path)
        return fast
    # Not the plain case (or something is wrong with it): row by row, naming the first bad row.
    handle = path.open(newline="", encoding="utf-8-sig")  # a byte-order mark some editors write is fine
    with handle:
        try:
            observations = _parse(handle, path, known, dict(image_sizes or {}), labels)
        except UnicodeDecodeError as error:
            raise FormatError(
                path, f"not UTF-8 text (it holds the byte 0x{error.object[error.start]:02x}): not an observations CSV?"
            ) from None
        except csv.Error as error:
            raise FormatError(path, f"not a CSV: {error}") from None
    if not _ends_with_newline(path):
        _warn_torn(path)
    return observations


def _warn_torn(path: Path) -> None:
    log.warning(
        "%s: the last row has no line end: if its writer was stopped mid-row its last value may be cut "
        "(a collector cuts a torn row off its buffer when it restarts)",
        path,
    )


def _cells_per_line_are(raw: bytes, cells: int) -> bool:
    """Whether every line of ``raw`` (blank ones too, and a last one without line end) has ``cells``
    comma-separated cells: numpy's reader would silently ignore a cell too many (a decimal comma)."""
    data = np.frombuffer(raw, dtype=np.uint8)
    ends = np.flatnonzero(data == ord("\n"))
    if data.size and data[-1] != ord("\n"):
        ends = np.append(ends, data.size)
    commas_before_end = np.searchsorted(np.flatnonzero(data == ord(",")), ends)
    return bool(np.all(np.diff(commas_before_end, prepend=0) == cells - 1))


def _frame_rows(frame: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The distinct frame ids, ascending, and each row's index among them (rows in frame order: no sort)."""
    if np.all(frame[1:] >= frame[:-1]):
        new = np.r_[True, frame[1:] != frame[:-1]]
        return frame[new], np.cumsum(new) - 1
    ids, rows = np.unique(frame, return_inverse=True)
    return ids, rows


def _index_of(values: NDArray[np.str_] | NDArray[np.bytes_], names: tuple[str, ...]) -> NDArray[np.int64] | None:
    """(N,) index of each value (str, or ASCII bytes) in ``names``; None when a value is not among them."""
    table = np.array([name.encode() for name in names] if values.dtype.kind == "S" else names)
    order = np.argsort(table)
    found = np.minimum(np.searchsorted(table, values, sorter=order), len(names) - 1)
    index = order[found]
    return index if np.array_equal(table[index], values) else None


def _parse_plain(
    raw: bytes, known: list[str] | None, sizes: dict[str, tuple[int, int]], labels: tuple[str, ...] = POINT_LABELS
) -> WandObservations | None:
    """The observations of a valid file without quoting or padding, parsed by numpy's C reader (about
    5x faster than row by row); None when the file is anything else or breaks a rule: the row-by-row
    reader then reads it and names the first bad row. Both give identical observations."""
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return None
    if any(mark in text for mark in ('"', " ", "\t")) or ("\r" in text and "\r" in text.replace("\r\n", "\n")):
        return None
    end = text.find("\n")  # (the first line only: not a copy of the rest)
    if end < 0 or text.find(",", end + 1) < 0:  # no row after the header (numpy's reader would warn of it)
        return None
    header = text[:end].rstrip("\r").split(",")
    if any(c not in header for c in COLUMNS):
        return None
    fields = [*COLUMNS, *(name for name in (STAMP, SATURATED, BRIGHTNESS) if name in header)]
    # numpy's reader checks every row's cells itself when it reads them all (a decimal comma: ValueError); with
    # columns left out it ignores cells beyond them, and they are counted first
    every = header == fields
    if not every and not _cells_per_line_are(raw, len(header)):
        return None
    longest = 1 + (max(map(len, known)) if known else 64)  # a longer name shows as this long: not known
    text_kind = "S" if text.isascii() else "U"  # bytes compare and sort faster than str
    kinds = {"frame": "i8", "camera": f"{text_kind}{longest}", "point": f"{text_kind}2", "u": "f8", "v": "f8"}
    kinds[STAMP] = "f8"
    kinds[SATURATED] = "i8"
    kinds[BRIGHTNESS] = "f8"
    try:
        table = np.loadtxt(
            io.BytesIO(raw),  # numpy's reader decodes bytes faster than it reads a str
            encoding="utf-8",
            delimiter=",",
            skiprows=1,
            comments=None,
            usecols=None if every else [header.index(name) for name in fields],
            dtype=[(name, kinds[name]) for name in fields],
            ndmin=1,
        )
    except ValueError:  # a cell that is not a number, rows of other lengths, ...
        return None
    if table.size == 0:
        return None
    frame = table["frame"]
    uv_rows = np.stack([table["u"], table["v"]], axis=1)
    stamp = table[STAMP] if STAMP in header else None
    flag = table[SATURATED] if SATURATED in header else None
    stops = table[BRIGHTNESS] if BRIGHTNESS in header else None
    if not np.all(np.isfinite(uv_rows)) or (flag is not None and not np.all((flag == 0) | (flag == 1))):
        return None
    if stops is not None and not np.all(np.isnan(stops) | (np.abs(stops) <= MAX_STOPS)):
        return None
    camera_text = table["camera"]
    if known is not None:
        names = tuple(known)
    else:
        found, first = np.unique(camera_text, return_index=True)
        if max(map(len, found)) >= longest:
            return None
        names = tuple(str(n, "ascii") if isinstance(n, bytes) else str(n) for n in found[np.argsort(first)])
    camera = _index_of(camera_text, names)
    point = _index_of(table["point"], labels)
    if camera is None or point is None:  # a camera the rig lacks, a label other than A, B, C
        return None
    if sizes:  # every point within its image's margin (cameras without a size: anywhere)
        high = np.array([sizes.get(name, (np.inf, np.inf)) for name in names], dtype=np.float64)[camera]
        if not (np.all(uv_rows >= -0.5 - IMAGE_MARGIN_PX) and np.all(uv_rows <= high - 0.5 + IMAGE_MARGIN_PX)):
            return None
    frame_ids, frame_row = _frame_rows(frame)
    n_cameras = len(names)
    key = (frame_row * n_cameras + camera) * len(labels) + point
    if np.any(np.bincount(key, minlength=frame_ids.size * n_cameras * len(labels)) > 1):  # a point twice
        return None
    uv = np.full((frame_ids.size, n_cameras, len(labels), 2), np.nan)
    uv[frame_row, camera, point] = uv_rows
    stamps = None
    if stamp is not None:
        if not np.all(np.isfinite(stamp)) or np.any(np.abs(stamp) > MAX_STAMP_S):
            return None
        stamps = np.full((frame_ids.size, n_cameras), np.nan)
        stamps[frame_row, camera] = stamp
        if not np.array_equal(stamps[frame_row, camera], stamp):  # the points of one image share its stamp
            return None
        for c in range(n_cameras):
            seen = stamps[:, c][np.isfinite(stamps[:, c])]
            if np.any(np.diff(seen) <= 0):  # stamps must increase with the frame id
                return None
    where = (frame_row, camera, point)
    saturated = _per_point(uv.shape[:3], where, None if flag is None else flag == 1, False)
    brightness = _per_point(uv.shape[:3], where, stops, np.nan)
    return WandObservations(frame_ids.astype(np.int64), names, uv, stamps, saturated, brightness)


def _ends_with_newline(path: Path) -> bool:
    with path.open("rb") as handle:
        handle.seek(0, 2)
        if handle.tell() == 0:
            return True
        handle.seek(-1, 2)
        return handle.read(1) == b"\n"


@dataclass(frozen=True)
class _Header:
    """Where the row-by-row reader finds each column.

    Attributes:
        index: the columns frame, camera, point, u, v.
        stamp: the stamp column (None: none).
        flag: the saturated column (None: none).
        cells: the cells of the header (a row may not have more).
        brightness: the brightness column (None: none).
    """

    index: tuple[int, ...]
    stamp: int | None
    flag: int | None
    cells: int
    brightness: int | None = None

    @property
    def width(self) -> int:
        """The fewest cells a row must have."""
        return max([*self.index] + [i for i in (self.stamp, self.flag, self.brightness) if i is not None]) + 1


def _header(path: Path, cells: list[str] | None) -> _Header:
    """The columns of the header row ``cells`` (None: the file is empty)."""
    if cells is None:
        raise FormatError(path, "empty file; expected the header frame,camera,point,u,v")
    names = [h.strip() for h in cells]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        raise FormatError(
            path, f"missing column(s) {', '.join(missing)}; expected header frame,camera,point,u,v", row=1
        )
    stamp = names.index(STAMP) if STAMP in names else None
    flag = names.index(SATURATED) if SATURATED in names else None
    brightness = names.index(BRIGHTNESS) if BRIGHTNESS in names else None
    return _Header(tuple(names.index(c) for c in COLUMNS), stamp, flag, len(names), brightness)


def _point_row(
    path: Path,
    row_number: int,
    row: list[str],
    header: _Header,
    labels: tuple[str, ...],
    sizes: dict[str, tuple[int, int]],
) -> tuple[int, str, str, float, float]:
    """One row's frame, camera, point and u, v, each checked (a point in its camera's image, when its size is known)."""
    if len(row) < header.width:
        raise FormatError(path, f"expected at least {header.width} columns, got {len(row)}", row=row_number)
    if len(row) > header.cells:
        raise FormatError(
            path,
            f"{len(row)} cells where the header has {header.cells} (a decimal comma? write 12.5, not 12,5)",
            row=row_number,
        )
    frame_text, camera, point, u_text, v_text = (row[i].strip() for i in header.index)
    try:
        frame = int(frame_text)
    except ValueError:
        raise FormatError(path, f"frame must be an integer, got {frame_text!r}", row=row_number) from None
    if not -(2**63) <= frame < 2**63:
        raise FormatError(path, f"frame {frame_text} is out of range (a frame id is a 64-bit integer)", row=row_number)
    if point not in labels:
        named = f"{', '.join(labels[:-1])} or {labels[-1]}"
        raise FormatError(path, f"point must be {named} (the wand's markers), got {point!r}", row=row_number)
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
    size = sizes.get(camera)
    if size is not None and not (
        -0.5 - IMAGE_MARGIN_PX <= u <= size[0] - 0.5 + IMAGE_MARGIN_PX
        and -0.5 - IMAGE_MARGIN_PX <= v <= size[1] - 0.5 + IMAGE_MARGIN_PX
    ):
        raise FormatError(
            path,
            f"camera '{camera}' frame {frame} point {point}: ({u_text}, {v_text}) lies outside its "
            f"{size[0]}x{size[1]} image (image_size in the rig description: the right camera? the right size?)",
            row=row_number,
        )
    return frame, camera, point, u, v


def _flag(path: Path, row_number: int, camera: str, frame: int, point: str, text: str) -> bool:
    """A row's saturated cell: 0 or 1."""
    if text not in ("0", "1"):
        raise FormatError(
            path, f"camera '{camera}' frame {frame} point {point}: saturated must be 0 or 1, got {text!r}",
            row=row_number,
        )  # fmt: skip
    return text == "1"


def _stops(path: Path, row_number: int, camera: str, frame: int, point: str, text: str) -> float:
    """A row's brightness cell: stops over full scale (nan or empty: not measured)."""
    try:
        stops = float(text) if text else math.nan
    except ValueError:
        stops = math.inf
    if not (math.isnan(stops) or abs(stops) <= MAX_STOPS):
        raise FormatError(
            path,
            f"camera '{camera}' frame {frame} point {point}: brightness must be stops over full scale (a number within "
            f"+-{MAX_STOPS:g}, or nan: not measured), got {text!r}",
            row=row_number,
        )
    return stops


def _parse(
    handle: TextIO,
    path: Path,
    known: list[str] | None,
    sizes: dict[str, tuple[int, int]],
    labels: tuple[str, ...] = POINT_LABELS,
) -> WandObservations:
    """The observations of a CSV read row by row, every row checked (the first fault raised, naming its row)."""
    reader = csv.reader(handle)
    header = _header(path, next(reader, None))
    label_index = {label: i for i, label in enumerate(labels)}
    frames: dict[int, int] = {}
    cameras: dict[str, int] = {name: i for i, name in enumerate(known)} if known is not None else {}
    entries: list[tuple[int, int, int, float, float]] = []
    flags: list[bool] = []
    stops: list[float] = []
    seen: set[tuple[int, int, int]] = set()
    view_stamps: dict[tuple[int, int], tuple[float, int]] = {}  # (frame, camera) -> (stamp, first row)
    for row_number, row in enumerate(reader, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        frame, camera, point, u, v = _point_row(path, row_number, row, header, labels, sizes)
        if camera not in cameras:
            if known is not None:
                raise FormatError(path, f"unknown camera '{camera}'; the rig has {', '.join(known)}", row=row_number)
            cameras[camera] = len(cameras)
        key = (frames.setdefault(frame, len(frames)), cameras[camera], label_index[point])
        if key in seen:
            raise FormatError(path, f"camera '{camera}' frame {frame} point {point} appears twice", row=row_number)
        seen.add(key)
        entries.append((*key, u, v))
        if header.flag is not None:
            flags.append(_flag(path, row_number, camera, frame, point, row[header.flag].strip()))
        if header.brightness is not None:
            stops.append(_stops(path, row_number, camera, frame, point, row[header.brightness].strip()))
        if header.stamp is not None:
            stamp = _stamp(path, row_number, camera, frame, row[header.stamp].strip())
            first = view_stamps.setdefault(key[:2], (stamp, row_number))
            if first[0] != stamp:
                raise FormatError(
                    path,
                    f"camera '{camera}' frame {frame}: stamp {float(stamp)!r} differs from {float(first[0])!r} in row "
                    f"{first[1]}; the points of one image share its stamp",
                    row=row_number,
                )
    if not entries:
        raise FormatError(path, "no observations after the header")
    stamps = view_stamps if header.stamp is not None else None
    return _parsed(
        path,
        frames,
        cameras,
        entries,
        stamps,
        flags if header.flag is not None else None,
        len(labels),
        stops if header.brightness is not None else None,
    )


def _parsed(
    path: Path,
    frames: dict[int, int],
    cameras: dict[str, int],
    entries: list[tuple[int, int, int, float, float]],
    view_stamps: dict[tuple[int, int], tuple[float, int]] | None,
    flags: list[bool] | None,
    n_points: int,
    stops: list[float] | None = None,
) -> WandObservations:
    """The observations of the rows read: (frame row, camera, point, u, v) ``entries``, frames in the order of
    their ids; each view's stamp (with its first row), each point's saturation flag and brightness, where the file
    has them."""
    frame_ids = np.array(sorted(frames, key=frames.__getitem__), dtype=np.int64)
    uv = np.full((len(frames), len(cameras), n_points, 2), np.nan)
    table = np.array(entries)
    f, c, p = (table[:, i].astype(np.int64) for i in range(3))
    uv[f, c, p] = table[:, 3:]
    order = np.argsort(frame_ids, kind="stable")
    names = tuple(sorted(cameras, key=cameras.__getitem__))
    stamps = None
    if view_stamps is not None:
        stamps = np.full((len(frames), len(cameras)), np.nan)
        for (frame_row, camera_index), (stamp, _) in view_stamps.items():
            stamps[frame_row, camera_index] = stamp
        stamps = stamps[order]
        _check_stamp_order(path, frame_ids[order], names, stamps, view_stamps, order)
    saturated = _per_point(uv.shape[:3], (f, c, p), flags, False)
    brightness = _per_point(uv.shape[:3], (f, c, p), stops, np.nan)
    return WandObservations(
        frame_ids[order],
        names,
        uv[order],
        stamps,
        None if saturated is None else saturated[order],
        None if brightness is None else brightness[order],
    )


def _per_point(
    shape: tuple[int, ...], where: tuple[NDArray[Any], ...], values: Any, empty: bool | float
) -> NDArray[Any] | None:
    """(F, C, K) a per-point column: ``values`` at the points ``where`` (frame rows, cameras, points), ``empty``
    elsewhere (its type the array's: bool flags or float stops); None where the file has no such column."""
    if values is None:
        return None
    out = np.full(shape, empty, dtype=bool if isinstance(empty, bool) else np.float64)
    out[where] = values
    return out


def _stamp(path: Path, row_number: int, camera: str, frame: int, text: str) -> float:
    try:
        stamp = float(text)
    except ValueError:
        raise FormatError(
            path, f"camera '{camera}' frame {frame}: stamp must be a number of seconds, got {text!r}", row=row_number
        ) from None
    if not math.isfinite(stamp):
        raise FormatError(path, f"camera '{camera}' frame {frame}: stamp must be finite, got {text}", row=row_number)
    if abs(stamp) > MAX_STAMP_S:
        raise FormatError(
            path,
            f"camera '{camera}' frame {frame}: stamp {text} is not in seconds (nanoseconds?); write seconds, "
            "e.g. 1700000000.033",
            row=row_number,
        )
    return stamp


def _check_stamp_order(
    path: Path,
    frame_ids: NDArray[np.int64],
    names: tuple[str, ...],
    stamps: NDArray[np.float64],
    view_stamps: dict[tuple[int, int], tuple[float, int]],
    order: NDArray[np.int64],
) -> None:
    """Each camera's stamps must increase with the frame id (one image per frame, in time order)."""
    for c, name in enumerate(names):
        rows = np.flatnonzero(np.isfinite(stamps[:, c]))
        steps = np.diff(stamps[rows, c])
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            first, second = rows[bad[0]], rows[bad[0] + 1]
            what = "repeats" if steps[bad[0]] == 0 else "goes backwards"
            raise FormatError(
                path,
                f"camera '{name}': its stamp {what} from frame {frame_ids[first]} ({float(stamps[first, c])!r} s) to "
                f"frame {frame_ids[second]} ({float(stamps[second, c])!r} s); each image is one frame, frames in time "
                "order",
                row=view_stamps[(int(order[second]), c)][1],
            )


def observation_rows(
    frame: int,
    camera_names: tuple[str, ...],
    uv: NDArray[np.float64],
    stamps: NDArray[np.float64] | None,
    saturated: NDArray[np.bool_] | None = None,
    brightness: NDArray[np.float64] | None = None,
) -> list[list[object]]:
    """The CSV rows of one frame: (C, K, 2) pixels (NaN: not seen), (C,) stamps in s (or None), (C, K)
    saturation flags (or None) and (C, K) brightness in stops (or None)."""
    rows: list[list[object]] = []
    for c, name in enumerate(camera_names):
        for p, label in enumerate(ALL_POINT_LABELS[: uv.shape[1]]):
            u, v = uv[c, p]
            if np.isfinite(u) and np.isfinite(v):
                row: list[object] = [frame, name, label, f"{u:.6f}", f"{v:.6f}"]
                if stamps is not None:
                    row.append(f"{stamps[c]:.9f}")
                if saturated is not None:
                    row.append(int(saturated[c, p]))
                if brightness is not None:
                    row.append(f"{brightness[c, p]:.3f}" if np.isfinite(brightness[c, p]) else "nan")
                rows.append(row)
    return rows


def header(with_stamps: bool, with_saturated: bool = False, with_brightness: bool = False) -> tuple[str, ...]:
    """The CSV header, with the stamp, the saturation flags' and the brightness columns or without them."""
    optional = ((STAMP, with_stamps), (SATURATED, with_saturated), (BRIGHTNESS, with_brightness))
    return (*COLUMNS, *(name for name, present in optional if present))


def write_observations(observations: WandObservations, path: str | Path) -> None:
    """Write every finite point of ``observations`` as CSV rows (frame, camera, A/B/C order; stamps, saturation
    flags and brightness if any)."""
    flags, stops = observations.saturated, observations.brightness
    text = io.StringIO(newline="")
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(header(observations.stamps is not None, flags is not None, stops is not None))
    for f, frame in enumerate(observations.frames):
        stamps = None if observations.stamps is None else observations.stamps[f]
        rows = observation_rows(
            int(frame),
            observations.camera_names,
            observations.uv[f],
            stamps,
            None if flags is None else flags[f],
            None if stops is None else stops[f],
        )
        writer.writerows(rows)
    write_text(path, text.getvalue())
