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
unreadable rig file), a ``--params-file`` that cannot be read, or a node that ends
with ``exit_code`` set (the replay of an unreadable bag) is one FATAL log line and
exit code 2; a parameter given that no node of the process declares gets a warning
naming the declared one it resembles. ``--help`` (before ``--ros-args``) prints what the
executable does and every parameter it reads, and exits 0.

A node rename on the command line (``-r __node:=NAME``) is meant for the executable's main
node: a second node of the process (the collector's calibrator) is built with
:func:`second_node_arguments`, the process's ROS arguments without that rename, so it keeps
its own name and its params-file section.
"""

from __future__ import annotations

import contextlib
import difflib
import itertools
import os
import re
import signal
import sys
import threading
from collections.abc import Callable, MutableMapping, Sequence
from pathlib import Path
from typing import Any

import rclpy
import yaml
from rclpy._rclpy_pybind11 import RCLError
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import try_shutdown

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
        """Run the nodes' ``close()`` hooks, stop the executors, join the threads, destroy the nodes (after the
        threads: a callback still running would publish through a destroyed publisher)."""
        for node in self.nodes:
            close = getattr(node, "close", None)
            if close is not None:
                close()
        for executor, _ in self._running:
            executor.shutdown()
        for _, thread in self._running:
            thread.join(timeout=10)
        for node in self.nodes:
            node.destroy_node()


#: Fast DDS profile for large images on one machine (see the module docstring).
LARGE_IMAGES_PROFILE = Path(__file__).with_name("fastdds_large_images.xml")


def use_large_image_transport(environ: MutableMapping[str, str]) -> None:
    """Point Fast DDS at :data:`LARGE_IMAGES_PROFILE` unless another RMW or profile was chosen."""
    if environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return
    if "FASTRTPS_DEFAULT_PROFILES_FILE" in environ or "FASTDDS_DEFAULT_PROFILES_FILE" in environ:
        return
    environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(LARGE_IMAGES_PROFILE)


#: What rclpy's ``__del__`` of a half-built object complains of: an executor's ``_sigint_gc``, a
#: guard condition's ``__gc`` (the one the executor was building when the signal came).
_HALF_BUILT = ("_sigint_gc", "_GuardCondition__gc")


def _quiet_half_built_executors(unraisable: Any) -> None:
    """sys.unraisablehook: drop rclpy's AttributeError from ``__del__`` of an executor (or of the signal
    guard condition it was building) whose ``__init__`` failed because a signal had just shut the
    context down (an rclpy bug)."""
    if isinstance(unraisable.exc_value, AttributeError) and any(n in str(unraisable.exc_value) for n in _HALF_BUILT):
        return
    sys.__unraisablehook__(unraisable)


def _shutdown(context: Context) -> None:
    """Shut the context down unless the signal handler is doing it at the same moment."""
    with contextlib.suppress(RuntimeError):  # "rcl_shutdown already called"
        try_shutdown(context=context)


#: Parameters rclpy itself reads or may be given for any node.
ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")


def undeclared_parameters(nodes: Sequence[Node]) -> list[str]:
    """One warning per parameter given to these nodes (``-p``, ``--params-file``) that none of them declares
    (a misspelt name would otherwise be ignored), with the declared names it resembles."""
    given: set[str] = set()
    declared: set[str] = set(ROS_PARAMETERS)
    for node in nodes:
        given |= set(getattr(node, "_parameter_overrides", {}))  # rclpy keeps the overrides only here
        declared |= set(node._parameters)
    unknown = sorted(n for n in given - declared if not n.startswith("qos_overrides."))
    lines = []
    for parameter in unknown:
        near = difflib.get_close_matches(parameter, sorted(declared), n=1, cutoff=0.6)
        hint = f" (did you mean {near[0]}?)" if near else ""
        lines.append(
            f"parameter {parameter} is not a parameter of {', '.join(n.get_name() for n in nodes)}: ignored{hint}"
        )
    return lines


def params_file_problem(args: Sequence[str]) -> str | None:
    """What is wrong with the first ``--params-file`` of ``args`` that cannot be read as YAML (None: nothing)."""
    for flag, value in itertools.pairwise(args):
        if flag != "--params-file":
            continue
        try:
            yaml.safe_load(Path(value).read_text(encoding="utf-8"))
        except OSError as error:
            return f"parameter file {value}: cannot read: {error.strerror}"
        except (UnicodeDecodeError, yaml.YAMLError) as error:
            return f"parameter file {value}: not valid YAML: {' '.join(str(error).split())}"
    return None


def _init_error(message: str) -> str:
    """One line from rcl's initialisation error, naming the parameter file when it is the cause."""
    found = re.search(r"Couldn't parse params file: '--params-file (.*?)'\. Error: (.*?)(?:, at /|$)", message, re.S)
    if found:
        return f"parameter file {found[1]}: {' '.join(found[2].split())}"
    return "cannot start ROS: " + " ".join(message.split(", at /")[0].split())


