"""ROS 2 nodes: message and parameter translation around the core (the only modules importing rclpy).

Started as an executable (``python -m wand_calib_ros.nodes.<node>`` or a console script), a node
exits 0 on SIGTERM from its first instant: importing rclpy takes most of a second, and before
rclpy installs its signal handlers the default one would end the process with 143. Until then no
node exists and nothing is collected, so the process ends at once (``os._exit``): raising
SystemExit there could land inside a C extension's import (numpy turns it into an ImportError,
exit 1; measured once in 12 starts under load).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path
from types import FrameType

#: The executables whose start this package guards (console scripts, ``ros2 run`` names).
_NODES = ("collector", "calibrator", "detector", "replay", "trigger")
EXECUTABLES = frozenset({*_NODES, *(f"wand-calib-{name}" for name in _NODES), "demo"})


def _stop_quietly(signum: int, frame: FrameType | None) -> None:
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _guard_the_start() -> None:
    starting_node = sys.argv[:1] == ["-m"] or Path(sys.argv[0] if sys.argv else "").name in EXECUTABLES
    if (
        starting_node
        and threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    ):
        signal.signal(signal.SIGTERM, _stop_quietly)


_guard_the_start()
