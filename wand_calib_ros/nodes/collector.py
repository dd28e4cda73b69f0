"""The collector node: images (or detector points) in, a coverage-checked persisted buffer out.

Per camera it subscribes either to the image topic (sensor-data QoS by default; raw, or
image_transport's ``<topic>/compressed``: ``image_transport``) and runs the LED detector itself, or
to a detector node's wand points (``input: points``). What each camera sees (static lights masked,
LEDs saturating, too dim or streaking, images without a view and why) is in /diagnostics, said
once per cause as a warning, and kept beside the buffer (``observations.detection.yaml``, the
masks in ``observations.masks/``); ``wand_calib/<cam>/detections`` shows an image with the
detections drawn (2 Hz, while subscribed). ``/take_mask`` takes each camera's mask from the next
``mask_take_s`` of images, the wand out of sight. Results are time-synchronised into frames, offered to the
persisted :class:`ObservationBuffer` and counted by the :class:`CoverageTracker`;
``/diagnostics`` (1 Hz), a coverage heat map per camera
(``wand_calib/<cam>/coverage``) and log lines on every change of what is
missing tell the person waving the wand what to do. ``/reset`` clears the
buffer after backing it up.

While waving, a running estimate (``running_estimate``) calibrates the buffer so far every
``estimate_period_s`` in a worker process (:mod:`wand_calib_ros.collection.estimate`): /diagnostics
shows per camera its image error, focal and principal-point uncertainty and whether they still fall,
and its preliminary results go to ``wand_calib/preliminary/<cam>/camera_info``,
``wand_calib/preliminary/<cam>/extrinsics`` and ``wand_calib/preliminary/markers``, never to the final
topics. With ``auto_calibrate`` the final calibration starts by itself once coverage is ready and every
camera's uncertainties are below ``auto_focal_std_percent`` and ``auto_principal_std_px``. After a
calibration the estimates stop (until ``/reset``) and the bump watch takes over.

``ros2 run wand_calib_ros collector`` also starts the calibrator node in the
same process (``with_calibrator``), so a ``/calibrate`` call is the whole
workflow. Only message and parameter translation lives here.
"""

from __future__ import annotations

import functools
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PolygonStamped, TransformStamped
from numpy.typing import NDArray
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from wand_calib_ros.collection.buffer import BUFFER_FILE, ObservationBuffer
from wand_calib_ros.collection.coverage import CoverageTracker
from wand_calib_ros.collection.estimate import MAX_PLACEMENTS, Estimate, RunningEstimate, converged
from wand_calib_ros.collection.floor import FLOOR_FILE, FloorWindow, append_floor_frame
from wand_calib_ros.collection.lock import CollectionLock
from wand_calib_ros.collection.recovery import move_aside
from wand_calib_ros.collection.stream_faults import Said, StreamFaults, image_problem
from wand_calib_ros.collection.sync import FrameSynchroniser, SyncedFrame
from wand_calib_ros.collection.watch import BumpWatch
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import CalibrationOptions
from wand_calib_ros.detection.blobs import Blobs
from wand_calib_ros.detection.health import save_what_cameras_saw
from wand_calib_ros.detection.masks import Mask, mask_of, read_mask, write_mask
from wand_calib_ros.detection.overlay import draw_overlay
from wand_calib_ros.detection.recording import CameraStream, Labelled
from wand_calib_ros.detection.wand import WandDetection, WandOptions
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.detection_summary import masks_folder
from wand_calib_ros.io.rig_yaml import load_camera_endpoints, load_camera_masks, load_rig
from wand_calib_ros.io.session_csv import ESTIMATES_FILE, EVENTS_FILE, append_estimate, append_event
from wand_calib_ros.nodes import messages
from wand_calib_ros.nodes.images import IMAGE_TRANSPORT, CameraImages
from wand_calib_ros.nodes.markers import markers_message
from wand_calib_ros.nodes.params import (
    COVERAGE,
    IMAGE_QOS,
    LABEL_HOLD,
    LATCHED,
    RIG,
    Param,
    coverage_thresholds,
    declare,
    existing_file,
    image_qos,
    usage,
)
from wand_calib_ros.nodes.runner import run, second_node_arguments

