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
from typing import Any

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
        if not self.context.ok():  # a signal came while the nodes were being built
            raise ExternalShutdownException()
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

    def _spin(self, executor: Executor) -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass
        except Exception:  # rclpy errors from a context a signal has just shut down
            if self.context.ok():
                raise

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


def _quiet_half_built_executors(unraisable: Any) -> None:
    """sys.unraisablehook: drop rclpy's AttributeError from ``Executor.__del__`` of an executor whose
    ``__init__`` failed because a signal had just shut the context down (an rclpy bug)."""
    if isinstance(unraisable.exc_value, AttributeError) and "_sigint_gc" in str(unraisable.exc_value):
        return
    sys.__unraisablehook__(unraisable)


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
    sys.unraisablehook = _quiet_half_built_executors
    context = Context()
    rclpy.init(
        args=list(argv) if argv is not None else sys.argv,
        context=context,
        signal_handler_options=SignalHandlerOptions.ALL,  # SIGINT and SIGTERM shut the context down
    )
    spinner = Spinner(context)
    stopped = threading.Event()
    context.on_shutdown(stopped.set)
    try:
        for node in build(context):
            spinner.add(node)
        while context.ok() and not stopped.wait(0.2):
            pass
    except WandCalibError as error:
        rclpy.logging.get_logger(name).fatal(str(error))
        code = EXIT_SETTINGS
    except KeyboardInterrupt:  # Ctrl-C (also while the nodes were being built): a clean stop
        code = 0
    except Exception:  # rclpy's RCLError, NotInitializedException, ... once a signal shut the context down
        if context.ok():
            raise
        code = 0  # SIGTERM while the nodes were being built: a clean stop
    else:
        code = 0
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):  # a second Ctrl-C must not interrupt the clean-up
            signal.signal(sig, signal.SIG_IGN)
        spinner.close()
        _shutdown(context)
    return code