#: Remap rules that rename "the" node of a process (rcl applies them to every node it starts).
_RENAMES = ("__node:=", "__name:=")


def second_node_arguments(args: Sequence[str]) -> list[str]:
    """The ROS arguments of ``args`` (every ``--ros-args`` block) without an untargeted node rename.

    Passed as ``cli_args`` with ``use_global_arguments=False`` to a second node of the process,
    it keeps namespace remaps, parameters, params files and log levels but not the main node's
    new name (a rename targeted at it, ``wand_calib_calibrator:__node:=cal``, still applies).
    """
    kept: list[str] = ["--ros-args"]
    inside = dropping = False
    for index, token in enumerate(args):
        if dropping:
            dropping = False
        elif token == "--ros-args":
            inside = True
        elif token == "--":
            inside = False
        elif inside:
            following = args[index + 1] if index + 1 < len(args) else ""
            if token in ("-r", "--remap") and following.startswith(_RENAMES):
                dropping = True
            else:
                kept.append(token)
    return kept


def wants_help(args: Sequence[str]) -> bool:
    """``-h`` or ``--help`` among the arguments before the first ``--ros-args``."""
    before = list(args[1:])
    if "--ros-args" in before:
        before = before[: before.index("--ros-args")]
    return "-h" in before or "--help" in before


def run(
    name: str,
    build: Callable[[Context, Sequence[str]], list[Node]],
    argv: Sequence[str] | None = None,
    *,
    help_text: str = "",
) -> int:
    """Run the nodes ``build`` makes until Ctrl-C, SIGTERM or their context shuts down.

    Args:
        name: the executable's name (for the start-up error line).
        build: makes the nodes in the given context from the command line (raises
            WandCalibError on bad settings).
        argv: command line (``--ros-args ...``); ``sys.argv`` when None.
        help_text: printed for ``--help`` (exit 0 without starting ROS).

    Returns:
        The process exit code.
    """
    args = list(argv) if argv is not None else sys.argv
    if help_text and wants_help(args):
        print(help_text)
        return 0
    use_large_image_transport(os.environ)  # before the first participant reads the profile
    sys.unraisablehook = _quiet_half_built_executors
    problem = params_file_problem(args)
    if problem is not None:  # before rcl, which would add its own error line
        rclpy.logging.get_logger(name).fatal(problem)
        return EXIT_SETTINGS
    context = Context()
    try:
        rclpy.init(
            args=args,
            context=context,
            signal_handler_options=SignalHandlerOptions.ALL,  # SIGINT and SIGTERM shut the context down
        )
    except RCLError as error:  # a missing or malformed --params-file, a bad --ros-args
        rclpy.logging.get_logger(name).fatal(_init_error(str(error)))
        return EXIT_SETTINGS
    spinner = Spinner(context)
    stopped = threading.Event()
    context.on_shutdown(stopped.set)
    try:
        nodes = build(context, args)
        for node in nodes:
            spinner.add(node)
        for line in undeclared_parameters(nodes):
            rclpy.logging.get_logger(name).warning(line)
        while context.ok() and not stopped.wait(0.2):
            pass
    except WandCalibError as error:  # (in the log of the node it concerns, when it names one)
        rclpy.logging.get_logger(getattr(error, "node", "") or name).fatal(str(error))
        code = EXIT_SETTINGS
    except KeyboardInterrupt:  # Ctrl-C (also while the nodes were being built): a clean stop
        code = 0
    except Exception:  # rclpy's RCLError, NotInitializedException, ... once a signal shut the context down
        if context.ok():
            raise
        code = 0  # SIGTERM while the nodes were being built: a clean stop
    else:
        code = max((int(getattr(node, "exit_code", 0)) for node in nodes), default=0)  # a node that failed
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):  # a second Ctrl-C must not interrupt the clean-up
            signal.signal(sig, signal.SIG_IGN)
        spinner.close()
        _shutdown(context)
    if any(getattr(node, "working", False) for node in spinner.nodes):
        # A solve still runs in a daemon thread: interpreter finalisation would end it with
        # pthread_exit inside scipy's C++ code, and the process would abort (SIGABRT) instead of
        # exiting with its code. Everything collected is already stored and synced.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code
