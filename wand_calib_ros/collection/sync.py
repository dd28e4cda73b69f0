"""Grouping of per-camera wand detections into frames by nearest stamps.

Detections (or "no wand") of the rig's cameras arrive one by one, each camera's in
time order: its time line (:mod:`wand_calib_ros.collection.timeline`) placed each one after the one before, and
decided what to do with any image that was not. Hardware-triggered cameras stamp their images identically; free-running
ones expose at their own phase and rate. The rule is the same for both: each
camera's frame period is learned from its own stamps; the camera with the longest
period (the slowest; the first in the rig on a tie) is the **anchor**, and each of its
images opens a frame. Every other camera's image joins the frame whose anchor stamp
is nearest, if it lies within ``tolerance`` (default half the anchor's period); when
two images of one camera compete for a frame, the nearer wins and the other forms a
frame of its own. Should the anchor miss an image (a dropped frame), a frame is
opened at the stamp its rate predicts, once the others have moved ``max_delay`` past it.

A frame is emitted as soon as no later image can change it (identical stamps: when
every camera has reported), or ``max_delay`` after its stamp. Each frame keeps every
view's own stamp, so the calibration places each view at its own instant.
Per camera counters say what could not be grouped: late images (their frame was
emitted already).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.collection.timeline import TimeLines
from wand_calib_ros.core.adjust.timing import frame_period
from wand_calib_ros.core.model.rig import WandObservations

FloatArray = NDArray[np.float64]

#: Stamps a camera's period is learned from (:func:`~wand_calib_ros.core.adjust.timing.frame_period`).
RATE_WINDOW = 30
#: Images per camera before its rate counts for choosing the anchor.
WARMUP_IMAGES = 4
#: An image of another camera joins a frame's anchor up to this fraction of the anchor period away
#: unless a tolerance is given.
HALF = 0.5


@dataclass(frozen=True, eq=False)
class SyncedFrame:
    """One frame: the anchor's image and the nearest image of every other camera.

    Attributes:
        stamp_ns: the frame's stamp (its anchor image's, or the anchor's predicted stamp).
        uv: (C, K, 2) the wand's markers per camera (NaN where a camera saw no wand or did not report).
        reported: (C,) which cameras have an image in the frame.
        stamps_ns: (C,) each reported image's own stamp (0 where not reported).
    """

    stamp_ns: int
    uv: FloatArray
    reported: NDArray[np.bool_]
    stamps_ns: NDArray[np.int64]

    @property
    def stamps_s(self) -> FloatArray:
        """(C,) each view's stamp in seconds (NaN where a camera has no image in the frame)."""
        return np.where(self.reported, self.stamps_ns / 1e9, np.nan)


@dataclass
class SyncStats:
    """Counters of the synchroniser (per camera where a camera's stream is at fault)."""

    frames: int = 0
    complete: int = 0
    late: dict[str, int] = field(default_factory=dict)


@dataclass
class _Slot:
    stamp_ns: int
    uv: FloatArray
    reported: NDArray[np.bool_]
    stamps_ns: NDArray[np.int64]


@dataclass
class _Stream:
    recent: deque[int] = field(default_factory=lambda: deque(maxlen=RATE_WINDOW))
    pending: deque[tuple[int, FloatArray | None]] = field(default_factory=deque)
    phases: deque[int] = field(default_factory=lambda: deque(maxlen=RATE_WINDOW))
    newest: int | None = None
    count: int = 0
    emitted: int | None = None  # the stamp of its newest image emitted in a frame
    period_ns: float | None = None  # the frame period of ``recent`` (None: fewer than three stamps)

    def note(self, stamp_ns: int) -> None:
        """A new image's stamp: the period is learned once per image, not per question about it."""
        self.recent.append(stamp_ns)
        period = frame_period(np.asarray(self.recent, dtype=np.float64))
        self.period_ns = period if np.isfinite(period) else None


