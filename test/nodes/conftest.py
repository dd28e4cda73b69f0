"""ROS fixtures: an isolated context per test (own domain id) with an executor spinning in a thread."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
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
