"""``wand-calib calibrate``: a rig description and observations in, a result (and camera_info files) out."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from wand_calib_ros.collection.floor import read_floor_frames
from wand_calib_ros.core.model.result import TIMING_MODES, CalibrationResult, CameraCalibration
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.outputs import check_writable, is_special

log = logging.getLogger("wand_calib_ros")

HELP = "calibrate a rig from wand observations"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    parser.add_argument("--observations", required=True, type=Path, help="observations CSV (frame,camera,point,u,v)")
    parser.add_argument("--output", required=True, type=Path, help="result YAML to write")
    parser.add_argument("--camera-info-dir", type=Path, help="also write ROS camera_info YAML files here")
    parser.add_argument(
        "--reference", help="reference camera name (default: the one sharing the most placements with the others)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the RANSAC sampler (default 0)")
    parser.add_argument("--truth", type=Path, help="truth YAML (from 'simulate') to compare the result with")
    parser.add_argument(
        "--max-placements",
        type=int,
        help="use at most this many placements, spread over the recording (a time budget for large rigs)",
    )
    parser.add_argument(
        "--floor",
        metavar="FRAMES",
        help="frames (e.g. 120-160,300-340, or a collector's floor_frames.txt) where the wand lies still on "
        "the floor, in two directions: they "
        "set the world frame (z up, origin at the first lay's A, x along its A->C) instead of being calibrated from",
    )
    parser.add_argument(
        "--floor-origin",
        choices=("A", "centre"),
        default="A",
        help="the world's origin: the first lay's A (default) or the wand's centre there",
    )
    parser.add_argument(
        "--time-offsets",
        choices=TIMING_MODES,
        default="auto",
        help="per camera time offsets (exposure = stamp - offset): auto (estimated for free-running cameras, "
        "else when significant), estimate, or fixed at zero (default auto)",
    )
    parser.add_argument(
        "--rolling-shutter",
        choices=TIMING_MODES,
        default="auto",
        help="per camera rolling-shutter readout times: auto (estimated when significant), estimate, or fixed "
        "(zero, or readout_ms of cameras.yaml) (default auto)",
    )


def floor_frames(text: str) -> tuple[int, ...]:
    """``--floor``: frame ids like ``120-160,300``, or a collector's floor_frames.txt (a path: it names an
    existing file, or holds a ``/`` or ends in ``.txt`` or ``.csv``).

    Raises:
        WandCalibError: one line naming the option or the file and what is wrong.
    """
    if not text.strip():
        raise WandCalibError(f"--floor {text!r} names no frame (give frames like 120-160,300-340, or a file)")
    path = Path(text)
    if path.is_dir():
        raise WandCalibError(f"--floor {text}: it is a folder, not a floor_frames.txt or frames like 120-160")
    if path.is_file():
        listed = read_floor_frames(path)
        if not listed:
            raise FormatError(path, "names no frame (one frame id per line)")
        return listed
    if "/" in text or "\\" in text or path.suffix.lower() in (".txt", ".csv"):
        raise FormatError(path, "no such file (--floor takes a floor_frames.txt or frames like 120-160)")
    frames: list[int] = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        first, dash, last = part.partition("-")
        try:
            lo, hi = int(first), int(last) if dash else int(first)
        except ValueError:
            raise WandCalibError(
                f"--floor: {part!r} is not a frame, a range of frames like 120-160, or a floor_frames.txt"
            ) from None
        if hi < lo:
            raise WandCalibError(f"--floor: {part!r}: the range ends before it starts")
        frames.extend(range(lo, hi + 1))
    if not frames:
        raise WandCalibError(f"--floor {text!r} names no frame (give frames like 120-160,300-340, or a file)")
    return tuple(sorted(set(frames)))


def _print_summary(result: CalibrationResult, output: Path) -> None:
    """What was calibrated, on stdout (on stderr when the result itself goes to a terminal or a pipe)."""
    where = sys.stderr if is_special(output) else sys.stdout
    print(f"calibrated {len(result.cameras)} cameras (reference {result.reference_camera}) -> {output}", file=where)
    for camera in result.cameras:
        fx, fy = camera.model.focal_px
        u0, v0 = camera.model.principal_point
        print(
            f"  {camera.name} ({camera.model.distortion_model}): fx {fx:.2f} fy {fy:.2f} px, principal point "
            f"({u0:.2f}, {v0:.2f}) px, RMS {camera.rms_reprojection_px:.3f} px over {camera.n_observations} points"
            + (f"; {', '.join(camera.fixed_coefficients)} fixed at 0" if camera.fixed_coefficients else "")
            + _timing_summary(result, camera),
            file=where,
        )
    print(
        f"  wand {result.wand.ends} {result.wand_length_mean_mm:.2f} +- {result.wand_length_std_mm:.2f} mm "
        f"(nominal {result.wand.L:.1f}), RMS error {result.wand_length_rms_mm:.3f} mm, wand score "
        f"{100 * result.wand_length_std_mm / result.wand_length_mean_mm:.3g} % (100 std / mean, as Argus and easyWand "
        f"give it); {result.placements_used} placements used, {result.placements_rejected} rejected",
        file=where,
    )
    print(
        "  models as OpenCV/ROS have them (camera_info, result 'opencv'): fx = k1*mu, fy = k1*mv, D from k2.. / k1",
        file=where,
    )
    if result.world is not None:
        world = result.world
        print(
            f"  world frame from the floor ({world.placements} placements): plane residual {world.residual_mm:.2f} mm, "
            f"normal +- {world.normal_std_deg:.3f} deg, origin +- {world.origin_std_mm:.2f} mm",
            file=where,
        )
    for line in () if result.timing is None else result.timing.clocks:
        print(f"  clock: {line}", file=where)
    for camera in result.cameras:
        for bias in camera.centre_bias:
            print(f"  centre bias: {bias.line(camera.name)}", file=where)
    if result.quality is not None:
        print(f"  {result.quality.line()}", file=where)
    for warning in result.warnings:
        print(f"  warning: {warning}", file=where)


def _timing_summary(result: CalibrationResult, camera: CameraCalibration) -> str:
    """Per camera time offset and readout time, where estimated."""
    timing = result.timing
    if timing is None:
        return ""
    scale, unit, digits = (1000.0, "ms", 3) if timing.unit == "s" else (1.0, "frames", 4)
    parts = [
        f"{label} {scale * value:+.{digits}f} +- {scale * camera.parameter_std[key]:.{digits}f} {unit}"
        for key, label, value in (
            ("time_offset", "time offset", camera.time_offset),
            ("readout", "readout", camera.readout),
        )
        if key in camera.parameter_std
    ]
    return "; " + ", ".join(parts) if parts else ""


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.core.initialise.pairwise import PairOptions
    from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
    from wand_calib_ros.io.observations_csv import read_rig_observations
    from wand_calib_ros.io.result_yaml import CameraGeometry, calibration_paths, write_calibration
    from wand_calib_ros.io.rig_yaml import load_rig
    from wand_calib_ros.sim.truth import compare_with_truth

    started = time.perf_counter()
    rig = load_rig(args.cameras)
    observations = read_rig_observations(args.observations, rig)
    log.info("read %d frames of %d cameras from %s", observations.uv.shape[0], len(rig.cameras), args.observations)
    if args.max_placements is not None and args.max_placements < 2:
        raise WandCalibError("--max-placements must be at least 2")
    options = CalibrationOptions(
        reference_camera=args.reference,
        pair=PairOptions(seed=args.seed),
        max_placements=args.max_placements,
        time_offsets=args.time_offsets,
        floor_frames=() if args.floor is None else floor_frames(args.floor),
        floor_origin=args.floor_origin,
        rolling_shutter=args.rolling_shutter,
    )
    check_writable(calibration_paths(rig.camera_names, args.output, args.camera_info_dir))  # before the solve
    result = calibrate(rig, observations, options)
    paths = write_calibration(result, args.output, args.camera_info_dir)
    if args.camera_info_dir:
        log.info("wrote camera_info files %s", ", ".join(str(p) for p in paths[1:]))
    log.info("done in %.2f s", time.perf_counter() - started)
    _print_summary(result, args.output)
    if args.truth:
        cameras = {c.name: CameraGeometry(c.model, c.pose, c.time_offset, c.readout) for c in result.cameras}
        unit = "frames" if result.timing is None else result.timing.unit
        print("\n".join(compare_with_truth(result.reference_camera, cameras, result.wand, args.truth, unit)))
    return 0
