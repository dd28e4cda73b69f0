"""ROS fixtures: an isolated context per test (own domain id) with an executor spinning in a thread."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402

from wand_calib_ros.nodes.calibrator import LATCHED  # noqa: E402,F401  (tests subscribe like users do)
from wand_calib_ros.nodes.launch import free_domain_id  # noqa: E402
from wand_calib_ros.nodes.runner import Spinner  # noqa: E402


@dataclass
class Ros:
    """A test's ROS world: context, nodes spun like ``main()`` spins them, a helper node."""

    context: Context
    spinner: Spinner
    helper: Node

    def add(self, node: Node) -> Node:
        return self.spinner.add(node)

    def collect(self, msgtype: type, topic: str, qos: QoSProfile | int = 10) -> list[Any]:
        """Messages arriving on ``topic`` (appended as they come)."""
        received: list[Any] = []
        self.helper.create_subscription(msgtype, topic, received.append, qos)
        return received


def wait_until(condition: Callable[[], bool], timeout_s: float, step_s: float = 0.05) -> bool:
    """Poll ``condition`` until it holds or ``timeout_s`` passed; returns whether it held."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(step_s)
    return True


@dataclass
class PointsRig:
    """A collector fed by detector points and its calibrator (:func:`points_rig`).

    Attributes:
        collector: the CollectorNode.
        play: publishes (F, C, K, 2) pixels as consecutive 30 fps frames of points (NaN views: empty
            polygons) and waits until the collector received them all.
    """

    collector: Any
    play: Callable[[Any], None]


def points_rig(
    ros: Ros,
    scenario: Any,
    tmp_path: Any,
    collector_parameters: dict[str, Any],
    *,
    watch: bool = False,
    rig: Any = None,
) -> PointsRig:
    """A collector with ``input: points`` (plus ``collector_parameters``) and a separate calibrator on
    ``scenario``'s rig (or ``rig``), output in ``tmp_path/out``, coverage not required; ``watch``: the
    calibrator hands its results to the collector (the bump watch)."""
    import numpy as np
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PolygonStamped
    from rclpy.parameter import Parameter
    from std_msgs.msg import Header

    from wand_calib_ros.io.rig_yaml import save_rig
    from wand_calib_ros.nodes.calibrator import CalibratorNode
    from wand_calib_ros.nodes.collector import POINTS_QOS, CollectorNode
    from wand_calib_ros.nodes.messages import points_message

    save_rig(scenario.rig if rig is None else rig, tmp_path / "cameras.yaml")
    common = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("require_coverage", value=False),
    ]
    collected = {"input": "points", "with_calibrator": False, **collector_parameters}
    collector = ros.add(
        CollectorNode(
            context=ros.context,
            parameter_overrides=[*common, *(Parameter(k, value=v) for k, v in collected.items())],
        )
    )
    ros.add(
        CalibratorNode(
            context=ros.context,
            parameter_overrides=[*common, Parameter("write_report", value=False)],
            before_calibrate=collector.flush,
            after_calibrate=collector.session.after_calibrate if watch else None,
        )
    )
    names = scenario.rig.camera_names
    publishers = {n: ros.helper.create_publisher(PolygonStamped, f"/{n}/wand_points", POINTS_QOS) for n in names}
    assert wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 10)
    sent = [0]

    def play(uv: Any) -> None:
        for frame in uv:
            sent[0] += 1
            stamp = Time(sec=1000 + sent[0] // 30, nanosec=int(sent[0] % 30 * 1e9 / 30))
            for c, name in enumerate(names):
                points = frame[c] if np.all(np.isfinite(frame[c])) else None
                publishers[name].publish(points_message(points, Header(stamp=stamp, frame_id=name)))
            time.sleep(0.002)
        assert wait_until(lambda: min(collector.session.received.values()) == sent[0], 20)

    return PointsRig(collector, play)


def publish_images(ros: Ros, collector: Any, recording: Any, names: tuple[str, ...]) -> None:
    """Publish a rendered recording's images on ``/<camera>/image_raw`` (once every camera's topic has
    a subscriber) and wait until the collector received them all."""
    from sensor_msgs.msg import Image

    from wand_calib_ros.nodes.messages import array_to_image

    publishers = {name: ros.helper.create_publisher(Image, f"/{name}/image_raw", 50) for name in names}
    assert wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 10)
    for camera, stamp, pixels in recording.frames:
        publishers[camera].publish(array_to_image(pixels, stamp, camera))
        time.sleep(0.005)
    assert wait_until(lambda: sum(collector.session.received.values()) == len(recording.frames), 20)


@pytest.fixture
def ros() -> Iterator[Ros]:
    context = Context()
    rclpy.init(context=context, domain_id=free_domain_id())
    spinner = Spinner(context)
    world = Ros(context, spinner, Node("test_helper", context=context))
    spinner.add(world.helper)
    try:
        yield world
    finally:
        spinner.close()
        rclpy.shutdown(context=context)
        assert not any(thread.is_alive() for thread in threading.enumerate() if thread.name.startswith("spin "))


def calibrates_as_kept(ros: Ros, tmp_path: Path, collector: Any) -> None:
    """/calibrate on what the collector kept gives exactly ``wand-calib calibrate`` on its buffer file."""
    import numpy as np
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from wand_calib_ros import cli
    from wand_calib_ros.io.result_yaml import read_result
    from wand_calib_ros.nodes.calibrator import CalibratorNode

    values = {
        "cameras_file": str(tmp_path / "cameras.yaml"),
        "output_dir": str(tmp_path / "out"),
        "require_coverage": False,
        "write_report": False,
        "time_offsets": "fixed",  # independent placements: no motion to time
    }
    ros.add(
        CalibratorNode(
            context=ros.context,
            parameter_overrides=[Parameter(k, value=v) for k, v in values.items()],
            before_calibrate=collector.flush,
        )
    )
    client = ros.helper.create_client(Trigger, "calibrate")
    assert client.wait_for_service(timeout_sec=5)
    response = client.call(Trigger.Request(), timeout_sec=120)
    assert response is not None and response.success, response
    out = tmp_path / "out"
    offline = ["calibrate", "--time-offsets", "fixed", "--cameras", str(tmp_path / "cameras.yaml"), "--observations"]
    assert cli.main(["-q", *offline, str(out / "observations.csv"), "--output", str(tmp_path / "offline.yaml")]) == 0
    _, live = read_result(out / "result.yaml")
    _, kept = read_result(tmp_path / "offline.yaml")
    for name, camera in kept.items():
        assert np.array_equal(live[name].model.intrinsic_vector(), camera.model.intrinsic_vector())
        assert np.array_equal(live[name].pose.translation, camera.pose.translation)
