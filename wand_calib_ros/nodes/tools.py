"""Small ROS tools this machine lacks the ``ros2`` CLI for: play a bag's images, call a Trigger.

``replay``: publish a rosbag2's camera images (sensor_msgs/Image; compressed ones
decoded) on the rig's image topics at their recorded pace (or ``rate`` times it),
then exit. ``trigger``: call a std_srvs/Trigger service (``/calibrate``,
``/reset``), print its answer, exit 0 on success and 1 otherwise.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Image
from std_srvs.srv import Trigger

from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.bags import read_image_frames
from wand_calib_ros.io.rig_yaml import load_camera_endpoints
from wand_calib_ros.nodes import messages
from wand_calib_ros.nodes.params import Param, declare, existing_file
from wand_calib_ros.nodes.runner import run

REPLAY_PARAMS = (
    Param("bag", "", "rosbag2 directory (mcap or sqlite3) with the cameras' images", required=True),
    Param("cameras_file", "", "rig description: its cameras' image_topic are played", required=True),
    Param("rate", 1.0, "playback speed over the recorded pace; 0 plays as fast as possible", 0.0, 1000.0),
    Param("qos", "reliable", "publisher QoS", choices=("sensor_data", "reliable")),
    Param("wait_for_subscribers_s", 10.0, "wait this long for every topic to have a subscriber", 0.0, 600.0),
)


class ReplayNode(Node):
    """Plays a bag's images once on a worker thread; ``done`` is set (and ``on_done`` called) at the end."""

    def __init__(self, *, on_done: Callable[[], object] | None = None, **kwargs: Any) -> None:
        super().__init__("wand_calib_replay", **kwargs)
        self.on_done = on_done
        self.done = threading.Event()
        values = declare(self, REPLAY_PARAMS)
        self.bag = Path(values["bag"]).expanduser()
        if not self.bag.exists():
            raise WandCalibError(f"parameter bag: no such bag {self.bag}")
        endpoints = load_camera_endpoints(existing_file(values, "cameras_file"))
        self.topics = {name: endpoint.image_topic for name, endpoint in endpoints.items()}
        qos = qos_profile_sensor_data if values["qos"] == "sensor_data" else QoSProfile(depth=100)
        self.publishers_ = {name: self.create_publisher(Image, topic, qos) for name, topic in self.topics.items()}
        self.rate = float(values["rate"])
        self.wait_s = float(values["wait_for_subscribers_s"])
        self.published = 0
        self._thread = threading.Thread(target=self._play, name="replay", daemon=True)
        self._thread.start()

    def _play(self) -> None:
        deadline = time.monotonic() + self.wait_s
        while time.monotonic() < deadline and any(p.get_subscription_count() == 0 for p in self.publishers_.values()):
            time.sleep(0.05)
        started, first = time.monotonic(), None
        try:
            for frame in read_image_frames(self.bag, self.topics):
                if not self.context.ok():
                    return
                first = frame.stamp_ns if first is None else first
                if self.rate > 0:
                    delay = (frame.stamp_ns - first) / 1e9 / self.rate - (time.monotonic() - started)
                    if delay > 0:
                        time.sleep(delay)
                self.publishers_[frame.camera].publish(
                    messages.array_to_image(frame.image, frame.stamp_ns, frame.camera, frame.encoding)
                )
                self.published += 1
            self.get_logger().info(f"played {self.published} images from {self.bag}")
        except WandCalibError as error:
            self.get_logger().error(f"cannot play {self.bag}: {error}")
        self.done.set()
        if self.on_done is not None:
            time.sleep(0.5)  # let reliable subscribers take the last messages
            self.on_done()

    def close(self) -> None:
        self._thread.join(timeout=2.0)


def replay_main(argv: Sequence[str] | None = None) -> int:
    """``ros2 run wand_calib_ros replay --ros-args -p bag:=... -p cameras_file:=...``"""
    return run("replay", lambda context: [ReplayNode(context=context, on_done=context.try_shutdown)], argv)


def call_trigger(service: str, timeout_s: float, context: Context | None = None) -> tuple[bool, str]:
    """Call a std_srvs/Trigger service; (success, message), or (False, why) when it is not there."""
    own = context is None
    context = context or Context()
    if own:
        rclpy.init(context=context)
    node = Node("wand_calib_trigger", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        client = node.create_client(Trigger, service)
        if not client.wait_for_service(timeout_sec=min(timeout_s, 30.0)):
            return False, f"service {service} is not available"
        response = client.call(Trigger.Request(), timeout_sec=timeout_s)
        if response is None:
            return False, f"{service} did not answer within {timeout_s:.0f} s"
        return bool(response.success), str(response.message)
    finally:
        executor.shutdown()
        node.destroy_node()
        if own:
            rclpy.try_shutdown(context=context)
        spinner.join(timeout=5)


def trigger_main(argv: Sequence[str] | None = None) -> int:
    """``trigger /calibrate``: call a std_srvs/Trigger service and print its answer."""
    parser = argparse.ArgumentParser(prog="trigger", description=__doc__.split("\n\n")[0])
    parser.add_argument("service", help="e.g. /calibrate or /reset")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for the answer")
    args = parser.parse_args(list(argv) if argv is not None else rclpy.utilities.remove_ros_args(sys.argv)[1:])
    success, message = call_trigger(args.service, args.timeout)
    print(f"{args.service}: {'success' if success else 'failure'}: {message}")
    return 0 if success else 1


if __name__ == "__main__":
    sys.exit(trigger_main())
