"""A live session's history next to its buffer: the running estimate's rounds and the session's events.

``estimates.csv``, header ``time,frames,camera,rms_px,focal_std_percent,principal_std_px,wand_rms_mm,grade``:
one row per camera per round (``time`` in seconds since the epoch when the round arrived; ``frames``
the buffer's frames it saw; the rest the round's quality figures). ``events.csv``, header
``time,event,camera,message``: ``moved`` (the bump watch named a camera), ``calibrated`` and
``refined`` (a final result; camera empty, or the repaired cameras joined by ``+``), ``stamps_shifted`` (a
camera's stamps jumped within a take and are stored moved to continue its time line; the message says by how
much). Both are
appended to as the session goes on and read back by the report.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.io.errors import FormatError

ESTIMATES_FILE = "estimates.csv"
EVENTS_FILE = "events.csv"
ESTIMATE_COLUMNS = (
    "time",
    "frames",
    "camera",
    "rms_px",
    "focal_std_percent",
    "principal_std_px",
    "wand_rms_mm",
    "grade",
)
EVENT_COLUMNS = ("time", "event", "camera", "message")
EVENTS = ("moved", "calibrated", "refined", "stamps_shifted")

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class EstimateHistory:
    """The rounds of a running estimate, one row per camera per round.

    Attributes:
        time: (N,) when each round arrived, s since the epoch.
        frames: (N,) buffer frames the round saw.
        camera: (N,) camera names.
        rms_px, focal_std_percent, principal_std_px, wand_rms_mm: (N,) the round's figures.
        grade: (N,) the round's grade.
    """

    time: FloatArray
    frames: NDArray[np.int64]
    camera: tuple[str, ...]
    rms_px: FloatArray
    focal_std_percent: FloatArray
    principal_std_px: FloatArray
    wand_rms_mm: FloatArray
    grade: tuple[str, ...]


@dataclass(frozen=True)
class SessionEvent:
    """One event of the session (module docstring)."""

    time: float
    event: str
    camera: str
    message: str


def _append(path: Path, columns: tuple[str, ...], rows: list[list[str]]) -> None:
    new = not path.exists() or path.stat().st_size == 0
    with path.open("a", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream, lineterminator="\n")
        if new:
            writer.writerow(columns)
        writer.writerows(rows)


def append_estimate(path: Path, when: float, frames: int, result: CalibrationResult) -> None:
    """One round's rows (nothing when the result was not judged)."""
    if result.quality is None:
        return
    rows = [
        [f"{when:.3f}", str(frames), c.name, f"{c.image_error_px:.6g}", f"{c.focal_std_percent:.6g}",
         f"{c.principal_std_px:.6g}", f"{result.wand_length_rms_mm:.6g}", result.quality.grade]
        for c in result.quality.cameras
    ]  # fmt: skip
    _append(path, ESTIMATE_COLUMNS, rows)


def append_event(path: Path, when: float, event: str, camera: str, message: str) -> None:
    """One event (``event`` one of :data:`EVENTS`)."""
    if event not in EVENTS:
        raise ValueError(f"event must be one of {EVENTS}, got {event!r}")
    _append(path, EVENT_COLUMNS, [[f"{when:.3f}", event, camera, message]])


def _rows(path: Path, columns: tuple[str, ...]) -> list[dict[str, str]]:
    try:
        with path.open(newline="", encoding="utf-8") as stream:
            reader = csv.DictReader(stream)
            if tuple(reader.fieldnames or ()) != columns:
                raise FormatError(path, f"expected the header {','.join(columns)}, got {reader.fieldnames}")
            return list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise FormatError(path, f"cannot be read: {error}") from None


def read_estimates(path: Path) -> EstimateHistory:
    """``estimates.csv`` (FormatError naming the file and row on a bad one)."""
    keys = ("time", "rms_px", "focal_std_percent", "principal_std_px", "wand_rms_mm")
    values: list[list[float]] = []
    frames: list[int] = []
    rows = _rows(path, ESTIMATE_COLUMNS)
    for number, row in enumerate(rows, start=2):
        try:
            values.append([float(row[key]) for key in keys])
            frames.append(int(row["frames"]))
        except (TypeError, ValueError):
            raise FormatError(path, "a value is not a number", row=number) from None
    table = np.array(values, dtype=np.float64).reshape(-1, len(keys))
    return EstimateHistory(
        table[:, 0],
        np.array(frames, dtype=np.int64),
        tuple(r["camera"] for r in rows),
        table[:, 1],
        table[:, 2],
        table[:, 3],
        table[:, 4],
        tuple(r["grade"] for r in rows),
    )


def read_events(path: Path) -> tuple[SessionEvent, ...]:
    """``events.csv`` (FormatError naming the file and row on a bad one)."""
    events = []
    for number, row in enumerate(_rows(path, EVENT_COLUMNS), start=2):
        try:
            events.append(SessionEvent(float(row["time"]), row["event"], row["camera"], row["message"]))
        except (TypeError, ValueError):
            raise FormatError(path, f"time {row['time']!r} is not a number", row=number) from None
    return tuple(events)
