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
workflow. Only message and parameter translation lives here: the collection itself is the ROS-free
:class:`~wand_calib_ros.collection.session.CollectionSession`'s.
"""

from __future__ import annotations

import functools
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

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

from wand_calib_ros.collection.estimate import MAX_PLACEMENTS, Estimate
from wand_calib_ros.collection.session import CollectionSession, SessionSettings
from wand_calib_ros.collection.stream_faults import Said
from wand_calib_ros.io.rig_yaml import load_camera_endpoints, load_camera_masks, load_rig
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

#: Points from detector nodes are few and small: deliver every one.
POINTS_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)


def session_settings(values: dict[str, Any]) -> SessionSettings:
    """The collection's settings from the node's parameters."""
    auto = (values["auto_focal_std_percent"], values["auto_principal_std_px"]) if values["auto_calibrate"] else None
    return SessionSettings(
        capacity=values["buffer_capacity"],
        min_motion_px=values["min_motion_px"],
        measure_brightness=values["input"] == "images",  # (its own detector measures the spots)
        sync_tolerance_ns=int(values["sync_tolerance_ms"] * 1e6),
        label_hold_ns=int(values["label_hold_ms"] * 1e6),
        floor_hold_s=float(values["floor_hold_s"]),
        mask_take_ns=int(values["mask_take_s"] * 1e9),
        coverage=coverage_thresholds(values),
        estimate_period_s=values["estimate_period_s"] if values["running_estimate"] else None,
        estimate_max_placements=values["estimate_max_placements"],
        auto=auto,
    )


class CollectorNode(Node):
    """The collection session's messages, services and feedback (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("wand_calib_collector", **kwargs)
        values = declare(self, PARAMS)
        self.values = values  #: its parameters (an in-process calibrator falls back to them)
        cameras_file = existing_file(values, "cameras_file")
        self.rig = load_rig(cameras_file)
        self.endpoints = load_camera_endpoints(cameras_file)
        self.with_calibrator = bool(values["with_calibrator"])
        self.clock: Callable[[], int] = time.monotonic_ns  #: when a message arrives, ns (a steady clock)
        images = values["input"] == "images"
        topics = {name: e.image_topic if images else e.points_topic for name, e in self.endpoints.items()}
        self.session = CollectionSession(
            self.rig,
            session_settings(values),
            Path(values["output_dir"]).expanduser(),
            load_camera_masks(cameras_file),
            topics,
        )
        # A single-threaded executor runs these callbacks (see nodes.runner): each camera's
        # messages in order, as the A/C labeller needs; /calibrate runs in the calibrator's executor.
        self.images: dict[str, CameraImages] = {}
        for name, endpoint in self.endpoints.items():
            if images:
                qos = image_qos(values["image_qos"])
                self.images[name] = CameraImages(
                    self, name, endpoint.image_topic, qos, values["image_transport"], self._on_image
                )
            else:
                callback = functools.partial(self._on_points, name)
                self.create_subscription(PolygonStamped, endpoint.points_topic, callback, POINTS_QOS)
        self.create_service(Trigger, "reset", functools.partial(self._answer, self.session.reset))
        self.create_service(Trigger, "take_mask", functools.partial(self._answer, self.session.take_mask))
        self.create_service(Trigger, "set_floor", functools.partial(self._answer, self.session.set_floor))
        names = self.rig.camera_names
        self.debug_images = {name: self.create_publisher(Image, f"wand_calib/{name}/detections", 1) for name in names}
        self.diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.heat_maps = {name: self.create_publisher(Image, f"wand_calib/{name}/coverage", 1) for name in names}
        self.preliminary_info = {
            name: self.create_publisher(CameraInfo, f"wand_calib/preliminary/{name}/camera_info", LATCHED)
            for name in names
        }
        self.preliminary_extrinsics = {
            name: self.create_publisher(TransformStamped, f"wand_calib/preliminary/{name}/extrinsics", LATCHED)
            for name in names
        }
        self.preliminary_markers = self.create_publisher(MarkerArray, "wand_calib/preliminary/markers", LATCHED)
        self.frame_ids = {name: endpoint.frame_id for name, endpoint in self.endpoints.items()}
        # Feedback on the steady clock: with use_sim_time and no /clock, ROS time stands still.
        self.create_timer(1.0, self._publish_feedback, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._say(self.session.opening("image topics" if images else "detector points"))

    def _on_image(self, camera: str, stamp_ns: int, pixels: NDArray[Any] | None, encoding: str) -> None:
        publisher = self.debug_images[camera]
        show = pixels is not None and publisher.get_subscription_count() > 0
        answer = self.session.image(camera, stamp_ns, self.clock(), pixels, encoding, show=show)
        self._say(answer.said)
        if answer.picture is not None:
            publisher.publish(messages.array_to_image(answer.picture, answer.stamp_ns, self.frame_ids[camera], "bgr8"))

    def _on_points(self, camera: str, message: PolygonStamped) -> None:
        try:
            points = messages.message_points(message, self.rig.wand.n_points)
        except ValueError as error:
            self.get_logger().warning(f"{camera}: ignoring wand points: {error}", throttle_duration_sec=5.0)
            self.session.unreadable_points(camera)
            return
        self._say(self.session.points(camera, messages.stamp_ns(message.header), self.clock(), points))

    def _answer(
        self, action: Callable[[], str], request: Trigger.Request, response: Trigger.Response
    ) -> Trigger.Response:
        response.success, response.message = True, action()
        self.get_logger().info(response.message)
        return response

    def _say(self, said: Sequence[Said]) -> None:
        """Log what the session said."""
        for item in said:  # (one call site per severity: rclpy refuses a call site's severity changing)
            if item.level == "warning":
                self.get_logger().warning(item.line)
            else:
                self.get_logger().info(item.line)

    def flush(self) -> None:
        """Store everything still held (ambiguous views, pending frames): before /calibrate, at exit."""
        self.session.flush()

    def close(self) -> None:
        """At exit: store what is held and write the buffer and what the cameras saw through to the disk."""
        self.session.close()

    def _publish_feedback(self) -> None:
        for images in self.images.values():
            switched = images.check()
            if switched is not None:
                self.get_logger().info(switched)
        feedback = self.session.feedback(self.clock())
        if feedback.estimate is not None:
            self._publish_estimate(feedback.estimate)
        stamp = self.get_clock().now().to_msg()
        source = self.get_fully_qualified_name().lstrip("/")  # e.g. rig1/wand_calib_collector
        values = (feedback.counts, feedback.rig_values, stamp, source, feedback.moved, feedback.notes, feedback.faults)
        self.diagnostics.publish(messages.diagnostics_message(feedback.status, *values))
        for spec in self.rig.cameras:
            cells = feedback.cells[spec.name]
            self.heat_maps[spec.name].publish(messages.heat_map_message(cells, spec.image_size, stamp, spec.name))
        self._say(feedback.said)

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


def build(context: Context, args: Sequence[str] = ()) -> list[Node]:
    """The collector and, unless ``with_calibrator`` is false, the calibrator fed by it.

    The calibrator keeps its own name under ``-r __node:=NAME`` (which renames the collector).
    """
    from wand_calib_ros.nodes.calibrator import CalibratorNode

    collector = CollectorNode(context=context)
    if not collector.with_calibrator:
        return [collector]
    session = collector.session
    calibrator = CalibratorNode(
        context=context,
        before_calibrate=session.flush,
        after_calibrate=session.after_calibrate,
        collector_values=collector.values,
        take=lambda: session.take,
        cli_args=second_node_arguments(args),
        use_global_arguments=False,
    )
    session.calibrate_now = calibrator.calibrate_now
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
