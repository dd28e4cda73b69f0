"""The detector node: one camera's images in, its wand points out.

For rigs that outgrow one machine: run a detector next to each camera
(``ros2 run wand_calib_ros detector --ros-args -r __node:=detector_cam0 -p
camera:=cam0 -p cameras_file:=...``) and the collector with ``input: points``.
It publishes one geometry_msgs/PolygonStamped per image on the camera's
``points_topic`` (default ``/<cam>/wand_points``): the image's header and A, B,
C in pixels, or an empty polygon when the image showed no usable wand. Views
whose A/C order needs a later image are published when it arrives (at most
``label_hold_ms`` late, with their own stamp). DDS carries the points between
machines; no other networking.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import PolygonStamped
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from wand_calib_ros.detection.recording import CameraStream, Labelled
from wand_calib_ros.detection.wand import WandOptions
from wand_calib_ros.io.images import image_array
from wand_calib_ros.io.rig_yaml import load_camera_endpoints, load_rig
from wand_calib_ros.nodes import messages
from wand_calib_ros.nodes.collector import POINTS_QOS
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
        spec = rig.cameras[rig.camera_names.index(name)]
        self.stream = CameraStream(spec, WandOptions.for_rig(rig), max_hold_ns=int(values["label_hold_ms"] * 1e6))
        self.frame_id = name
        qos = image_qos(values["image_qos"])
        self.publisher = self.create_publisher(PolygonStamped, endpoint.points_topic, POINTS_QOS)
        self.create_subscription(Image, endpoint.image_topic, self._on_image, qos)
        self.get_logger().info(f"{name}: {endpoint.image_topic} -> {endpoint.points_topic}")

    def _on_image(self, message: Image) -> None:
        self.frame_id = message.header.frame_id or self.frame_id
        try:
            _, detection, reason = self.stream.detect(
                image_array(message), message.encoding, messages.stamp_ns(message.header)
            )
        except ValueError:
            detection, reason = None, "bad_image"
        self._publish(self.stream.label(messages.stamp_ns(message.header), detection, reason))

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