PARAMS = (
    *RIG,
    *COVERAGE,
    Param(
        "input",
        "images",
        "images: detect the wand here; points: subscribe to detector nodes",
        choices=("images", "points"),
    ),
    IMAGE_QOS,
    IMAGE_TRANSPORT,
    Param("mask_take_s", 1.0, "/take_mask: seconds of images whose lights become each camera's mask", 0.1, 60.0),
    Param(
        "sync_tolerance_ms",
        0.0,
        "images further apart than this never form a frame (ms; 0: half the frame period, learned per stream)",
        0.0,
        1000.0,
    ),
    Param("buffer_capacity", 20000, "frames stored before only coverage-adding frames are kept", 100, 10**7),
    Param("min_motion_px", 2.0, "a frame whose wand moved less than this (px) in every camera is skipped", 0.0, 1000.0),
    Param(
        "floor_hold_s",
        2.0,
        "after each /set_floor, frames of this long are floor frames (the wand still on the floor)",
        0.1,
        60.0,
    ),
    LABEL_HOLD,
    Param("with_calibrator", True, "also run the calibrator node (/calibrate) in this process"),
    Param("running_estimate", True, "calibrate the buffer so far every estimate_period_s while waving (preliminary)"),
    Param("estimate_period_s", 3.0, "seconds between the running estimate's rounds (at least)", 0.5, 3600.0),
    Param(
        "estimate_max_placements", MAX_PLACEMENTS, "placements one running-estimate round calibrates at most", 30, 10**6
    ),
    Param("auto_calibrate", False, "calibrate without /calibrate once coverage is ready and the estimate converged"),
    Param(
        "auto_focal_std_percent",
        0.5,
        "auto_calibrate: every camera's focal-length standard deviation at most this (% of it)",
        0.0,
        100.0,
    ),
    Param(
        "auto_principal_std_px",
        2.0,
        "auto_calibrate: every camera's principal-point standard deviation at most this (px)",
        0.0,
        10000.0,
    ),
)

#: The detections image of a camera is published at most once per this many seconds.
DEBUG_PERIOD_S = 0.5
#: observations.detection.yaml is written again at most once per this many seconds.
SUMMARY_PERIOD_S = 10.0

#: Points from detector nodes are few and small: deliver every one.
#: Released views' saturation flags held for their frames at most (a view no frame took is forgotten after them).
MAX_HELD_FLAGS = 10_000
POINTS_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)


