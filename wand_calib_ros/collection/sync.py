"""Approximate time synchronisation of per-camera wand detections into frames.

Detections (or "no wand") of the rig's cameras arrive one by one. Those whose
stamps lie within ``slop_ns`` of a pending frame's first stamp join it; a
frame is emitted as soon as every camera has reported (identical stamps of
hardware-triggered cameras are the fast path), or when a detection arrives
more than ``max_delay_ns`` after it. Detections for frames already emitted are
counted as late; stamps older than the newest seen as out of order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SyncedFrame:
    """One synchronised frame.

    Attributes:
        stamp_ns: stamp of its first detection.
        uv: (C, 3, 2) A, B, C per camera (NaN where a camera saw no wand or did not report).
        reported: (C,) which cameras reported.
    """

    stamp_ns: int
    uv: FloatArray
    reported: NDArray[np.bool_]


@dataclass
class SyncStats:
    """Counters of the synchroniser."""

    frames: int = 0
    complete: int = 0
    late: int = 0
    out_of_order: int = 0
    duplicates: int = 0


@dataclass
class _Pending:
    stamp_ns: int
    uv: FloatArray
    reported: NDArray[np.bool_]


@dataclass
class FrameSynchroniser:
    """Groups detections of ``cameras`` into frames (see the module docstring)."""

    cameras: tuple[str, ...]
    slop_ns: int = 5_000_000
    max_delay_ns: int = 200_000_000
    stats: SyncStats = field(default_factory=SyncStats)
    _pending: list[_Pending] = field(default_factory=list)
    _newest: int = -(2**62)
    _emitted_until: int = -(2**62)

    def add(self, camera: str, stamp_ns: int, points: FloatArray | None) -> list[SyncedFrame]:
        """Add one camera's result; returns the frames completed by it (oldest first)."""
        c = self.cameras.index(camera)
        if stamp_ns < self._newest:
            self.stats.out_of_order += 1
        self._newest = max(self._newest, stamp_ns)
        target = next((p for p in self._pending if abs(stamp_ns - p.stamp_ns) <= self.slop_ns), None)
        if target is None and stamp_ns <= self._emitted_until + self.slop_ns:
            self.stats.late += 1  # its frame has been emitted already
            return self._flush(stamp_ns)
        if target is None:
            target = _Pending(stamp_ns, np.full((len(self.cameras), 3, 2), np.nan), np.zeros(len(self.cameras), bool))
            self._pending.append(target)
            self._pending.sort(key=lambda p: p.stamp_ns)
        if target.reported[c]:
            self.stats.duplicates += 1
        else:
            target.reported[c] = True
            if points is not None:
                target.uv[c] = points
        return self._flush(stamp_ns)

    def flush_all(self) -> list[SyncedFrame]:
        """Emit every pending frame (end of a recording, shutdown)."""
        out = [self._emit(p) for p in self._pending]
        self._pending = []
        return out

    def _flush(self, now_ns: int) -> list[SyncedFrame]:
        ready = [p for p in self._pending if p.reported.all() or now_ns - p.stamp_ns > self.max_delay_ns]
        self._pending = [p for p in self._pending if not (p.reported.all() or now_ns - p.stamp_ns > self.max_delay_ns)]
        return [self._emit(p) for p in ready]

    def _emit(self, pending: _Pending) -> SyncedFrame:
        self.stats.frames += 1
        self.stats.complete += int(pending.reported.all())
        self._emitted_until = max(self._emitted_until, pending.stamp_ns)
        return SyncedFrame(pending.stamp_ns, pending.uv, pending.reported)
