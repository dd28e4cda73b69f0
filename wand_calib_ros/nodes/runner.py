"""The one ``main()`` body the nodes share: init, build, spin, shut down cleanly.

Ctrl-C and SIGTERM end the spin (rclpy raises ExternalShutdownException); the
nodes' ``close()`` hooks run (the collector flushes its buffer), the executor's
threads are joined and the process exits 0. A :class:`WandCalibError` while
building the nodes (a bad parameter, an unreadable rig file) is one FATAL log
line and exit code 2.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node

from wand_calib_ros.errors import WandCalibError

#: Exit code of a node that could not start (bad parameters or files).
EXIT_SETTINGS = 2


def run(name: str, build: Callable[[Context], list[Node]], argv: Sequence[str] | None = None, threads: int = 4) -> int:
    """Run the nodes ``build`` makes in one multi-threaded executor until shutdown.

    Args:
        name: the executable's name (for the start-up error line).
        build: makes the nodes in the given context (raises WandCalibError on bad settings).
        argv: command line (``--ros-args ...``); ``sys.argv`` when None.
        threads: executor threads.

    Returns:
        The process exit code.
    """
    context = Context()
    rclpy.init(args=list(argv) if argv is not None else sys.argv, context=context)
    try:
        nodes = build(context)
    except WandCalibError as error:
        rclpy.logging.get_logger(name).fatal(str(error))
        rclpy.try_shutdown(context=context)
        return EXIT_SETTINGS
    executor = MultiThreadedExecutor(num_threads=threads, context=context)
    for node in nodes:
        executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for node in nodes:
            close = getattr(node, "close", None)
            if close is not None:
                close()
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
    return 0