@dataclass
class FrameSynchroniser:
    """Groups detections of ``cameras`` into frames (see the module docstring).

    Attributes:
        cameras: the rig's camera names.
        tolerance_ns: images further than this from a frame's anchor stamp never join it
            (0: half the anchor's frame period).
        max_delay_ns: how long (in stamp time) a frame waits for a camera that does not report.
        n_points: the wand's markers per view (3: the paper's wand).
    """

    cameras: tuple[str, ...]
    tolerance_ns: int = 0
    max_delay_ns: int = 200_000_000
    n_points: int = 3
    stats: SyncStats = field(default_factory=SyncStats)
    anchor: int | None = None
    _streams: list[_Stream] = field(default_factory=list)
    _slots: deque[_Slot] = field(default_factory=deque)
    _last_slot_ns: int | None = None
    _emitted_until: int | None = None
    _newest: int | None = None
    _held: list[SyncedFrame] = field(default_factory=list)  # single images waiting for older frames to go

    def __post_init__(self) -> None:
        self._streams = [_Stream() for _ in self.cameras]
        self.stats.late.update(dict.fromkeys(self.cameras, 0))

    def period_ns(self, camera: str) -> float | None:
        """A camera's learned frame period (None until it sent three images)."""
        return self._streams[self.cameras.index(camera)].period_ns

    def phase_ns(self, camera: str) -> float | None:
        """Median stamp of a camera's images minus their frames' anchor stamps, over recent frames
        (0 for the anchor; None before it joined a frame)."""
        phases = self._streams[self.cameras.index(camera)].phases
        return float(np.median(np.asarray(phases))) if phases else None

    def add(self, camera: str, stamp_ns: int, points: FloatArray | None) -> list[SyncedFrame]:
        """Add one camera's result; returns the frames it completes (oldest first)."""
        c = self.cameras.index(camera)
        stream = self._streams[c]
        if stream.newest is not None and stamp_ns <= stream.newest:
            raise ValueError(
                f"{camera}: an image stamped {stamp_ns} ns, not after its newest ({stream.newest} ns): place each "
                "image on its camera's time line (TimeLines.place) and add only those it places next"
            )
        stream.newest = stamp_ns
        stream.note(stamp_ns)
        stream.count += 1
        self._newest = stamp_ns if self._newest is None else max(self._newest, stamp_ns)
        if (
            self._emitted_until is not None
            and self.anchor is not None
            and stamp_ns < self._emitted_until - self._tolerance(c)
        ):
            self.stats.late[camera] += 1  # the frames it could have joined are gone
            return []
        stream.pending.append((stamp_ns, points))
        return self._advance(final=False)

    def flush_all(self) -> list[SyncedFrame]:
        """Emit everything still held (end of a recording, shutdown)."""
        if self.anchor is None:
            self._choose_anchor(force=True)
        return self._advance(final=True)

    # -- internals -----------------------------------------------------------------------------

    def _anchor_period(self) -> float:
        assert self.anchor is not None
        period = self._streams[self.anchor].period_ns
        return period if period is not None else 2.0 * self.max_delay_ns

    def _tolerance(self, camera: int) -> float:
        """How far from its frame's anchor stamp an image of ``camera`` may lie: the given tolerance, else
        half the anchor's period or half the camera's own if that is shorter. Its nearest image is never
        further than that, and a camera that lost most of its images, the anchor too, looks slower than it
        is: half of what it seems to take would let the neighbouring frame's image in."""
        if self.tolerance_ns > 0:
            return float(self.tolerance_ns)
        own = self._streams[camera].period_ns
        return HALF * (self._anchor_period() if own is None else min(own, self._anchor_period()))

    def _choose_anchor(self, *, force: bool = False) -> None:
        ready = [s.count >= WARMUP_IMAGES for s in self._streams]
        waited = self._newest is not None and any(
            s.pending and self._newest - s.pending[0][0] > self.max_delay_ns for s in self._streams
        )
        if not (all(ready) or waited or force):
            return
        periods = [s.period_ns for s in self._streams]
        known = [p for p in periods if p is not None]
        if not known:
            candidates = [i for i, s in enumerate(self._streams) if s.count]
            if not candidates:
                return
            self.anchor = max(candidates, key=lambda i: (self._streams[i].count, -i))
            return
        longest = max(known)
        self.anchor = next(i for i, p in enumerate(periods) if p is not None and p >= 0.99 * longest)

    def _open_slots(self, final: bool) -> None:
        """Anchor images become frames; where the anchor is silent, other cameras' images get frames at
        the anchor's predicted stamps (once an anchor image after them arrived, or ``max_delay`` passed)."""
        assert self.anchor is not None
        anchor = self._streams[self.anchor]
        period = self._anchor_period()
        while anchor.pending:
            stamp, points = anchor.pending[0]
            self._predict_slots(stamp - HALF * period, period)  # the anchor dropped images before this one
            anchor.pending.popleft()
            slot = self._slot_for_anchor(stamp, period)
            slot.reported[self.anchor] = True
            slot.stamps_ns[self.anchor] = stamp
            if points is not None:
                slot.uv[self.anchor] = points
        if self._newest is not None:
            self._predict_slots(self._newest - (0 if final else self.max_delay_ns), period)

    def _predict_slots(self, until_ns: float, period: float) -> None:
        """Frames at the anchor's predicted stamps nearest to the other cameras' waiting images before
        ``until_ns`` (one per image at most: a long silence costs nothing)."""
        if self._last_slot_ns is None:
            return
        waiting = sorted(
            stamp for c, s in enumerate(self._streams) if c != self.anchor for stamp, _ in s.pending if stamp < until_ns
        )
        for stamp in waiting:
            steps = round((stamp - self._last_slot_ns) / period)
            if steps >= 1 and self._last_slot_ns + steps * period < until_ns:
                self._new_slot(round(self._last_slot_ns + steps * period))

    def _slot_for_anchor(self, stamp_ns: int, period: float) -> _Slot:
        """The frame an anchor image opens; an anchor image older than frames already opened for the
        other cameras' waiting images (its delivery lagged behind theirs) fills the predicted frame it
        belongs to, or a frame of its own in stamp order."""
        if self._last_slot_ns is None or stamp_ns > self._last_slot_ns:
            return self._new_slot(stamp_ns)
        near = min(self._slots, key=lambda s: abs(s.stamp_ns - stamp_ns), default=None)
        if near is not None and not near.reported[self.anchor] and abs(near.stamp_ns - stamp_ns) <= HALF * period:
            return near
        return self._new_slot(stamp_ns)

    def _new_slot(self, stamp_ns: int) -> _Slot:
        """A new frame at ``stamp_ns``, kept in stamp order among those not yet emitted."""
        n = len(self.cameras)
        slot = _Slot(
            stamp_ns, np.full((n, self.n_points, 2), np.nan), np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int64)
        )
        if self._slots and stamp_ns < self._slots[-1].stamp_ns:
            index = sum(s.stamp_ns <= stamp_ns for s in self._slots)
            self._slots.insert(index, slot)
        else:
            self._slots.append(slot)
        self._last_slot_ns = stamp_ns if self._last_slot_ns is None else max(self._last_slot_ns, stamp_ns)
        return slot

    def _assign(self, final: bool) -> list[SyncedFrame]:
        """Give each pending image of the other cameras to its nearest frame; returns the images left alone."""
        singles: list[SyncedFrame] = []
        half = HALF * self._anchor_period()
        for c, stream in enumerate(self._streams):
            if c == self.anchor:
                continue
            tolerance = self._tolerance(c)
            while stream.pending:
                stamp, points = stream.pending[0]
                slot = self._nearest_slot(stamp)
                last = self._last_slot_ns
                if slot is None or last is None:
                    if final:
                        stream.pending.popleft()
                        singles.append(self._single(c, stamp, points))
                        continue
                    break
                if stamp > last + half and not final:
                    break  # the anchor's next image may be nearer: wait for it
                stream.pending.popleft()
                distance = abs(stamp - slot.stamp_ns)
                if distance > tolerance:
                    singles.append(self._single(c, stamp, points))
                    continue
                if slot.reported[c]:
                    if abs(slot.stamps_ns[c] - slot.stamp_ns) <= distance:
                        singles.append(self._single(c, stamp, points))
                        continue
                    singles.append(self._single(c, int(slot.stamps_ns[c]), slot.uv[c].copy()))
                slot.reported[c] = True
                slot.stamps_ns[c] = stamp
                slot.uv[c] = np.nan if points is None else points
        return singles

    def _nearest_slot(self, stamp: int) -> _Slot | None:
        if not self._slots:
            return None
        return min(self._slots, key=lambda s: abs(s.stamp_ns - stamp))

    def _single(self, c: int, stamp: int, points: FloatArray | None) -> SyncedFrame:
        n = len(self.cameras)
        uv = np.full((n, self.n_points, 2), np.nan)
        if points is not None:
            uv[c] = points
        reported = np.zeros(n, dtype=bool)
        reported[c] = True
        stamps = np.zeros(n, dtype=np.int64)
        stamps[c] = stamp
        return SyncedFrame(stamp, uv, reported, stamps)

    def _settled(self, slot: _Slot) -> bool:
        """Whether no image still to come can join or replace one in this frame."""
        assert self._newest is not None
        if self._newest - slot.stamp_ns > self.max_delay_ns:
            return True
        for c, stream in enumerate(self._streams):
            tolerance = self._tolerance(c)
            if c == self.anchor or (stream.newest is not None and stream.newest >= slot.stamp_ns + tolerance):
                continue
            if stream.pending and stream.pending[0][0] <= slot.stamp_ns + tolerance:
                return False  # an image of it waits to be assigned
            period = stream.period_ns
            if not slot.reported[c] or period is None or stream.newest is None:
                return False
            distance = abs(int(slot.stamps_ns[c]) - slot.stamp_ns)
            if stream.newest + 0.9 * period - slot.stamp_ns <= distance:
                return False  # its next image may be nearer
        return True

    def _advance(self, *, final: bool) -> list[SyncedFrame]:
        if self.anchor is None:
            self._choose_anchor()
            if self.anchor is None:
                return []
        self._open_slots(final)
        # Frames leave in stamp order: an image alone in its frame waits for the older frames, else a
        # camera's stamps could go backwards from one stored frame to the next (lossy transports).
        self._held = sorted([*self._held, *self._assign(final)], key=lambda f: f.stamp_ns)
        out: list[SyncedFrame] = []
        while self._slots and (final or self._settled(self._slots[0])):
            slot = self._slots.popleft()
            out += self._release_held(before_ns=slot.stamp_ns)
            if slot.reported[self.anchor]:
                for c in np.flatnonzero(slot.reported):
                    self._streams[c].phases.append(int(slot.stamps_ns[c]) - slot.stamp_ns)
            out.append(SyncedFrame(slot.stamp_ns, slot.uv, slot.reported, slot.stamps_ns))
            self._emitted_until = slot.stamp_ns
        out += self._release_held(before_ns=self._slots[0].stamp_ns if self._slots else None)
        return [frame for frame in out if self._in_order(frame)]

    def _release_held(self, before_ns: int | None) -> list[SyncedFrame]:
        """The held single images not newer than ``before_ns`` (None: all)."""
        count = len(self._held) if before_ns is None else sum(f.stamp_ns <= before_ns for f in self._held)
        released, self._held = self._held[:count], self._held[count:]
        return released

    def _in_order(self, frame: SyncedFrame) -> bool:
        """Count an emitted frame; a view not newer than its camera's last emitted one (a rare grouping on a
        lossy transport) is taken out of it and counted late, so that no camera's stamps ever go backwards
        from frame to frame. False when nothing is left of the frame."""
        for c in np.flatnonzero(frame.reported):
            stream = self._streams[c]
            stamp = int(frame.stamps_ns[c])
            if stream.emitted is not None and stamp <= stream.emitted:
                frame.reported[c] = False
                frame.uv[c] = np.nan
                self.stats.late[self.cameras[c]] += 1
            else:
                stream.emitted = stamp
        if not frame.reported.any():
            return False
        self.stats.frames += 1
        self.stats.complete += int(frame.reported.all())
        return True


