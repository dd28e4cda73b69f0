"""How the nodes are spun, and the one ``main()`` body they share.

Each node gets its own executor in its own thread (:class:`Spinner`). Nodes that
take images use a SingleThreadedExecutor: measured here, rclpy's
MultiThreadedExecutor dropped about half of 240 small messages/s (and of 120
images/s) while the single-threaded one took every one. A node whose callbacks
must overlap (the calibrator answers "in progress" while it solves) sets
``EXECUTOR_THREADS`` above 1.

Camera images are large: unless the user chose a Fast DDS profile, the nodes load
``fastdds_large_images.xml`` (a 64 MB shared-memory segment instead of 0.5 MB).
Fast DDS puts a sample into its sender's segment, so this matters for the
images a node publishes (``wand-calib-replay``); camera drivers on the same
machine need the same profile for best-effort 1280x1024 images (measured
here at 4 x 30 fps: 51 % dropped without it, none with it; reliable delivery
dropped none either way).

Ctrl-C and SIGTERM shut the context down; the nodes' ``close()`` hooks run (the
collector flushes its buffer), the executor threads are joined and the process
exits 0. A :class:`WandCalibError` while building the nodes (a bad parameter, an
unreadable rig file) is one FATAL log line and exit code 2.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, MutableMapping, Sequence
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from wand_calib_ros.errors import WandCalibError

#: Exit code of a node that could not start (bad parameters or files).
EXIT_SETTINGS = 2


class Spinner:
    """Spins each added node in its own executor and thread; :meth:`close` stops them all."""

    def __init__(self, context: Context) -> None:
        self.context = context
        self.nodes: list[Node] = []
        self._running: list[tuple[Executor, threading.Thread]] = []

    def add(self, node: Node) -> Node:
        threads = int(getattr(node, "EXECUTOR_THREADS", 1))
        executor: Executor = (
            MultiThreadedExecutor(num_threads=threads, context=self.context)
            if threads > 1
            else SingleThreadedExecutor(context=self.context)
        )
        executor.add_node(node)
        thread = threading.Thread(target=self._spin, args=(executor,), name=f"spin {node.get_name()}", daemon=True)
        thread.start()
        self.nodes.append(node)
        self._running.append((executor, thread))
        return node

    @staticmethod
    def _spin(executor: Executor) -> None:
        with contextlib.suppress(ExternalShutdownException):
            executor.spin()

    def close(self) -> None:
        """Run the nodes' ``close()`` hooks, stop the executors, destroy the nodes, join the threads."""
        for node in self.nodes:
            close = getattr(node, "close", None)
            if close is not None:
                close()
        for executor, _ in self._running:
            executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        for _, thread in self._running:
            thread.join(timeout=10)


#: Fast DDS profile for large images on one machine (see the module docstring).
LARGE_IMAGES_PROFILE = Path(__file__).with_name("fastdds_large_images.xml")


def use_large_image_transport(environ: MutableMapping[str, str]) -> None:
    """Point Fast DDS at :data:`LARGE_IMAGES_PROFILE` unless another RMW or profile was chosen."""
    if environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return
    if "FASTRTPS_DEFAULT_PROFILES_FILE" in environ or "FASTDDS_DEFAULT_PROFILES_FILE" in environ:
        return
    environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(LARGE_IMAGES_PROFILE)


def _shutdown(context: Context) -> None:
    """Shut the context down unless the signal handler is doing it at the same moment."""
    with contextlib.suppress(RuntimeError):  # "rcl_shutdown already called"
        rclpy.try_shutdown(context=context)


def run(name: str, build: Callable[[Context], list[Node]], argv: Sequence[str] | None = None) -> int:
    """Run the nodes ``build`` makes until Ctrl-C, SIGTERM or their context shuts down.

    Args:
        name: the executable's name (for the start-up error line).
        build: makes the nodes in the given context (raises WandCalibError on bad settings).
        argv: command line (``--ros-args ...``); ``sys.argv`` when None.

    Returns:
        The process exit code.
    """
    use_large_image_transport(os.environ)  # before the first participant reads the profile
    context = Context()
    rclpy.init(
        args=list(argv) if argv is not None else sys.argv,
        context=context,
        signal_handler_options=SignalHandlerOptions.ALL,  # SIGINT and SIGTERM shut the context down
    )
    try:
        nodes = build(context)
    except WandCalibError as error:
        rclpy.logging.get_logger(name).fatal(str(error))
        _shutdown(context)
        return EXIT_SETTINGS
    except KeyboardInterrupt:  # Ctrl-C while the nodes were being built: a clean stop
        _shutdown(context)
        return 0
    except Exception:  # rclpy's RCLError, NotInitializedException, ... once a signal shut the context down
        if context.ok():
            raise
        return 0  # SIGTERM while the nodes were being built: a clean stop
    stopped = threading.Event()
    context.on_shutdown(stopped.set)
    spinner = Spinner(context)
    for node in nodes:
        spinner.add(node)
    try:
        while context.ok() and not stopped.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):  # a second Ctrl-C must not interrupt the clean-up
            signal.signal(sig, signal.SIG_IGN)
        spinner.close()
        _shutdown(context)
    return 0
