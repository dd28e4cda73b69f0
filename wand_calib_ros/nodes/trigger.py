"""Call a std_srvs/Trigger service (``/calibrate``, ``/reset``) and print its answer (``ros2 service call``).

Exit code 0 when the service answered success, 1 otherwise.
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import try_shutdown
from std_srvs.srv import Trigger


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
            try_shutdown(context=context)
        spinner.join(timeout=5)


def main(argv: Sequence[str] | None = None) -> int:
    """``trigger /calibrate``: call a std_srvs/Trigger service and print its answer."""
    parser = argparse.ArgumentParser(prog="trigger", description=__doc__.split("\n\n")[0])
    parser.add_argument("service", help="e.g. /calibrate or /reset")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for the answer")
    args = parser.parse_args(list(argv) if argv is not None else rclpy.utilities.remove_ros_args(sys.argv)[1:])
    success, message = call_trigger(args.service, args.timeout)
    print(f"{args.service}: {'success' if success else 'failure'}: {message}")
    return 0 if success else 1


if __name__ == "__main__":
    sys.exit(main())