def group_by_stamps(
    cameras: tuple[str, ...],
    detections: Iterable[tuple[str, int, FloatArray | None]],
    tolerance_ns: int = 0,
    n_points: int = 3,
) -> list[SyncedFrame]:
    """The frames of a whole recording: its (camera, stamp_ns, points) detections through a
    :class:`FrameSynchroniser` in stamp order, sorted by frame stamp (a camera's repeated stamp: its first)."""
    sync = FrameSynchroniser(cameras, tolerance_ns=tolerance_ns, max_delay_ns=10**18, n_points=n_points)
    timelines = TimeLines(cameras)
    frames: list[SyncedFrame] = []
    for camera, stamp, points in sorted(detections, key=lambda d: d[1]):
        if timelines.place(camera, stamp, None).order == "next":
            frames += sync.add(camera, stamp, points)
    frames += sync.flush_all()
    return sorted(frames, key=lambda f: f.stamp_ns)


def frames_to_observations(frames: list[SyncedFrame], cameras: tuple[str, ...], n_points: int = 3) -> WandObservations:
    """Observations of grouped frames: frame ids are their indices, each view with its image's stamp (s);
    frames in which no camera saw the wand are left out."""
    if not frames:
        return WandObservations(np.zeros(0, dtype=np.int64), cameras, np.zeros((0, len(cameras), n_points, 2)))
    uv = np.stack([f.uv for f in frames])
    seen = np.stack([f.reported for f in frames]) & np.any(np.isfinite(uv), axis=(2, 3))
    stamps = np.where(seen, np.stack([f.stamps_ns for f in frames]) / 1e9, np.nan)
    keep = seen.any(axis=1)
    return WandObservations(np.flatnonzero(keep), cameras, uv[keep], stamps[keep])
