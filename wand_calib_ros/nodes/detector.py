"""The detector node: one camera's images in, its wand points out.

For rigs that outgrow one machine: run a detector next to each camera
(``ros2 run wand_calib_ros detector --ros-args -r __node:=detector_cam0 -p
camera:=cam0 -p cameras_file:=...``) and the collector with ``input: points``.
It publishes one geometry_msgs/PolygonStamped per image on the camera's
``points_topic`` (default ``/<cam>/wand_points``): the image's header and A, B,
C in pixels, or an empty polygon when the image showed no usable wand. Views
whose A/C order needs a later image are published when it arrives (at most
``label_hold_ms`` late, with their own stamp). DDS carries the points between
machines; no other networking. It reads raw images or image_transport's
``<topic>/compressed`` (``image_transport``), ignores the rig file's ``mask`` and
the static lights it learns, takes a mask on ``/<node>/take_mask`` (the wand
out of sight), says once per cause when the camera's LEDs saturate, are too dim
or streak, and shows its detections on ``<node>/detections`` (2 Hz, while
subscribed).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import PolygonStamped
from numpy.typing import NDArray
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from wand_calib_ros.collection.session import OVERLAY_PERIOD_S
from wand_calib_ros.detection.masks import mask_of
from wand_calib_ros.detection.overlay import draw_overlay
from wand_calib_ros.detection.recording import CameraStream, Labelled
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.io.rig_yaml import load_camera_endpoints, load_camera_masks, load_rig
from wand_calib_ros.nodes import messages
from wand_calib_ros.nodes.collector import POINTS_QOS
from wand_calib_ros.nodes.images import IMAGE_TRANSPORT, CameraImages
from wand_calib_ros.nodes.params import (
    IMAGE_QOS,
    LABEL_HOLD,
    RIG,
    Param,
    SettingsError,
    declare,
    existing_file,
    image_qos,
    usage,
)
from wand_calib_ros.nodes.runner import run

PARAMS = (
    RIG[0],
    Param("camera", "", "the camera of cameras_file whose images this node reads", required=True),
    IMAGE_QOS,
    IMAGE_TRANSPORT,
    Param("mask_take_s", 1.0, "~/take_mask: seconds of images whose lights become the camera's mask", 0.1, 60.0),
    LABEL_HOLD,
)


class DetectorNode(Node):
    """LED detection and A/C labelling for one camera (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("wand_calib_detector", **kwargs)
        values = declare(self, PARAMS)
        cameras_file = existing_file(values, "cameras_file")
        rig = load_rig(cameras_file)
        name = values["camera"]
        if name not in rig.camera_names:
            raise SettingsError(f"parameter camera: {name!r} is not in {cameras_file} ({', '.join(rig.camera_names)})")
        endpoint = load_camera_endpoints(cameras_file)[name]
        spec = rig.camera(name)
        masks = load_camera_masks(cameras_file)
        mask = mask_of(masks[name], spec.image_size) if name in masks else None
        hold = int(values["label_hold_ms"] * 1e6)
        self.stream = CameraStream(spec, WandOptions.for_rig(rig), max_hold_ns=hold, mask=mask)
        self.frame_id = name
        self.mask_take_s = float(values["mask_take_s"])
        qos = image_qos(values["image_qos"])
        self.publisher = self.create_publisher(PolygonStamped, endpoint.points_topic, POINTS_QOS)
        self.debug_image = self.create_publisher(Image, "~/detections", 1)
        self._shown = 0.0
        self._said: set[str] = set()
        self.images = CameraImages(self, name, endpoint.image_topic, qos, values["image_transport"], self._on_image)
        self.create_service(Trigger, "~/take_mask", self._on_take_mask)
        self.create_timer(1.0, self._feedback, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"{name}: {endpoint.image_topic} -> {endpoint.points_topic}")

    def _on_image(self, camera: str, stamp_ns: int, pixels: NDArray[Any] | None, encoding: str) -> None:
        blobs, detection, reason = self.stream.detect(pixels, encoding, stamp_ns)
        self._publish(self.stream.label(stamp_ns, detection, reason))
        now = time.monotonic()
        if pixels is not None and now - self._shown >= OVERLAY_PERIOD_S and self.debug_image.get_subscription_count():
            self._shown = now
            picture = draw_overlay(pixels, encoding, blobs, detection, reason, self.stream.mask)
            self.debug_image.publish(messages.array_to_image(picture, stamp_ns, self.frame_id, "bgr8"))

    def _feedback(self) -> None:
        """Switch to compressed images when only those come; say each exposure problem once."""
        switched = self.images.check()
        if switched is not None:
            self.get_logger().info(switched)
        for cause, line in self.stream.report().warnings().items():
            if cause not in self._said:
                self._said.add(cause)
                self.get_logger().warning(line)

    def _on_take_mask(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.stream.take_mask(int(self.mask_take_s * 1e9))
        response.success = True
        response.message = (
            f"{self.frame_id}: taking the mask from the next {self.mask_take_s:g} s of images: keep the wand out of "
            "sight; the lights in them are ignored from then on"
        )
        return response

    def _publish(self, outcomes: list[Labelled]) -> None:
        for outcome in outcomes:
            header = Header(stamp=messages.time_message(outcome.stamp_ns), frame_id=self.frame_id)
            self.publisher.publish(messages.points_message(outcome.points, header))

    def close(self) -> None:
        """Publish what the labeller still holds (unsettled: empty polygons) while ROS is still up."""
        outcomes = self.stream.flush()
        if self.context.ok():
            self._publish(outcomes)


def build(context: Context, args: Sequence[str] = ()) -> list[Node]:
    return [DetectorNode(context=context)]


def main(argv: Sequence[str] | None = None) -> int:
    """``ros2 run wand_calib_ros detector --ros-args -p cameras_file:=... -p camera:=cam0``"""
    return run("detector", build, argv, help_text=usage("detector", __doc__, ("wand_calib_detector", PARAMS)))


if __name__ == "__main__":
    sys.exit(main())
