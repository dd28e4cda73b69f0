"""Play a bag's camera images on the rig's image topics (``ros2 bag play`` for images, without ROS installed).

Publishes sensor_msgs/Image on each camera's image topic, or, where the bag holds only a camera's
compressed images (image_transport's ``<topic>/compressed``), sensor_msgs/CompressedImage on
``<image topic>/compressed`` as recorded, at the recorded pace (or ``rate`` times it), and exits when
the bag ends.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from rclpy.node import Node
from sensor_msgs.msg import CompressedImage, Image

from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.bags import COMPRESSED, COMPRESSED_SUFFIX, bag_topics, choose_topics, read_image_messages
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.images import image_array
from wand_calib_ros.io.rig_yaml import load_camera_endpoints
from wand_calib_ros.nodes import messages
from wand_calib_ros.nodes.params import Param, declare, existing_file, image_qos, usage
from wand_calib_ros.nodes.runner import EXIT_SETTINGS, run

REPLAY_PARAMS = (
    Param("bag", "", "rosbag2 directory (mcap or sqlite3) with the cameras' images", required=True),
    Param("cameras_file", "", "rig description: its cameras' image_topic are played", required=True),
    Param("rate", 1.0, "playback speed over the recorded pace; 0 plays as fast as possible", 0.0, 1000.0),
    Param("qos", "reliable", "publisher QoS", choices=("sensor_data", "reliable")),
    Param("wait_for_subscribers_s", 10.0, "wait this long for every topic to have a subscriber", 0.0, 600.0),
)


class ReplayNode(Node):
    """Plays a bag's images once on a worker thread, then calls ``on_done`` (if given)."""

    def __init__(self, *, on_done: Callable[[], object] | None = None, **kwargs: Any) -> None:
        super().__init__("wand_calib_replay", **kwargs)
        self.on_done = on_done
        values = declare(self, REPLAY_PARAMS)
        self.bag = Path(values["bag"]).expanduser()
        if not self.bag.exists():
            raise WandCalibError(f"parameter bag: no such bag {self.bag}")
        endpoints = load_camera_endpoints(existing_file(values, "cameras_file"))
        raw = {name: endpoint.image_topic for name, endpoint in endpoints.items()}
        self.topics = choose_topics(bag_topics(self.bag), raw, "auto")  # where the bag holds each camera's images
        qos = image_qos(values["qos"])
        self.publishers_ = {
            name: self.create_publisher(CompressedImage if topic.endswith(COMPRESSED_SUFFIX) else Image, topic, qos)
            for name, topic in self.topics.items()
        }
        self.rate = float(values["rate"])
        self.wait_s = float(values["wait_for_subscribers_s"])
        self.published = 0
        self.exit_code = 0  #: the process's exit code once playing ends (EXIT_SETTINGS: the bag is unreadable)
        self._thread = threading.Thread(target=self._play, name="replay", daemon=True)
        self._thread.start()

    def _play(self) -> None:
        deadline = time.monotonic() + self.wait_s
        while time.monotonic() < deadline and any(p.get_subscription_count() == 0 for p in self.publishers_.values()):
            time.sleep(0.05)
        started, first = time.monotonic(), None
        try:
            for camera, stamp_ns, msgtype, stored in read_image_messages(self.bag, self.topics):
                if not self.context.ok():
                    return
                first = stamp_ns if first is None else first
                if self.rate > 0:
                    delay = (stamp_ns - first) / 1e9 / self.rate - (time.monotonic() - started)
                    if delay > 0:
                        time.sleep(delay)
                self.publishers_[camera].publish(self._message(camera, stamp_ns, msgtype, stored))
                self.published += 1
            self.get_logger().info(f"played {self.published} images from {self.bag}")
        except WandCalibError as error:
            self.get_logger().fatal(f"cannot play {self.bag}: {error}")
            self.exit_code = EXIT_SETTINGS
        if self.on_done is not None:
            time.sleep(0.5)  # let reliable subscribers take the last messages
            self.on_done()

    def _message(self, camera: str, stamp_ns: int, msgtype: str, stored: Any) -> Image | CompressedImage:
        """The rclpy message of a stored one (a raw image re-encoded from its pixels, a compressed one as is)."""
        if msgtype == COMPRESSED:
            message = CompressedImage()
            message.header.stamp = messages.time_message(stamp_ns)
            message.header.frame_id = camera
            message.format = str(stored.format)
            message.data = bytes(stored.data)
            return message
        try:
            pixels = image_array(stored)
        except ValueError as error:
            raise FormatError(self.bag, f"{camera}: {error}") from None
        return messages.array_to_image(pixels, stamp_ns, camera, str(stored.encoding))

    def close(self) -> None:
        self._thread.join(timeout=2.0)


def main(argv: Sequence[str] | None = None) -> int:
    """``ros2 run wand_calib_ros replay --ros-args -p bag:=... -p cameras_file:=...``"""
    return run(
        "replay",
        lambda context, _args: [ReplayNode(context=context, on_done=context.try_shutdown)],
        argv,
        help_text=usage("replay", __doc__, ("wand_calib_replay", REPLAY_PARAMS)),
    )


if __name__ == "__main__":
    sys.exit(main())
