"""Start and stop the package's nodes as child processes (a small launch file in Python).

Used by the live demo, the process tests and the benchmarks. Children run with
this interpreter and a copy of this environment (the ROS wheels' library path
included) plus their own ``ROS_DOMAIN_ID``, and log to a file.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path


def free_domain_id() -> int:
    """A ROS_DOMAIN_ID in 30..199 for an isolated run (not reproducible on purpose)."""
    return random.SystemRandom().randrange(30, 200)


def child_env(domain_id: int) -> dict[str, str]:
    """This process's environment with ``ROS_DOMAIN_ID`` set and unbuffered Python output."""
    return {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONUNBUFFERED": "1"}


def ros_args(params: Mapping[str, bool | int | float | str]) -> list[str]:
    """``--ros-args -p name:=value ...`` with values typed as ROS parses them (5.0 stays a float)."""
    args = ["--ros-args"]
    for name, value in params.items():
        text = (
            str(value).lower() if isinstance(value, bool) else repr(value) if isinstance(value, float) else str(value)
        )
        args += ["-p", f"{name}:={text}"]
    return args


def start(
    module: str,
    params: Mapping[str, bool | int | float | str],
    *,
    domain_id: int,
    log: Path,
    arguments: Sequence[str] = (),
) -> subprocess.Popen[bytes]:
    """Start ``python -m module [arguments] --ros-args -p ...`` with its output in ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("ab") as output:
        return subprocess.Popen(
            [sys.executable, "-m", module, *arguments, *(ros_args(params) if params else [])],
            env=child_env(domain_id),
            stdout=output,
            stderr=subprocess.STDOUT,
        )


def stop(process: subprocess.Popen[bytes], sig: int = signal.SIGINT, timeout_s: float = 30.0) -> int:
    """Send ``sig`` and wait; a process that does not end in time is killed. Returns its exit code."""
    if process.poll() is None:
        process.send_signal(sig)
        try:
            process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return int(process.returncode)
