"""A bounded, persisted buffer of synchronised wand observations.

Every accepted frame is appended to an observations CSV (the core's format, each
view with its image's stamp) and flushed at once, and the file is synced to disk at
least every SYNC_INTERVAL_S: a killed process loses at most the frame being
written, a machine losing power at most the last second. A restart resumes from the
file, cutting a torn last write back to the last complete frame (the file as found
is kept aside, see :mod:`wand_calib_ros.collection.recovery`). A frame in which no camera's wand moved by more than
``min_motion_px`` since the last accepted frame is a near-duplicate (the wand
held still) and is skipped; once ``capacity`` frames are stored, a frame is only
accepted when it shows a camera the wand in an image cell with few
observations, so the buffer stays bounded without losing coverage.
"""

from __future__ import annotations

import csv
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.collection.floor import FLOOR_FILE
from wand_calib_ros.collection.recovery import TornTail, cut_torn_tail, move_aside
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.observations_csv import header, observation_rows, read_rig_observations
from wand_calib_ros.io.outputs import check_writable
from wand_calib_ros.io.session_csv import ESTIMATES_FILE, EVENTS_FILE

FloatArray = NDArray[np.float64]

#: The buffer's file name in a collector's output directory.
BUFFER_FILE = "observations.csv"

#: Cells per image side for the coverage test of a full buffer.
GRID = 8
#: The longest time (s) an appended frame stays in the operating system's cache only.
SYNC_INTERVAL_S = 1.0


#: The files beside a buffer that belong to its take: /reset moves them aside with it.
SIBLINGS = (FLOOR_FILE, ESTIMATES_FILE, EVENTS_FILE)


@dataclass
class BufferStats:
    """Counters of the buffer."""

    accepted: int = 0
    still: int = 0
    full: int = 0
    empty: int = 0


