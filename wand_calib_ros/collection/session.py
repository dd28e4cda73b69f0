"""A live collection without ROS: images (or a detector's points) in, a coverage-checked persisted buffer out.

The collector node hands every message to a :class:`CollectionSession` as ``(camera, stamp, arrival, pixels or
points)`` and does what it answers: the lines to log, the pictures and values to publish. The session owns the
collection:

- each camera's detector (:class:`~wand_calib_ros.detection.recording.CameraStream`) and its stream's faults
  and time line (:class:`~wand_calib_ros.collection.stream_faults.StreamFaults`);
- the synchroniser that forms frames (:mod:`~wand_calib_ros.collection.sync`), the persisted buffer they are
  offered to (:mod:`~wand_calib_ros.collection.buffer`), with the saturation flags of their views, and the
  coverage they add (:mod:`~wand_calib_ros.collection.coverage`);
- the floor's lays, the running estimate (:mod:`~wand_calib_ros.collection.estimate`), auto_calibrate
  (:mod:`~wand_calib_ros.collection.auto_calibrate`), the bump watch after a calibration
  (:mod:`~wand_calib_ros.collection.watch`), and what has been said.

An image's stamp goes node -> session -> detector and back once. Every method may be called from any thread:
the collector's executor calls the message and feedback methods, the calibrator's the flush and the result.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.collection.auto_calibrate import AutoCalibrate
from wand_calib_ros.collection.buffer import BUFFER_FILE, ObservationBuffer
from wand_calib_ros.collection.coverage import CoverageStatus, CoverageThresholds, CoverageTracker
from wand_calib_ros.collection.estimate import Estimate, RunningEstimate
from wand_calib_ros.collection.feedback import estimate_values, timing_values
from wand_calib_ros.collection.floor import FLOOR_FILE, FloorWindow, append_floor_frame
from wand_calib_ros.collection.live_clocks import LiveClocks
from wand_calib_ros.collection.lock import CollectionLock
from wand_calib_ros.collection.stream_faults import Said, SaidOnce, StreamFaults, image_problem
from wand_calib_ros.collection.sync import FrameSynchroniser, SyncedFrame
from wand_calib_ros.collection.timeline import Placed
from wand_calib_ros.collection.watch import BumpWatch
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.core.pipeline import CalibrationOptions
from wand_calib_ros.detection.blobs import Blobs
from wand_calib_ros.detection.health import save_what_cameras_saw
from wand_calib_ros.detection.masks import Mask, mask_of, read_mask, write_mask
from wand_calib_ros.detection.overlay import draw_overlay
from wand_calib_ros.detection.recording import CameraStream, Labelled
from wand_calib_ros.detection.wand import WandDetection, WandOptions
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.detection_summary import masks_folder
from wand_calib_ros.io.rig_yaml import MaskSpec
from wand_calib_ros.io.session_csv import ESTIMATES_FILE, EVENTS_FILE, append_estimate, append_event

#: The detections picture of a camera is drawn at most once per this many seconds.
OVERLAY_PERIOD_S = 0.5
#: observations.detection.yaml is written again at most once per this many seconds.
SUMMARY_PERIOD_S = 10.0
#: Released views' saturation flags held for their frames at most (a view no frame took is forgotten after them).
MAX_HELD_FLAGS = 10_000
#: While coverage is not ready, what is still missing is said again after this many seconds.
PROGRESS_PERIOD_S = 10.0
#: Frames may wait this long (ns) beyond the label hold for a late camera.
SYNC_DELAY_NS = 500_000_000

#: The calibrator's entry for auto_calibrate: (who asks, called when done with (success, answer)) -> started.
CalibrateNow = Callable[[str, Callable[[bool, str], None]], bool]
#: Diagnostics values per camera.
Values = dict[str, dict[str, int | str]]


@dataclass(frozen=True)
class SessionSettings:
    """A live collection's settings (the collector's parameters).

    Attributes:
        capacity: frames stored before only coverage-adding frames are kept.
        min_motion_px: a frame whose wand moved less than this in every camera is skipped.
        measure_brightness: the session's own detector measures the spots (images in, not a detector's points).
        sync_tolerance_ns: images further apart than this never form a frame (0: half the frame period).
        label_hold_ns: how long a camera's views wait for their A/C labels.
        floor_hold_s: after each /set_floor, frames of this long are floor frames.
        mask_take_ns: /take_mask takes each camera's mask from this long of images.
        coverage: when the buffer is ready to calibrate.
        estimate_period_s: seconds between the running estimate's rounds (None: no running estimate).
        estimate_max_placements: placements one round calibrates at most.
        auto: auto_calibrate's focal-length (%) and principal-point (px) standard deviations (None: off).
    """

    capacity: int
    min_motion_px: float
    measure_brightness: bool
    sync_tolerance_ns: int
    label_hold_ns: int
    floor_hold_s: float
    mask_take_ns: int
    coverage: CoverageThresholds
    estimate_period_s: float | None
    estimate_max_placements: int
    auto: tuple[float, float] | None


@dataclass(frozen=True, eq=False)
class ImageAnswer:
    """What an image gave.

    Attributes:
        stamp_ns: its stamp on its camera's time line.
        said: the lines to log.
        picture: its detections drawn (bgr8) when asked for and due, else None.
    """

    stamp_ns: int
    said: tuple[Said, ...]
    picture: NDArray[np.uint8] | None


@dataclass(frozen=True, eq=False)
class Feedback:
    """What the collection shows now (once a second).

    Attributes:
        said: the lines to log.
        status: the coverage.
        counts: per camera its diagnostics values.
        rig_values: the rig's diagnostics values.
        moved: per camera that moved since the last calibration, what to say.
        notes: per camera its detector's warnings.
        faults: per camera its stream's faults.
        cells: per camera its coverage cells (a heat map).
        estimate: a running estimate's new round to publish, or None.
    """

    said: tuple[Said, ...]
    status: CoverageStatus
    counts: Values
    rig_values: dict[str, int | str]
    moved: dict[str, str]
    notes: dict[str, list[str]]
    faults: dict[str, list[str]]
    cells: dict[str, NDArray[np.int64]]
    estimate: Estimate | None


class CollectionSession:
    """One rig's live collection into ``output_dir`` (see the module docstring).

    Args:
        rig: the rig description.
        settings: the collection's settings.
        output_dir: the folder of the buffer (held by this session alone while it runs).
        masks: per camera the rig file's ``mask``.
        topics: per camera the topic its messages come from (named in what is said of its faults).
    """

    def __init__(
        self,
        rig: RigSpec,
        settings: SessionSettings,
        output_dir: Path,
        masks: Mapping[str, MaskSpec],
        topics: Mapping[str, str],
    ) -> None:
        self.rig, self.settings = rig, settings
        self.hold = CollectionLock(output_dir)  # one writer per folder
        self.buffer = ObservationBuffer.open(
            output_dir / BUFFER_FILE,
            rig,
            capacity=settings.capacity,
            min_motion_px=settings.min_motion_px,
            with_brightness=settings.measure_brightness,
        )
        self.coverage = CoverageTracker(rig, settings.coverage)
        self.coverage.add(self.buffer.observations().uv)  # the frames a restart found in the buffer file
        self.sync = self._synchroniser()
        wand, given = WandOptions.for_rig(rig), self._given_masks(masks)
        self.streams = {
            c.name: CameraStream(c, wand, max_hold_ns=settings.label_hold_ns, mask=given.get(c.name))
            for c in rig.cameras
        }
        self.faults = StreamFaults(rig.camera_names, topics)  # silences, stamp jumps, unusable images, drops
        self.clocks = LiveClocks(rig)  # clocks seconds apart, lined up from the wand
        self.floor = FloorWindow(settings.floor_hold_s)
        self.estimates: RunningEstimate | None = None
        if settings.estimate_period_s is not None:
            period_s, most = settings.estimate_period_s, settings.estimate_max_placements
            self.estimates = RunningEstimate(rig, CalibrationOptions(), period_s=period_s, max_placements=most)
        self.auto = None if settings.auto is None else AutoCalibrate(*settings.auto)
        self.calibrate_now: CalibrateNow | None = None  #: the in-process calibrator's, for auto_calibrate
        self.timing: CalibrationResult | None = None  #: the last calibration's result (its time offsets)
        self.watch: BumpWatch | None = None  #: after a calibration: is a camera moving away from it?
        self.calibrated = False  #: a final calibration since the start or the last /reset: estimates stop
        self.take = 0  #: counted up by each /reset (a calibration of a cleared take is not this one's)
        self.received = dict.fromkeys(rig.camera_names, 0)  #: messages per camera
        self.malformed = dict.fromkeys(rig.camera_names, 0)  #: detector points that could not be read
        self._brightness: dict[tuple[str, int], NDArray[np.float64]] = {}  # released views' brightness, until stored
        self._said = SaidOnce()
        self._moved_said: dict[str, str] = {}
        self._shown = dict.fromkeys(rig.camera_names, 0.0)  # when each camera's overlay was last drawn
        self._summary_saved = 0.0  # when observations.detection.yaml was last written (monotonic)
        self._summary_images = 0  # messages received by then
        self._progress: tuple[bool, float] | None = None  # (ready, when) of the last progress line
        self._lock = threading.Lock()

    def _synchroniser(self) -> FrameSynchroniser:
        """A new synchroniser of the rig's frames (a take's)."""
        return FrameSynchroniser(
            self.rig.camera_names,
            tolerance_ns=self.settings.sync_tolerance_ns,
            max_delay_ns=self.settings.label_hold_ns + SYNC_DELAY_NS,
            n_points=self.rig.wand.n_points,
        )

    def opening(self, source: str) -> tuple[Said, ...]:
        """What to say once the collection runs, its messages coming from ``source``."""
        said = []
        if self.buffer.repaired is not None:
            said.append(Said("warning", self.buffer.repaired.describe(self.buffer.path)))
        said.append(
            Said(
                "info",
                f"collecting {', '.join(self.rig.camera_names)} from {source} into {self.buffer.path} "
                f"({len(self.buffer.frames)} frames resumed)",
            )
        )
        return tuple(said)

    def _given_masks(self, masks: Mapping[str, MaskSpec]) -> dict[str, Mask]:
        """Per camera the rig file's mask and the ones /take_mask took for this collection (kept beside it)."""
        given = {name: mask_of(spec, self.rig.camera(name).image_size) for name, spec in masks.items()}
        for spec in self.rig.cameras:
            taken = self._taken_path(spec.name)
            if taken.is_file():
                mask = read_mask(taken, spec.image_size)
                given[spec.name] = np.maximum(given[spec.name], mask) if spec.name in given else mask
        return given

    def _taken_path(self, camera: str) -> Path:
        return masks_folder(self.buffer.path) / f"{camera}.taken.png"

    # Messages in

    def image(
        self, camera: str, stamp_ns: int, arrival_ns: int, pixels: NDArray[Any] | None, encoding: str, *, show: bool
    ) -> ImageAnswer:
        """An image of ``camera`` (None: its data could not be read) arrived at ``arrival_ns`` (a steady clock):
        placed on its time line, searched for the wand and offered to the frames; with ``show`` its detections
        drawn (at most every OVERLAY_PERIOD_S)."""
        stream = self.streams[camera]
        with self._lock:
            placed, said = self.faults.arrived(camera, stamp_ns, arrival_ns)
            self._note_shift(camera, placed)
            self.clocks.arrived(camera, placed.stamp_ns, arrival_ns)
            taking = stream.taking_mask
            self.received[camera] += 1
            blobs: Blobs | None
            detection: WandDetection | None
            reason: str | None
            if placed.order != "next":  # its time line passed it over: not searched, counted
                blobs, detection, reason = None, None, stream.passed_over(placed.order == "repeat")
            else:
                blobs, detection, reason = stream.detect(pixels, encoding, placed.stamp_ns)
                if reason is not None:
                    size = self.rig.camera(camera).image_size
                    problem = image_problem(reason, None if pixels is None else pixels.shape, encoding, size)
                    said += self.faults.unusable(camera, reason, problem, arrival_ns)
                self._offer(camera, stream.label(placed.stamp_ns, detection, reason))
            taken = stream.taken if taking and not stream.taking_mask else None
        if taken is not None:
            write_mask(self._taken_path(camera), taken)
            said.append(Said("info", f"{camera}: mask taken ({100 * float((taken > 0).mean()):.2f} % of the image)"))
        now, picture = time.monotonic(), None
        if show and pixels is not None and now - self._shown[camera] >= OVERLAY_PERIOD_S:
            self._shown[camera] = now
            picture = draw_overlay(pixels, encoding, blobs, detection, reason, stream.mask)
        return ImageAnswer(placed.stamp_ns, tuple(said), picture)

    def points(self, camera: str, stamp_ns: int, arrival_ns: int, points: NDArray[np.float64] | None) -> list[Said]:
        """A detector's (K, 2) labelled wand points of ``camera`` (None: no wand) arrived: placed on its time line
        and offered to the frames, counted as its own detector counts an image. Returns the lines to log."""
        with self._lock:
            placed, said = self.faults.arrived(camera, stamp_ns, arrival_ns)
            self._note_shift(camera, placed)
            self.clocks.arrived(camera, placed.stamp_ns, arrival_ns)
            self.received[camera] += 1
            stream = self.streams[camera]
            if placed.order != "next":  # its time line passed it over
                stream.passed_over(placed.order == "repeat")
            else:
                stream.stats.images += 1
                if points is None:
                    stream.stats.rejected["no_wand"] += 1
                else:
                    stream.stats.detected += 1
                self._offer(camera, [Labelled(placed.stamp_ns, points)])
        return said

    def _note_shift(self, camera: str, placed: Placed) -> None:
        """A jump of ``camera``'s stamps within the take moves the ones stored after it: kept in events.csv (caller
        holds the lock)."""
        jump = placed.jump
        if jump is None or jump.kind == "unstamped":
            return
        shift = self.faults.timelines.shift_ns(camera) / 1e9
        together = " (every camera's stamps jumped together)" if jump.shared else ""
        line = f"its stamps jumped {jump.jump_s:+.3f} s{together}: stored moved by {shift:+.3f} s to continue the take"
        append_event(self.buffer.path.with_name(EVENTS_FILE), time.time(), "stamps_shifted", camera, line)

    def unreadable_points(self, camera: str) -> None:
        """A detector's message of ``camera`` could not be read."""
        with self._lock:
            self.malformed[camera] += 1

    def _offer(self, camera: str, outcomes: list[Labelled]) -> None:
        """Synchronise released outcomes and store completed frames (caller holds the lock)."""
        for outcome in outcomes:
            self.clocks.keep(camera, outcome.stamp_ns, outcome.points)
            shift = self.clocks.shift_ns(camera)
            if shift is None:  # held: its clock is not lined up yet
                continue
            stamp = outcome.stamp_ns - shift
            if outcome.points is not None and outcome.brightness is not None:
                self._brightness[(camera, stamp)] = outcome.brightness
            self._store(self.sync.add(camera, stamp, outcome.points))

    def _brightness_of(self, frame: SyncedFrame) -> NDArray[np.float64]:
        """(C, K) the brightness of a frame's views' points (NaN: not measured; forgotten once asked: a view is in
        one frame)."""
        stops = np.full(frame.uv.shape[:2], np.nan)
        for c, name in enumerate(self.rig.camera_names):
            found = self._brightness.pop((name, int(frame.stamps_ns[c])), None) if frame.reported[c] else None
            if found is not None and found.shape == stops[c].shape:
                stops[c] = found
        if len(self._brightness) > MAX_HELD_FLAGS:  # (views no frame took: a camera's images dropped late)
            for key in list(self._brightness)[: len(self._brightness) - MAX_HELD_FLAGS]:
                del self._brightness[key]
        return stops

    def _store(self, frames: list[SyncedFrame]) -> None:
        for frame in frames:
            on_floor = self.floor.is_open(time.monotonic())
            if self.watch is not None:
                self.watch.offer(frame.uv)
            stops = self._brightness_of(frame)
            stamps = self.clocks.stored_stamps(frame.stamps_s)  # (each view's own stamp)
            if self.buffer.offer(frame.uv, stamps, keep=on_floor, brightness=stops):
                self.coverage.add(frame.uv)
                if on_floor:
                    append_floor_frame(self.buffer.path.with_name(FLOOR_FILE), self.buffer.frames[-1])

    # The calibrator's

    def flush(self) -> None:
        """Store everything still held (ambiguous views, pending frames): before a calibration, at exit."""
        with self._lock:
            for name, stream in self.streams.items():
                self._offer(name, stream.flush())
            self._store(self.sync.flush_all())

    def snapshot(self) -> WandObservations:
        """The buffer so far (for the running estimate)."""
        with self._lock:
            return self.buffer.observations()

    def after_calibrate(self, result: CalibrationResult) -> None:
        """Keep a calibration's result: its time offsets are shown, and the frames that follow are watched for a
        camera that moved."""
        with self._lock:
            self.timing = result
            if self.watch is not None:
                self.watch.close()
            self.watch = BumpWatch(self.rig, result)
            self._moved_said = {}
            self.calibrated = True

    def auto_done(self, success: bool, message: str) -> None:
        """auto_calibrate's calibration ended (the calibrator's thread)."""
        if self.auto is not None:
            self.auto.done(success, message)

    def close(self) -> None:
        """At exit: store what is held and write the buffer and what the cameras saw through to the disk."""
        self.flush()
        if sum(self.received.values()) != self._summary_images:
            self._save_what_cameras_saw()
        with self._lock:
            self.buffer.sync()
            if self.watch is not None:
                self.watch.close()
        if self.estimates is not None:
            self.estimates.close()
        self.hold.release()

    # Services

    def reset(self) -> str:
        """/reset: the buffer (with what was still held, and its history beside it) moved to a backup, a new take
        begun: new frames, the cameras' time lines started again (a take keeps its images' own stamps); what to
        answer."""
        with self._lock:  # serialised with the frames being stored and with other resets
            for name, stream in self.streams.items():  # what the old take still held goes into its buffer
                self._offer(name, stream.flush())
            self._store(self.sync.flush_all())
            backup = self.buffer.reset()
            self.sync = self._synchroniser()
            self.faults.timelines.restart()  # the new take's images keep their own stamps
            self.clocks.restart()
            self._brightness.clear()
            self.floor.lays = 0
            self.take += 1
            self.coverage = CoverageTracker(self.rig, self.coverage.thresholds)
            self.calibrated = False
            if self.auto is not None:
                self.auto.reset()
        if self.estimates is not None:  # the next round starts cold on the new buffer
            self.estimates.restart()
        return f"buffer cleared; {'it was empty' if backup is None else f'backup {backup}'}"

    def set_floor(self) -> str:
        """/set_floor: the frames of the next ``floor_hold_s`` are a lay of the wand on the floor; what to answer."""
        with self._lock:
            lay = self.floor.open(time.monotonic())
        after = "call /set_floor again with the wand in a second direction" if lay == 1 else "then /calibrate"
        return (
            f"floor lay {lay}: hold the wand still on the floor for {self.floor.hold_s:g} s; {after} "
            "(the world frame: z up, the origin at the first lay's A, x along its A->C)"
        )

    def take_mask(self) -> str:
        """/take_mask: each camera's mask from its next images; what to answer."""
        with self._lock:
            for stream in self.streams.values():
                stream.take_mask(self.settings.mask_take_ns)
        return (
            f"taking each camera's mask from its next {self.settings.mask_take_ns / 1e9:g} s of images: keep the "
            f"wand out of sight; the lights in them are ignored from then on (kept in {masks_folder(self.buffer.path)})"
        )

    # Feedback

    def feedback(self, arrival_ns: int) -> Feedback:
        """What to show and say now (``arrival_ns`` on the clock messages arrive by): coverage, the cameras' figures
        and faults, the running estimate (and auto_calibrate), a camera that moved, and the progress line."""
        with self._lock:
            status, counts, rig_values = self.coverage.status(), self._counts(), self._rig_values()
            cells = {name: self.coverage.cells[c].copy() for c, name in enumerate(self.rig.camera_names)}
            watch = self.watch
            faults, said = self.faults.check(arrival_ns)
            said += self.clocks.step(arrival_ns)
        now = time.monotonic()
        notes = self._detection_feedback(counts, said)
        estimate = self._estimate_feedback(now, status.ready, counts, rig_values, said)
        moved = {} if watch is None else self._moved(watch, said)
        said += self._progress_lines(status, faults, rig_values, now)
        return Feedback(tuple(said), status, counts, rig_values, moved, notes, faults, cells, estimate)

    def _counts(self) -> Values:
        """Each camera's diagnostics values (caller holds the lock)."""
        counts: Values = {}
        for name, stream in self.streams.items():
            counts[name] = {"received": self.received[name], "wand_labelled": stream.stats.detected}
            counts[name] |= {f"rejected_{reason}": n for reason, n in sorted(stream.stats.rejected.items())}
            if self.malformed[name]:
                counts[name]["malformed_points"] = self.malformed[name]
            counts[name] |= timing_values(self.sync, name, self.timing)
            counts[name] |= self.faults.values(name)
            counts[name] |= self.clocks.values(name)
        return counts

    def _rig_values(self) -> dict[str, int | str]:
        """The rig's diagnostics values (caller holds the lock)."""
        sync, stored = self.sync.stats, self.buffer.stats
        behind, repeats = self.faults.timelines.totals()
        return {
            "frames_stored": len(self.buffer.frames),
            "frames_synchronised": sync.frames,
            "frames_all_cameras": sync.complete,
            "frames_anchored_by": "-" if self.sync.anchor is None else self.rig.camera_names[self.sync.anchor],
            "late_messages": sum(sync.late.values()),
            "out_of_order_messages": behind,
            "duplicate_messages": repeats,
            "skipped_still": stored.still,
            "skipped_buffer_full": stored.full,
            "without_wand": stored.empty,
        }

    def _detection_feedback(self, counts: Values, said: list[Said]) -> dict[str, list[str]]:
        """Each camera's detection figures into its ``counts``, its warnings (said once per cause) and the summary
        written now and then; returns the warnings per camera."""
        notes: dict[str, list[str]] = {}
        with self._lock:
            reports = {name: stream.report() for name, stream in self.streams.items()}
        for name, report in reports.items():
            values = report.as_dict()
            shown: dict[str, int | str] = {
                "static_lights": len(report.sources),
                "masked_percent": f"{100 * report.masked_fraction:.2f}",
            }
            shown |= {key: f"{values[key]:g}" for key in ("saturated", "dim", "streak_median_px") if key in values}
            counts.setdefault(name, {}).update(shown)
            warnings = report.warnings()
            notes[name] = list(warnings.values())
            said += [Said("warning", line) for cause, line in warnings.items() if self._said.first(name, cause)]
        received = sum(self.received.values())
        if received != self._summary_images and time.monotonic() - self._summary_saved >= SUMMARY_PERIOD_S:
            said += self._save_what_cameras_saw()  # on news only: a resumed collection's summary stays until images
        return notes

    def _save_what_cameras_saw(self) -> list[Said]:
        """Each camera's detection report and mask beside the buffer (observations.detection.yaml, .masks/)."""
        with self._lock:
            reports = {name: stream.report() for name, stream in self.streams.items()}
            masks = {name: stream.mask for name, stream in self.streams.items()}
            self._summary_images = sum(self.received.values())
        try:
            save_what_cameras_saw(self.buffer.path, reports, masks)
        except WandCalibError as error:
            line = f"cannot keep what the cameras saw: {error}"
            return [Said("warning", line)] if self._said.first("", line) else []  # (each cause once)
        finally:
            self._summary_saved = time.monotonic()
        return []

    def _estimate_feedback(
        self, now: float, ready: bool, counts: Values, rig_values: dict[str, int | str], said: list[Said]
    ) -> Estimate | None:
        """Step the running estimate (noting a new round in its history), add its diagnostics values, and start
        auto_calibrate when its conditions hold. Returns a new round to publish, or None."""
        arrived = None
        if self.estimates is not None and not self.calibrated:
            arrived = self.estimates.step(now, self.snapshot)
            if arrived is not None and arrived.round.result is not None:
                history = self.buffer.path.with_name(ESTIMATES_FILE)
                append_estimate(history, time.time(), arrived.round.frames, arrived.round.result)
            else:
                arrived = None
            per_camera, estimate_rig = estimate_values(self.estimates.latest, self.estimates.failure, now)
            for name, values in per_camera.items():
                counts.setdefault(name, {}).update(values)
            rig_values |= estimate_rig
        if self.auto is None:
            return arrived
        latest = self.estimates.latest if self.estimates is not None else None
        start = self.calibrate_now
        due = start is not None and latest is not None and self.auto.due(ready, latest, self.calibrated)
        if due and start is not None and latest is not None and start("auto-calibrate", self.auto_done):
            said.append(Said("info", self.auto.started(latest)))  # (the calibrator may have refused: busy)
        shown = self.auto.shown(self.calibrated)
        if shown is not None:
            rig_values["auto_calibrate"] = shown
        return arrived

    def _moved(self, watch: BumpWatch, said: list[Said]) -> dict[str, str]:
        """The bump watch stepped: per camera that moved, what to say (once, and kept in events.csv)."""
        watch.step()
        moved = watch.moved()
        for name, line in sorted(moved.items()):
            if line in self._moved_said.values():
                continue
            said.append(Said("warning", f"{line}: call /refine to re-estimate it, or /reset, wave and /calibrate"))
            append_event(self.buffer.path.with_name(EVENTS_FILE), time.time(), "moved", name, line)
        self._moved_said = moved
        return moved

    def _progress_lines(
        self, status: CoverageStatus, faults: dict[str, list[str]], rig_values: dict[str, int | str], now: float
    ) -> list[Said]:
        """Whether the take is ready to calibrate, said when that changes, and what is still missing every
        PROGRESS_PERIOD_S."""
        ready = status.ready
        said_before = self._progress
        if said_before is not None and said_before[0] == ready and (ready or now - said_before[1] <= PROGRESS_PERIOD_S):
            return []
        self._progress = (ready, now)
        faulty = [f"{name}: {'; '.join(lines)}" for name, lines in faults.items() if lines]
        frames = rig_values["frames_stored"]
        if ready and faulty:
            return [Said("info", f"ready to calibrate ({frames} frames), but " + " | ".join(faulty))]
        if ready:
            return [Said("info", f"ready to calibrate ({frames} frames): call /calibrate")]
        return [Said("info", f"still missing: {line}") for line in status.progress()]
