"""Arguments several commands share: a simulated take's clocks (``simulate --take``, ``render``) and
``--wand-mm``."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from wand_calib_ros.core.model.rig import WandSpec
from wand_calib_ros.errors import WandCalibError

if TYPE_CHECKING:
    from wand_calib_ros.sim.clocks import TakeOptions


def take_arguments(parser: argparse.ArgumentParser, when: str) -> None:
    """The cameras' clocks of a simulated take (``simulate --take``, ``render``)."""
    group = parser.add_argument_group(f"cameras' clocks ({when})")
    group.add_argument(
        "--fps", type=float, nargs="+", default=[30.0], help="frame rate, or one per camera (default 30)"
    )
    group.add_argument(
        "--free-running", action="store_true", help="each camera at its own phase and stamp latency (else triggered)"
    )
    group.add_argument(
        "--max-latency-ms", type=float, default=8.0, help="free-running latencies in +- this (default 8)"
    )
    group.add_argument(
        "--max-phase-frames", type=float, default=0.5, help="free-running phases in +- this of a frame (default 0.5)"
    )
    group.add_argument("--jitter-ms", type=float, default=0.2, help="free-running stamp jitter (default 0.2 ms)")
    group.add_argument("--readout-ms", type=float, default=0.0, help="rolling-shutter readout time (default 0: global)")
    group.add_argument("--speed", type=float, default=1000.0, help="median speed of the LEDs, mm/s (default 1000)")


def take_options(args: argparse.Namespace, duration_s: float) -> TakeOptions:
    """The clocks ``take_arguments`` describe, for a take of ``duration_s``.

    Raises:
        WandCalibError: a rate, speed or delay out of range, named.
    """
    from wand_calib_ros.sim.clocks import TakeOptions

    values = (args.max_latency_ms, args.max_phase_frames, args.jitter_ms, args.readout_ms)
    if not all(v >= 0 for v in values) or not all(f > 0 for f in args.fps) or not args.speed > 0:
        raise WandCalibError("--fps and --speed must be positive; latencies, phases, jitter and readout >= 0")
    return TakeOptions(
        duration_s=duration_s,
        fps=tuple(args.fps) if len(args.fps) > 1 else args.fps[0],
        free_running=args.free_running,
        max_phase_frames=args.max_phase_frames,
        max_latency_s=args.max_latency_ms / 1000.0,
        jitter_s=args.jitter_ms / 1000.0,
        readout_s=args.readout_ms / 1000.0,
        speed_mm_s=args.speed,
    )


def timed_take(args: argparse.Namespace) -> bool:
    """Whether render's arguments ask for a take with clocks (else the classic triggered recording)."""
    return bool(args.free_running or args.readout_ms or len(args.fps) > 1 or args.speed != 1000.0)


def wand_positions(text: str) -> WandSpec:
    """The wand of ``--wand-mm 0,120,250,400,600``."""
    try:
        return WandSpec(tuple(float(v) for v in text.split(",")))
    except ValueError:
        raise WandCalibError(f"--wand-mm must be comma-separated numbers in mm, got {text!r}") from None