@dataclass
class ObservationBuffer:
    """See the module docstring. Create with :meth:`open`."""

    path: Path
    rig: RigSpec
    capacity: int
    min_motion_px: float
    frames: list[int] = field(default_factory=list)
    uv: list[FloatArray] = field(default_factory=list)
    stamps: list[FloatArray] = field(default_factory=list)
    saturated: list[NDArray[np.bool_]] = field(default_factory=list)
    brightness: list[FloatArray] = field(default_factory=list)
    stats: BufferStats = field(default_factory=BufferStats)
    with_stamps: bool = True
    with_saturated: bool = False
    with_brightness: bool = False
    repaired: TornTail | None = None  #: a torn tail cut on opening
    _cells: NDArray[np.int64] | None = None
    _synced: float = 0.0  # time.monotonic() of the last fsync

    @staticmethod
    def open(
        path: Path,
        rig: RigSpec,
        *,
        capacity: int = 20_000,
        min_motion_px: float = 2.0,
        with_stamps: bool = True,
        with_brightness: bool = False,
    ) -> ObservationBuffer:
        """A buffer persisted at ``path``; resumes from the file when it exists (a torn last write is
        cut, see :attr:`repaired`; any other corruption is an error).

        Args:
            with_stamps: a new file stores each view's stamp (a resumed file keeps what it has: one
                written without stamps, by an older version, is continued without them).
            with_brightness: a new file stores each point's saturation flag and brightness (the collector's own
                detector measured them; a resumed file keeps what it has: an older one the flags alone).

        Raises:
            FormatError: the file exists but is not a buffer this rig can continue.
        """
        buffer = ObservationBuffer(
            Path(path),
            rig,
            capacity,
            min_motion_px,
            with_stamps=with_stamps,
            with_saturated=with_brightness,
            with_brightness=with_brightness,
        )
        buffer._cells = np.zeros((len(rig.cameras), GRID, GRID), dtype=np.int64)
        if buffer.path.exists():
            try:
                buffer.repaired = cut_torn_tail(buffer.path)
            except OSError as error:
                raise FormatError(buffer.path, f"cannot repair the buffer: {error.strerror}") from None
        if buffer.path.exists() and has_rows(buffer.path):
            try:
                existing = read_rig_observations(buffer.path, rig)
            except FormatError as error:
                if buffer.repaired is not None:  # not a buffer a tear explains: put the file back as found
                    os.replace(buffer.repaired.original, buffer.path)
                raise FormatError(buffer.path, f"cannot resume the buffer ({error}); move the file away") from None
            buffer.with_stamps = existing.stamps is not None
            buffer.with_saturated = existing.saturated is not None
            buffer.with_brightness = existing.brightness is not None
            stamps = existing.stamps if existing.stamps is not None else np.full(existing.uv.shape[:2], np.nan)
            flags = existing.saturated if existing.saturated is not None else np.zeros(existing.uv.shape[:3], bool)
            stops = existing.brightness if existing.brightness is not None else np.full(existing.uv.shape[:3], np.nan)
            for frame, uv, stamp, flag, stop in zip(existing.frames, existing.uv, stamps, flags, stops, strict=True):
                buffer._remember(int(frame), uv, stamp, flag, stop)
        else:
            check_writable([buffer.path])
            buffer.path.parent.mkdir(parents=True, exist_ok=True)
            buffer._start_file()
        return buffer

    @property
    def next_frame(self) -> int:
        """Frame id for the next accepted frame (continues after a resume)."""
        return self.frames[-1] + 1 if self.frames else 0

    def offer(
        self,
        uv: FloatArray,
        stamps: FloatArray | None = None,
        *,
        keep: bool = False,
        brightness: FloatArray | None = None,
    ) -> bool:
        """Consider one synchronised frame ((C, 3, 2), NaN where unseen) with its views' stamps ((C,) s,
        NaN where a camera has no image in it) and its points' brightness ((C, 3) stops over full scale, NaN: not
        measured; None: none measured); True when it was stored. ``keep``: store it even when the wand is still or
        the buffer full (the wand laid on the floor)."""
        if stamps is None and self.with_stamps:
            raise ValueError("this buffer stores the views' stamps: offer them with the frame")
        stamps = np.full(uv.shape[0], np.nan) if stamps is None else np.asarray(stamps, dtype=np.float64)
        complete = np.all(np.isfinite(uv), axis=(1, 2))
        if complete.sum() < 1:
            self.stats.empty += 1
            return False
        if self.uv and not keep:
            last = self.uv[-1]
            moved = np.linalg.norm(uv - last, axis=-1).max(axis=-1)  # (C,) NaN where either is missing
            both = complete & np.all(np.isfinite(last), axis=(1, 2))
            if both.any() and not np.any(moved[both] > self.min_motion_px) and np.array_equal(both, complete):
                self.stats.still += 1
                return False
        if not keep and len(self.frames) >= self.capacity and not self._adds_coverage(uv, complete):
            self.stats.full += 1
            return False
        frame = self.next_frame
        stops = np.full(uv.shape[:2], np.nan) if brightness is None else np.asarray(brightness, dtype=np.float64)
        flags = np.nan_to_num(stops, nan=-1.0) >= 0.0
        self._append_rows(frame, uv, stamps, flags, stops)
        self._remember(frame, uv, stamps, flags, stops)
        self.stats.accepted += 1
        return True

    def observations(self) -> WandObservations:
        """Everything stored, in the core's observation type."""
        n = len(self.rig.cameras)
        uv = np.array(self.uv) if self.uv else np.zeros((0, n, self.rig.wand.n_points, 2))
        stamps = (np.array(self.stamps) if self.stamps else np.zeros((0, n))) if self.with_stamps else None
        flags = stops = None
        if self.with_saturated:
            flags = np.array(self.saturated) if self.saturated else np.zeros(uv.shape[:3], dtype=bool)
        if self.with_brightness:
            stops = np.array(self.brightness) if self.brightness else np.zeros(uv.shape[:3])
        frames = np.array(self.frames, dtype=np.int64)
        return WandObservations(frames, self.rig.camera_names, uv, stamps, flags, stops)

    def reset(self) -> Path | None:
        """Move the file to a new timestamped backup (one never replaces another) and start empty. The take's
        history beside it (:data:`SIBLINGS`: its floor frames, estimates and events) is moved aside with it.

        Returns:
            The backup, or None when nothing was stored (the file is only restarted).
        """
        backup = None
        if self.path.exists() and has_rows(self.path):
            backup = move_aside(self.path, "bak")
        for name in SIBLINGS:
            kept = self.path.with_name(name)
            if kept.exists():
                move_aside(kept, "bak")
        self.frames, self.uv, self.stamps, self.saturated, self.brightness = [], [], [], [], []
        self.stats = BufferStats()
        self._cells = np.zeros((len(self.rig.cameras), GRID, GRID), dtype=np.int64)
        self._start_file()
        return backup

    def _start_file(self) -> None:
        with self.path.open("w", newline="", encoding="utf-8") as handle:
            columns = header(self.with_stamps, self.with_saturated, self.with_brightness)
            csv.writer(handle, lineterminator="\n").writerow(columns)
            self._sync(handle.fileno())

    def _cell_index(self, c: int, points: FloatArray) -> NDArray[np.int64]:
        width, height = self.rig.cameras[c].image_size
        return np.clip((points / [width, height] * GRID).astype(np.int64), 0, GRID - 1)

    def _adds_coverage(self, uv: FloatArray, complete: NDArray[np.bool_]) -> bool:
        assert self._cells is not None
        median = np.median(self._cells, axis=(1, 2))
        for c in np.flatnonzero(complete):
            cells = self._cell_index(int(c), uv[c])
            if np.any(self._cells[c, cells[:, 1], cells[:, 0]] < max(median[c], 1)):
                return True
        return False

    def _remember(
        self, frame: int, uv: FloatArray, stamps: FloatArray, saturated: NDArray[np.bool_], brightness: FloatArray
    ) -> None:
        assert self._cells is not None
        self.frames.append(frame)
        self.uv.append(np.asarray(uv, dtype=np.float64))
        self.saturated.append(saturated & np.isfinite(uv[..., 0]))
        self.brightness.append(np.where(np.isfinite(uv[..., 0]), brightness, np.nan))
        self.stamps.append(np.where(np.any(np.isfinite(uv), axis=(1, 2)), stamps, np.nan))
        for c in np.flatnonzero(np.all(np.isfinite(uv), axis=(1, 2))):
            cells = self._cell_index(int(c), uv[c])
            np.add.at(self._cells[c], (cells[:, 1], cells[:, 0]), 1)

    def _append_rows(
        self, frame: int, uv: FloatArray, stamps: FloatArray, saturated: NDArray[np.bool_], brightness: FloatArray
    ) -> None:
        with self.path.open("a", newline="", encoding="utf-8") as handle:
            rows = observation_rows(
                frame,
                self.rig.camera_names,
                uv,
                stamps if self.with_stamps else None,
                saturated if self.with_saturated else None,
                brightness if self.with_brightness else None,
            )
            csv.writer(handle, lineterminator="\n").writerows(rows)
            handle.flush()
            if time.monotonic() - self._synced >= SYNC_INTERVAL_S:
                self._sync(handle.fileno())

    def sync(self) -> None:
        """Write everything appended so far through to the disk (at exit)."""
        if self.path.exists():
            with self.path.open("rb") as handle:
                self._sync(handle.fileno())

    def _sync(self, descriptor: int) -> None:
        os.fsync(descriptor)
        self._synced = time.monotonic()


def has_rows(path: Path) -> bool:
    """Whether the file holds more than a header (a collector that saw no wand leaves just the header)."""
    with path.open("rb") as handle:
        return sum(1 for line, _ in zip(handle, range(2), strict=False) if line.strip()) > 1
