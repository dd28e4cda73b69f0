"""A camera's images into a node: raw ``sensor_msgs/Image`` on its image topic, or image_transport's
``sensor_msgs/CompressedImage`` on ``<image topic>/compressed``, decoded to the arrays the detector reads.

With ``image_transport: auto`` a node listens to the raw topic and, while no image has come, looks at
the graph every second: when only the compressed topic is published (a driver or a bag that sends
JPEG), it listens there instead and says so.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from numpy.typing import NDArray
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CompressedImage, Image

from wand_calib_ros.io.bags import COMPRESSED_SUFFIX
from wand_calib_ros.io.images import decode_compressed, image_array
from wand_calib_ros.nodes import messages
from wand_calib_ros.nodes.params import Param

IMAGE_TRANSPORT = Param(
    "image_transport",
    "auto",
    "raw: sensor_msgs/Image on each camera's image_topic; compressed: CompressedImage on <image_topic>/compressed; "
    "auto: raw, or compressed where only that is published",
    choices=("auto", "raw", "compressed"),
)

#: What a node is handed per image: (camera, stamp ns, pixels or None when they cannot be read, encoding).
OnImage = Callable[[str, int, NDArray[Any] | None, str], None]


class CameraImages:
    """One camera's image subscription (see the module docstring)."""

    def __init__(self, node: Node, camera: str, topic: str, qos: QoSProfile, transport: str, on_image: OnImage) -> None:
        self.node, self.camera, self.raw_topic, self.qos, self.on_image = node, camera, topic, qos, on_image
        self.transport = "compressed" if transport == "compressed" else "raw"
        self.auto = transport == "auto"
        self.received = 0
        self._subscription: Any = None
        self._subscribe()

    @property
    def topic(self) -> str:
        """The topic listened to."""
        return self.raw_topic + (COMPRESSED_SUFFIX if self.transport == "compressed" else "")

    def _subscribe(self) -> None:
        if self._subscription is not None:
            self.node.destroy_subscription(self._subscription)
        if self.transport == "compressed":
            self._subscription = self.node.create_subscription(
                CompressedImage, self.topic, self._on_compressed, self.qos
            )
        else:
            self._subscription = self.node.create_subscription(Image, self.topic, self._on_raw, self.qos)

    def check(self) -> str | None:
        """With ``auto``, before any image came: listen to the compressed topic when only it is published.
        Returns what to log when it switched."""
        if not self.auto or self.received or self.transport == "compressed":
            return None
        raw = self.node.count_publishers(self.raw_topic)
        compressed = self.node.count_publishers(self.raw_topic + COMPRESSED_SUFFIX)
        if raw or not compressed:
            return None
        self.transport = "compressed"
        self._subscribe()
        return f"{self.camera}: nothing publishes {self.raw_topic}, its compressed images do: listening to {self.topic}"

    def _on_raw(self, message: Image) -> None:
        self.received += 1
        try:
            pixels: NDArray[Any] | None = image_array(message)
        except ValueError:
            pixels = None
        self.on_image(self.camera, messages.stamp_ns(message.header), pixels, message.encoding)

    def _on_compressed(self, message: CompressedImage) -> None:
        self.received += 1
        try:
            pixels, encoding = decode_compressed(bytes(message.data), message.format)
        except ValueError:
            pixels, encoding = None, "compressed"
        self.on_image(self.camera, messages.stamp_ns(message.header), pixels, encoding)
