"""ROS fixtures: an isolated context per test (own domain id) with an executor spinning in a thread."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.context import Context  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


def free_domain_id() -> int:
    """A ROS_DOMAIN_ID unlikely to be used by a parallel test run (pid and randomness mixed)."""
    return int((os.getpid() * 7 + np.random.default_rng().integers(0, 1000)) % 170) + 30


@dataclass
class Ros:
    """A test's ROS world: context, executor in a thread, a helper node for publishers and clients."""

    context: Context
    domain_id: int
    executor: MultiThreadedExecutor
    helper: Node
    nodes: list[Node] = field(default_factory=list)

    def add(self, node: Node) -> Node:
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

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
    domain_id = free_domain_id()
    rclpy.init(context=context, domain_id=domain_id)
    executor = MultiThreadedExecutor(num_threads=6, context=context)
    world = Ros(context, domain_id, executor, Node("test_helper", context=context))
    executor.add_node(world.helper)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        yield world
    finally:
        for node in world.nodes:
            close = getattr(node, "close", None)
            if close is not None:
                close()
        executor.shutdown()
        for node in [*world.nodes, world.helper]:
            node.destroy_node()
        rclpy.shutdown(context=context)
        spinner.join(timeout=5)
        assert not spinner.is_alive()