class CollectorNode(Node):
    """Detection (or detector points), synchronisation, persisted buffer, coverage feedback."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("wand_calib_collector", **kwargs)
        values = declare(self, PARAMS)
        self.values = values  #: its parameters (an in-process calibrator falls back to them)
        cameras_file = existing_file(values, "cameras_file")
        self.rig = load_rig(cameras_file)
        self.endpoints = load_camera_endpoints(cameras_file)
        self.with_calibrator = bool(values["with_calibrator"])
        output_dir = Path(values["output_dir"]).expanduser()
        self.hold = CollectionLock(output_dir)  # one writer per folder
        self.buffer = ObservationBuffer.open(
            output_dir / BUFFER_FILE,
            self.rig,
            capacity=values["buffer_capacity"],
            min_motion_px=values["min_motion_px"],
            with_saturation=values["input"] == "images",  # (its own detector measures the spots)
        )
        self._saturation: dict[tuple[str, int], NDArray[np.bool_]] = {}  # released views' flags, until stored
        self.clock: Callable[[], int] = time.monotonic_ns  #: when a message arrives, ns (a steady clock)
        if self.buffer.repaired is not None:
            self.get_logger().warning(self.buffer.repaired.describe(self.buffer.path))
        self.coverage = CoverageTracker(self.rig, coverage_thresholds(values))
        self.coverage.add(self.buffer.observations().uv)  # the frames a restart found in the buffer file
        hold_ns = int(values["label_hold_ms"] * 1e6)
        self.sync = FrameSynchroniser(
            self.rig.camera_names,
            tolerance_ns=int(values["sync_tolerance_ms"] * 1e6),
            max_delay_ns=hold_ns + 500_000_000,
            n_points=self.rig.wand.n_points,
        )
        self.timing: CalibrationResult | None = None  # the last /calibrate's result (its time offsets)
        self.watch: BumpWatch | None = None  # after a /calibrate: is a camera moving away from it?
        self.estimates = (
            RunningEstimate(
                self.rig,
                CalibrationOptions(),
                period_s=values["estimate_period_s"],
                max_placements=values["estimate_max_placements"],
            )
            if values["running_estimate"]
            else None
        )
        self.auto = (
            (values["auto_focal_std_percent"], values["auto_principal_std_px"]) if values["auto_calibrate"] else None
        )
        #: the in-process calibrator's, for auto_calibrate: (source, when done(success, answer)) -> started
        self.calibrate_now: Callable[[str, Callable[[bool, str], None]], bool] | None = None
        self.calibrated = False  # a final calibration since the start or the last /reset: estimates stop
        self.take = 0  #: counted up by each /reset (a calibration of a cleared take is not this one's)
        self._auto_state: str | None = None  # auto_calibrate: None (not started), calibrating, failed ...
        self._auto_round: Estimate | None = None  # the round that started it
        self._moved_logged: dict[str, str] = {}
        wand = WandOptions.for_rig(self.rig)
        masks = self._given_masks(cameras_file)
        self.streams = {
            c.name: CameraStream(c, wand, max_hold_ns=hold_ns, mask=masks.get(c.name)) for c in self.rig.cameras
        }
        self.mask_take_s = float(values["mask_take_s"])
        self._said: dict[str, set[str]] = {name: set() for name in self.rig.camera_names}  # warnings given
        self._summary_saved = 0.0  # when observations.detection.yaml was last written (monotonic)
        self._summary_images = 0  # images received by then
        self.received = dict.fromkeys(self.rig.camera_names, 0)
        self.malformed = dict.fromkeys(self.rig.camera_names, 0)
        topics = {
            name: e.image_topic if values["input"] == "images" else e.points_topic for name, e in self.endpoints.items()
        }
        self.faults = StreamFaults(self.rig.camera_names, topics)  # silences, stamp jumps, unusable images, drops
        self.lock = threading.Lock()
        self._logged: tuple[bool, float] | None = None  # (ready, when) of the last coverage log line
        # A single-threaded executor runs these callbacks (see nodes.runner): each camera's
        # messages in order, as the A/C labeller needs; /calibrate runs in the calibrator's executor.
        self.images: dict[str, CameraImages] = {}
        self.debug_images = {
            name: self.create_publisher(Image, f"wand_calib/{name}/detections", 1) for name in self.rig.camera_names
        }
        self._debug_shown = dict.fromkeys(self.rig.camera_names, 0.0)
        for name, endpoint in self.endpoints.items():
            if values["input"] == "images":
                qos = image_qos(values["image_qos"])
                self.images[name] = CameraImages(
                    self, name, endpoint.image_topic, qos, values["image_transport"], self._on_image
                )
            else:
                self.create_subscription(
                    PolygonStamped, endpoint.points_topic, functools.partial(self._on_points, name), POINTS_QOS
                )
        self.create_service(Trigger, "reset", self._on_reset)
        self.create_service(Trigger, "take_mask", self._on_take_mask)
        self.floor = FloorWindow(float(values["floor_hold_s"]))
        self.create_service(Trigger, "set_floor", self._on_set_floor)
        self.diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.heat_maps = {
            name: self.create_publisher(Image, f"wand_calib/{name}/coverage", 1) for name in self.rig.camera_names
        }
        self.preliminary_info = {
            name: self.create_publisher(CameraInfo, f"wand_calib/preliminary/{name}/camera_info", LATCHED)
            for name in self.rig.camera_names
        }
        self.preliminary_extrinsics = {
            name: self.create_publisher(TransformStamped, f"wand_calib/preliminary/{name}/extrinsics", LATCHED)
            for name in self.rig.camera_names
        }
        self.preliminary_markers = self.create_publisher(MarkerArray, "wand_calib/preliminary/markers", LATCHED)
        self.frame_ids = {name: endpoint.frame_id for name, endpoint in self.endpoints.items()}
        # Feedback on the steady clock: with use_sim_time and no /clock, ROS time stands still.
        self.create_timer(1.0, self._publish_feedback, clock=Clock(clock_type=ClockType.STEADY_TIME))
        source = {"images": "image topics", "points": "detector points"}[values["input"]]
        self.get_logger().info(
            f"collecting {', '.join(self.rig.camera_names)} from {source} into {self.buffer.path} "
            f"({len(self.buffer.frames)} frames resumed)"
        )

    def _given_masks(self, cameras_file: Path) -> dict[str, Mask]:
        """Per camera the rig file's mask and the ones /take_mask took for this collection (kept beside it)."""
        masks = {
            name: mask_of(spec, self.rig.camera(name).image_size)
            for name, spec in load_camera_masks(cameras_file).items()
        }
        for spec in self.rig.cameras:
            taken = self._taken_path(spec.name)
            if taken.is_file():
                mask = read_mask(taken, spec.image_size)
                masks[spec.name] = np.maximum(masks[spec.name], mask) if spec.name in masks else mask
        return masks

    def _taken_path(self, camera: str) -> Path:
        return masks_folder(self.buffer.path) / f"{camera}.taken.png"

    def _on_image(self, camera: str, stamp_ns: int, pixels: NDArray[Any] | None, encoding: str) -> None:
        stream = self.streams[camera]
        arrival = self.clock()
        with self.lock:
            placed, said = self.faults.arrived(camera, stamp_ns, arrival)
            stamp_ns = placed.stamp_ns
            taking = stream.taking_mask
            self.received[camera] += 1
            blobs: Blobs | None
            detection: WandDetection | None
            reason: str | None
            if placed.order != "next":  # its time line passed it over: not searched, counted
                blobs, detection, reason = None, None, stream.passed_over(placed.order)
            else:
                blobs, detection, reason = stream.detect(pixels, encoding, stamp_ns)
                if reason is not None:
                    size = self.rig.camera(camera).image_size
                    problem = image_problem(reason, None if pixels is None else pixels.shape, encoding, size)
                    said += self.faults.unusable(camera, reason, problem, arrival)
                self._offer(camera, stream.label(stamp_ns, detection, reason))
            taken = stream.taken if taking and not stream.taking_mask else None
        self._say(said)
        if taken is not None:
            write_mask(self._taken_path(camera), taken)
            self.get_logger().info(f"{camera}: mask taken ({100 * float((taken > 0).mean()):.2f} % of the image)")
        self._show(camera, stamp_ns, pixels, encoding, blobs, detection, reason)

    def _show(
        self,
        camera: str,
        stamp_ns: int,
        pixels: NDArray[Any] | None,
        encoding: str,
        blobs: Blobs | None,
        detection: WandDetection | None,
        reason: str | None,
    ) -> None:
        """The image with its detections drawn on ``wand_calib/<cam>/detections``: 2 Hz at most, while subscribed."""
        publisher = self.debug_images[camera]
        now = time.monotonic()
        if pixels is None or now - self._debug_shown[camera] < DEBUG_PERIOD_S or not publisher.get_subscription_count():
            return
        self._debug_shown[camera] = now
        picture = draw_overlay(pixels, encoding, blobs, detection, reason, self.streams[camera].mask)
        publisher.publish(messages.array_to_image(picture, stamp_ns, self.frame_ids[camera], "bgr8"))

    def _on_points(self, camera: str, message: PolygonStamped) -> None:
        try:
            points = messages.message_points(message, self.rig.wand.n_points)
        except ValueError as error:
            self.get_logger().warning(f"{camera}: ignoring wand points: {error}", throttle_duration_sec=5.0)
            with self.lock:
                self.malformed[camera] += 1
            return
        with self.lock:
            placed, said = self.faults.arrived(camera, messages.stamp_ns(message.header), self.clock())
            self.received[camera] += 1
            stream = self.streams[camera]
            if placed.order != "next":  # its time line passed it over
                stream.passed_over(placed.order)
            else:  # the detector node labelled it: count it the same way
                stream.stats.images += 1
                if points is None:
                    stream.stats.rejected["no_wand"] += 1
                else:
                    stream.stats.detected += 1
                self._offer(camera, [Labelled(placed.stamp_ns, points)])
        self._say(said)

    def _say(self, said: list[Said]) -> None:
        """Log what the stream faults said."""
        for item in said:  # (one call site per severity: rclpy refuses a call site's severity changing)
            if item.level == "warning":
                self.get_logger().warning(item.line)
            else:
                self.get_logger().info(item.line)

    def _offer(self, camera: str, outcomes: list[Labelled]) -> None:
        """Synchronise released outcomes and store completed frames (caller holds the lock)."""
        for outcome in outcomes:
            if outcome.points is not None and outcome.saturated is not None:
                self._saturation[(camera, outcome.stamp_ns)] = outcome.saturated
            self._store(self.sync.add(camera, outcome.stamp_ns, outcome.points))

    def _flags(self, frame: SyncedFrame) -> NDArray[np.bool_]:
        """(C, K) the saturation flags of a frame's views (forgotten once asked: a view is in one frame)."""
        flags = np.zeros(frame.uv.shape[:2], dtype=bool)
        for c, name in enumerate(self.rig.camera_names):
            found = self._saturation.pop((name, int(frame.stamps_ns[c])), None) if frame.reported[c] else None
            if found is not None and found.shape == flags[c].shape:
                flags[c] = found
        if len(self._saturation) > MAX_HELD_FLAGS:  # (views no frame took: a camera's images dropped late)
            for key in list(self._saturation)[: len(self._saturation) - MAX_HELD_FLAGS]:
                del self._saturation[key]
        return flags

    def _store(self, frames: list[SyncedFrame]) -> None:
        for frame in frames:
            on_floor = self.floor.is_open(time.monotonic())
            if self.watch is not None:
                self.watch.offer(frame.uv)
            flags = self._flags(frame)
            if self.buffer.offer(frame.uv, messages.frame_stamps(frame), keep=on_floor, saturated=flags):
                self.coverage.add(frame.uv)
                if on_floor:
                    append_floor_frame(self.buffer.path.with_name(FLOOR_FILE), self.buffer.frames[-1])

    def flush(self) -> None:
        """Store everything still held (ambiguous views, pending frames): before /calibrate, at exit."""
        with self.lock:
            for name, stream in self.streams.items():
                self._offer(name, stream.flush())
            self._store(self.sync.flush_all())

    def close(self) -> None:
        """At exit: store what is held and write the buffer and what the cameras saw through to the disk."""
        self.flush()
        if sum(self.received.values()) != self._summary_images:
            self._save_what_cameras_saw()
        with self.lock:
            self.buffer.sync()
            if self.watch is not None:
                self.watch.close()
        if self.estimates is not None:
            self.estimates.close()
        self.hold.release()

    def after_calibrate(self, result: CalibrationResult) -> None:
        """Keep a calibration's result: /diagnostics then shows its time offsets, and the frames that
        follow are watched for a camera that moved."""
        with self.lock:
            self.timing = result
            if self.watch is not None:
                self.watch.close()
            self.watch = BumpWatch(self.rig, result)
            self._moved_logged = {}
            self.calibrated = True

    def snapshot(self) -> WandObservations:
        """The buffer so far (for the running estimate)."""
        with self.lock:
            return self.buffer.observations()

    def _publish_estimate(self, estimate: Estimate) -> None:
        """A running estimate's result on the preliminary topics."""
        result, scene = estimate.round.result, estimate.round.scene
        if result is None or scene is None:
            return
        stamp = self.get_clock().now().to_msg()
        for name in self.rig.camera_names:
            frame = self.frame_ids[name]
            self.preliminary_info[name].publish(messages.camera_info_message(result, name, stamp, frame))
            # the rounds fit no floor: the poses are the reference camera's, "world" is never their parent
            transform = messages.extrinsics_message(result, name, stamp, "world", self.frame_ids)
            self.preliminary_extrinsics[name].publish(transform)
        parent = messages.parent_frame(result, "world", self.frame_ids)
        self.preliminary_markers.publish(markers_message(scene, stamp, parent, preliminary=True))

    def _estimate_feedback(
        self, now: float, ready: bool, counts: dict[str, dict[str, int | str]], rig_values: dict[str, int | str]
    ) -> None:
        """Step the running estimate (publishing and noting a new round), add its diagnostics values,
        and start auto_calibrate when its conditions hold."""
        if self.estimates is not None and not self.calibrated:
            arrived = self.estimates.step(now, self.snapshot)
            if arrived is not None and arrived.round.result is not None:
                self._publish_estimate(arrived)
                history = self.buffer.path.with_name(ESTIMATES_FILE)
                append_estimate(history, time.time(), arrived.round.frames, arrived.round.result)
            per_camera, estimate_rig = messages.estimate_values(self.estimates.latest, self.estimates.failure, now)
            for name, values in per_camera.items():
                counts.setdefault(name, {}).update(values)
            rig_values |= estimate_rig
        started = self._maybe_auto_calibrate(ready)
        if started is not None:
            self.get_logger().info(started)
        if self._auto_state is not None:
            rig_values["auto_calibrate"] = "calibrated" if self.calibrated else self._auto_state

    def _auto_done(self, success: bool, message: str) -> None:
        """auto_calibrate's calibration ended (the calibrator's thread): a failure lets a later round retry."""
        if not success:
            self._auto_state = f"failed, retrying after the next round: {message}"

    def _maybe_auto_calibrate(self, ready: bool) -> str | None:
        """Start the final calibration when auto_calibrate's conditions hold; what it says, if it did."""
        if self.auto is None or self.calibrated or self.calibrate_now is None or self._auto_state == "calibrating":
            return None
        latest = self.estimates.latest if self.estimates is not None else None
        if not ready or latest is None or latest.round.result is None:
            return None
        if not converged(latest.round.result, *self.auto):
            return None
        if self._auto_state is not None and self._auto_round is latest:  # a failed try: wait for a new round
            return None
        if not self.calibrate_now("auto-calibrate", self._auto_done):
            return None
        self._auto_state, self._auto_round = "calibrating", latest
        return (
            f"auto-calibrate: coverage is ready and every camera's focal length is within +-{self.auto[0]:g} % and "
            f"principal point within +-{self.auto[1]:g} px: calibrating"
        )

    def _save_what_cameras_saw(self) -> None:
        """Each camera's detection report and mask beside the buffer (observations.detection.yaml, .masks/)."""
        with self.lock:
            reports = {name: stream.report() for name, stream in self.streams.items()}
            masks = {name: stream.mask for name, stream in self.streams.items()}
            self._summary_images = sum(self.received.values())
        try:
            save_what_cameras_saw(self.buffer.path, reports, masks)
        except WandCalibError as error:
            self.get_logger().warning(f"cannot keep what the cameras saw: {error}", throttle_duration_sec=60.0)
        self._summary_saved = time.monotonic()

    def _detection_feedback(self, counts: dict[str, dict[str, int | str]]) -> dict[str, list[str]]:
        """Each camera's detection figures into its diagnostics values, its warnings (said once per cause), the
        transports checked and the summary written now and then; returns the warnings per camera."""
        for images in self.images.values():
            switched = images.check()
            if switched is not None:
                self.get_logger().info(switched)
        notes: dict[str, list[str]] = {}
        with self.lock:
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
            for cause, line in warnings.items():
                if cause not in self._said[name]:
                    self._said[name].add(cause)
                    self.get_logger().warning(line)
        received = sum(self.received.values())
        if received != self._summary_images and time.monotonic() - self._summary_saved >= SUMMARY_PERIOD_S:
            self._save_what_cameras_saw()  # on news only: a resumed collection's summary stays until images come
        return notes

    def _counts(self) -> dict[str, dict[str, int | str]]:
        counts: dict[str, dict[str, int | str]] = {}
        for name, stream in self.streams.items():
            counts[name] = {"received": self.received[name], "wand_labelled": stream.stats.detected}
            counts[name] |= {f"rejected_{reason}": n for reason, n in sorted(stream.stats.rejected.items())}
            if self.malformed[name]:
                counts[name]["malformed_points"] = self.malformed[name]
            counts[name] |= messages.timing_values(self.sync, name, self.timing)
            counts[name] |= self.faults.values(name)
        return counts

    def _publish_feedback(self) -> None:
        with self.lock:
            status = self.coverage.status()
            counts = self._counts()
            sync, stored = self.sync.stats, self.buffer.stats
            behind, repeats = self.faults.timelines.totals()
            rig_values: dict[str, int | str] = {
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
            cells = {name: self.coverage.cells[c].copy() for c, name in enumerate(self.rig.camera_names)}
            watch = self.watch
            faults, said = self.faults.check(self.clock())
        self._say(said)
        now = time.monotonic()
        notes = self._detection_feedback(counts)
        self._estimate_feedback(now, status.ready, counts, rig_values)
        moved = {}
        if watch is not None:
            watch.step()
            moved = watch.moved()
            for name, line in sorted(moved.items()):
                if line in self._moved_logged.values():
                    continue
                self.get_logger().warning(f"{line}: call /refine to re-estimate it, or /reset, wave and /calibrate")
                append_event(self.buffer.path.with_name(EVENTS_FILE), time.time(), "moved", name, line)
            self._moved_logged = moved
        stamp = self.get_clock().now().to_msg()
        source = self.get_fully_qualified_name().lstrip("/")  # e.g. rig1/wand_calib_collector
        self.diagnostics.publish(
            messages.diagnostics_message(status, counts, rig_values, stamp, source, moved, notes, faults)
        )
        for spec in self.rig.cameras:
            self.heat_maps[spec.name].publish(
                messages.heat_map_message(cells[spec.name], spec.image_size, stamp, spec.name)
            )
        faulty = [f"{name}: {'; '.join(lines)}" for name, lines in faults.items() if lines]
        if self._logged is None or self._logged[0] != status.ready or (not status.ready and now - self._logged[1] > 10):
            if status.ready and faulty:
                frames = rig_values["frames_stored"]
                self.get_logger().info(f"ready to calibrate ({frames} frames), but " + " | ".join(faulty))
            elif status.ready:
                self.get_logger().info(f"ready to calibrate ({rig_values['frames_stored']} frames): call /calibrate")
            else:
                self.get_logger().info("still missing: " + " | ".join(status.messages()))
            self._logged = (status.ready, now)

    def _on_set_floor(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self.lock:
            lay = self.floor.open(time.monotonic())
        after = "call /set_floor again with the wand in a second direction" if lay == 1 else "then /calibrate"
        response.success = True
        response.message = (
            f"floor lay {lay}: hold the wand still on the floor for {self.floor.hold_s:g} s; {after} "
            "(the world frame: z up, the origin at the first lay's A, x along its A->C)"
        )
        self.get_logger().info(response.message)
        return response

    def _on_take_mask(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self.lock:
            for stream in self.streams.values():
                stream.take_mask(int(self.mask_take_s * 1e9))
        response.success = True
        response.message = (
            f"taking each camera's mask from its next {self.mask_take_s:g} s of images: keep the wand out of sight; "
            f"the lights in them are ignored from then on (kept in {masks_folder(self.buffer.path)})"
        )
        self.get_logger().info(response.message)
        return response

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self.lock:  # serialised with the frames being stored and with other resets
            backup = self.buffer.reset()
            self._saturation.clear()
            for name in (FLOOR_FILE, ESTIMATES_FILE, EVENTS_FILE):  # they belong to the buffer just moved away
                kept = self.buffer.path.with_name(name)
                if kept.exists():
                    move_aside(kept, "bak")
            self.floor.lays = 0
            self.take += 1
            self.coverage = CoverageTracker(self.rig, self.coverage.thresholds)
            self.calibrated, self._auto_state = False, None
        if self.estimates is not None:  # the next round starts cold on the new buffer
            self.estimates.restart()
        saved = "it was empty" if backup is None else f"backup {backup}"
        response.success, response.message = True, f"buffer cleared; {saved}"
        self.get_logger().info(response.message)
        return response


def build(context: Context, args: Sequence[str] = ()) -> list[Node]:
    """The collector and, unless ``with_calibrator`` is false, the calibrator fed by it.

    The calibrator keeps its own name under ``-r __node:=NAME`` (which renames the collector).
    """
    from wand_calib_ros.nodes.calibrator import CalibratorNode

    collector = CollectorNode(context=context)
    if not collector.with_calibrator:
        return [collector]
    calibrator = CalibratorNode(
        context=context,
        before_calibrate=collector.flush,
        after_calibrate=collector.after_calibrate,
        collector_values=collector.values,
        take=lambda: collector.take,
        cli_args=second_node_arguments(args),
        use_global_arguments=False,
    )
    collector.calibrate_now = calibrator.calibrate_now
    return [collector, calibrator]


def main(argv: Sequence[str] | None = None) -> int:
    """``ros2 run wand_calib_ros collector --ros-args --params-file config/<rig>.params.yaml``"""
    from wand_calib_ros.nodes import calibrator

    help_text = usage(
        "collector", __doc__, ("wand_calib_collector", PARAMS), ("wand_calib_calibrator", calibrator.PARAMS)
    )
    return run("collector", build, argv, help_text=help_text)


if __name__ == "__main__":
    sys.exit(main())
