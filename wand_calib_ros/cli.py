"""The offline command ``wand-calib``: simulate rigs and calibrate recorded observations.

Errors a user can cause end the command with exit code 2 and one line on
stderr naming the problem; progress goes to stderr, results to files.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from wand_calib_ros.collection.floor import read_floor_frames
from wand_calib_ros.core.pairwise import PairOptions
from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
from wand_calib_ros.core.result import CalibrationResult, CameraCalibration
from wand_calib_ros.core.rig import WandSpec
from wand_calib_ros.core.timing import TIMING_MODES
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.export import FORMATS as EXPORT_FORMATS
from wand_calib_ros.io.observations_csv import read_observations, write_observations
from wand_calib_ros.io.outputs import check_writable
from wand_calib_ros.io.result_yaml import (
    CameraGeometry,
    calibration_paths,
    camera_entry,
    read_result,
    write_calibration,
    write_yaml,
)
from wand_calib_ros.io.rig_yaml import load_rig, save_rig
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory, truth_timing
from wand_calib_ros.sim.outliers import corrupt
from wand_calib_ros.sim.scenarios import SCENARIOS, image_placements, sample_placements, simulate
from wand_calib_ros.sim.sweeps import paper_sweeps
from wand_calib_ros.sim.truth import compare_with_truth

log = logging.getLogger("wand_calib_ros")

#: Placements in the held-out file written by ``simulate`` (judges D_RMS).
HELDOUT_PLACEMENTS = 100


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
        frames = read_floor_frames(path)
        if not frames:
            raise FormatError(path, "names no frame (one frame id per line)")
        return frames
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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wand-calib", description="Wand calibration of fisheye, conventional and mixed camera rigs."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug output on stderr")
    parser.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors on stderr")
    commands = parser.add_subparsers(dest="command", required=True)

    cal = commands.add_parser("calibrate", help="calibrate a rig from wand observations")
    cal.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    cal.add_argument("--observations", required=True, type=Path, help="observations CSV (frame,camera,point,u,v)")
    cal.add_argument("--output", required=True, type=Path, help="result YAML to write")
    cal.add_argument("--camera-info-dir", type=Path, help="also write ROS camera_info YAML files here")
    cal.add_argument(
        "--reference", help="reference camera name (default: the one sharing the most placements with the others)"
    )
    cal.add_argument("--seed", type=int, default=0, help="seed of the RANSAC sampler (default 0)")
    cal.add_argument("--truth", type=Path, help="truth YAML (from 'simulate') to compare the result with")
    cal.add_argument(
        "--max-placements",
        type=int,
        help="use at most this many placements, spread over the recording (a time budget for large rigs)",
    )
    cal.add_argument(
        "--floor",
        metavar="FRAMES",
        help="frames (e.g. 120-160,300-340, or a collector's floor_frames.txt) where the wand lies still on "
        "the floor, in two directions: they "
        "set the world frame (z up, origin at the first lay's A, x along its A->C) instead of being calibrated from",
    )
    cal.add_argument(
        "--floor-origin",
        choices=("A", "centre"),
        default="A",
        help="the world's origin: the first lay's A (default) or the wand's centre there",
    )
    cal.add_argument(
        "--time-offsets",
        choices=TIMING_MODES,
        default="auto",
        help="per camera time offsets (exposure = stamp - offset): auto (estimated for free-running cameras, "
        "else when significant), estimate, or fixed at zero (default auto)",
    )
    cal.add_argument(
        "--rolling-shutter",
        choices=TIMING_MODES,
        default="auto",
        help="per camera rolling-shutter readout times: auto (estimated when significant), estimate, or fixed "
        "(zero, or readout_ms of cameras.yaml) (default auto)",
    )

    ren = commands.add_parser("render", help="render a scenario's waved wand into a rosbag2 of images")
    ren.add_argument("scenario", choices=sorted(SCENARIOS), help="rig to simulate")
    ren.add_argument(
        "--out", required=True, type=Path, help="directory: bag/ (or bag.bag), cameras.yaml, truth.yaml, drawn.csv"
    )
    ren.add_argument("--frames", type=int, default=300, help="frames per camera (default 300)")
    ren.add_argument("--wand-mm", metavar="POSITIONS", help="another wand (as simulate --wand-mm), e.g. 0,600")
    ren.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    ren.add_argument("--reflections", type=float, default=0.0, help="probability of a spurious spot per image")
    ren.add_argument("--occlusions", type=float, default=0.0, help="probability that an LED is hidden")
    ren.add_argument(
        "--storage",
        choices=("mcap", "sqlite3", "ros1"),
        default="mcap",
        help="bag format (default mcap; ros1: bag.bag)",
    )
    ren.add_argument("--independent", action="store_true", help="independent placements instead of a waved wand")
    _take_arguments(
        ren, "with any of them, a take of --frames / fps seconds at --speed through the cameras' shared view"
    )

    det = commands.add_parser("detect", help="detect the wand in a rosbag2 of camera images")
    det.add_argument("bag", type=Path, help="rosbag2 directory (mcap or sqlite3)")
    det.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    det.add_argument("--output", required=True, type=Path, help="observations CSV to write")
    det.add_argument("--topic", default="/{camera}/image_raw", help="topic pattern (default /{camera}/image_raw)")
    det.add_argument(
        "--sync-tolerance-ms",
        type=float,
        default=0.0,
        help="images further apart never form a frame (default 0: half the frame period)",
    )
    det.add_argument("--debug-dir", type=Path, help="write overlay images (blobs, chosen A/B/C) here")
    det.add_argument("--debug-every", type=int, default=30, help="overlay every N-th image per camera (default 30)")

    rep = commands.add_parser("report", help="write an HTML calibration report with figures")
    rep.add_argument("--result", required=True, type=Path, help="result YAML of 'calibrate'")
    rep.add_argument("--observations", required=True, type=Path, help="observations CSV it was computed from")
    rep.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    rep.add_argument("--out", required=True, type=Path, help="directory for index.html and the PNG figures")

    exp = commands.add_parser("export", help="write a result in another tool's format")
    exp.add_argument("--result", required=True, type=Path, help="result YAML of 'calibrate'")
    exp.add_argument(
        "--format",
        required=True,
        choices=EXPORT_FORMATS,
        help="opencv: FileStorage YAML per camera (cv2.fisheye); anipose: calibration.toml (aniposelib, "
        "caliscope, freemocap); kalibr: camchain.yaml; camera_info: ROS camera_info YAML per camera; dlt: "
        "easyWand/Argus/DLTdv coefficients (pinhole cameras, a calibration with a floor)",
    )
    exp.add_argument("--out", required=True, type=Path, help="directory for the file(s)")

    ref = commands.add_parser("refine", help="re-estimate cameras that moved since a calibration, from new views")
    ref.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    ref.add_argument("--result", required=True, type=Path, help="the calibration's result YAML")
    ref.add_argument("--observations", required=True, type=Path, help="observations CSV of new wand views")
    ref.add_argument("--output", required=True, type=Path, help="result YAML to write")
    ref.add_argument(
        "--moved", help="cameras to re-estimate, comma-separated (default: those the new views show moved)"
    )
    ref.add_argument("--with-intrinsics", action="store_true", help="re-estimate their k1, k2, u0, v0 too")

    imp = commands.add_parser("import", help="read another tool's wand points into an observations CSV")
    imp.add_argument("--format", required=True, choices=("xypts",), help="xypts: easyWand/Argus/DLTdv *xypts.csv")
    imp.add_argument("--points", required=True, type=Path, help="the other tool's point file")
    imp.add_argument("--cameras", required=True, type=Path, help="rig description (camera C = its C-th camera)")
    imp.add_argument("--out", required=True, type=Path, help="observations CSV to write")
    imp.add_argument(
        "--origin",
        choices=("bottom-left", "top-left"),
        default="bottom-left",
        help="the file's pixel origin: bottom-left, y up (Argus, DLTdv; default) or top-left (OpenCV)",
    )

    sweep = commands.add_parser("sweep", help="reproduce the paper's Figs. 4-6 (CSV and PNG)")
    sweep.add_argument("--out", required=True, type=Path, help="directory for fig4-6 CSV and PNG files")
    sweep.add_argument("--runs", type=int, default=10, help="simulations per sweep value (default 10, as the paper)")
    sweep.add_argument("--seed", type=int, default=0, help="base random seed (default 0)")
    sweep.add_argument("--quick", action="store_true", help="only the first, middle and last value of each sweep")

    sim = commands.add_parser("simulate", help="write a synthetic rig with known truth")
    sim.add_argument("scenario", choices=sorted(SCENARIOS), help="rig to simulate")
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument("--noise", type=float, default=1.0, help="pixel noise standard deviation (default 1.0)")
    sim.add_argument("--out", required=True, type=Path, help="directory to write into")
    sim.add_argument("--placements", type=int, help="number of wand placements (scenario default if omitted)")
    sim.add_argument(
        "--outliers",
        type=float,
        default=0.0,
        help="fraction of complete camera views to corrupt (A/C swap, spurious blob, 20 px error)",
    )
    sim.add_argument(
        "--wand-mm",
        metavar="POSITIONS",
        help="another wand: its markers' positions along it in mm, comma-separated from 0 (e.g. 0,120,250,400,600)",
    )
    sim.add_argument(
        "--led-cone-deg",
        type=float,
        metavar="DEG",
        help="half-angle of the LEDs' emission cone (scenario default if omitted; 180: seen from everywhere)",
    )
    sim.add_argument(
        "--plumb-bob",
        action="store_true",
        help="conventional, mixed, mixed3: the conventional cameras' true lenses are plumb_bob ones (tangential terms)",
    )
    sim.add_argument(
        "--known-intrinsics",
        action="store_true",
        help="write every camera's true intrinsics into cameras.yaml (intrinsics, fixed: true), as a board gives them",
    )
    sim.add_argument("--true-focal", type=float, help="paper scenario: true focal length in mm (default 2.0)")
    sim.add_argument(
        "--principal-point",
        type=float,
        nargs=2,
        metavar=("U0", "V0"),
        help="paper scenario: true principal point in px (default 310 250)",
    )
    sim.add_argument(
        "--take",
        type=float,
        metavar="SECONDS",
        help="a continuous wave of this length instead of independent placements",
    )
    _take_arguments(sim, "for --take")
    return parser


def _take_arguments(parser: argparse.ArgumentParser, when: str) -> None:
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


def _take_options(args: argparse.Namespace, duration_s: float) -> TakeOptions:
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


def _timed_take(args: argparse.Namespace) -> bool:
    """Whether render's arguments ask for a take with clocks (else the classic triggered recording)."""
    return bool(args.free_running or args.readout_ms or len(args.fps) > 1 or args.speed != 1000.0)


def _print_summary(result: CalibrationResult, output: Path) -> None:
    print(f"calibrated {len(result.cameras)} cameras (reference {result.reference_camera}) -> {output}")
    for camera in result.cameras:
        fx, fy = camera.model.focal_px
        u0, v0 = camera.model.principal_point
        print(
            f"  {camera.name} ({camera.model.distortion_model}): fx {fx:.2f} fy {fy:.2f} px, principal point "
            f"({u0:.2f}, {v0:.2f}) px, RMS {camera.rms_reprojection_px:.3f} px over {camera.n_observations} points"
            + (f"; {', '.join(camera.fixed_coefficients)} fixed at 0" if camera.fixed_coefficients else "")
            + _timing_summary(result, camera)
        )
    ends = f"|{result.wand.labels[0]}{result.wand.labels[-1]}|"  # |AC| of the three-LED wand
    print(
        f"  wand {ends} {result.wand_length_mean_mm:.2f} +- {result.wand_length_std_mm:.2f} mm "
        f"(nominal {result.wand.L:.1f}), RMS error {result.wand_length_rms_mm:.3f} mm; "
        f"{result.placements_used} placements used, {result.placements_rejected} rejected"
    )
    print("  models as OpenCV/ROS have them (camera_info, result 'opencv'): fx = k1*mu, fy = k1*mv, D from k2.. / k1")
    if result.world is not None:
        world = result.world
        print(
            f"  world frame from the floor ({world.placements} placements): plane residual {world.residual_mm:.2f} mm, "
            f"normal +- {world.normal_std_deg:.3f} deg, origin +- {world.origin_std_mm:.2f} mm"
        )
    if result.quality is not None:
        print(f"  {result.quality.line()}")
    for warning in result.warnings:
        print(f"  warning: {warning}")


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


def _calibrate(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    rig = load_rig(args.cameras)
    observations = read_observations(
        args.observations, rig.camera_names, image_sizes=rig.image_sizes, labels=rig.wand.labels
    )
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


def _wand_positions(text: str) -> WandSpec:
    """The wand of ``--wand-mm 0,120,250,400,600``."""
    try:
        return WandSpec(tuple(float(v) for v in text.split(",")))
    except ValueError:
        raise WandCalibError(f"--wand-mm must be comma-separated numbers in mm, got {text!r}") from None


def _simulate(args: argparse.Namespace) -> int:
    factory = SCENARIOS[args.scenario]
    kwargs: dict[str, object] = {}
    if args.true_focal is not None or args.principal_point is not None:
        if args.scenario != "paper":
            raise WandCalibError("--true-focal and --principal-point apply to the 'paper' scenario only")
        if args.true_focal is not None:
            kwargs["true_focal_mm"] = args.true_focal
        if args.principal_point is not None:
            kwargs["principal_point"] = tuple(args.principal_point)
    if args.placements is not None:
        if args.placements < 1:
            raise WandCalibError("--placements must be positive")
        kwargs["n_placements"] = args.placements
    if args.plumb_bob:
        if args.scenario not in ("conventional", "mixed", "mixed3"):
            raise WandCalibError("--plumb-bob applies to the conventional, mixed and mixed3 scenarios")
        kwargs["pinhole"] = True
    if not (args.noise >= 0):
        raise WandCalibError("--noise must be >= 0")
    if not (0 <= args.outliers < 1):
        raise WandCalibError("--outliers must be a fraction in [0, 1)")
    scenario = factory(**kwargs)
    if args.wand_mm is not None:
        scenario = dataclasses.replace(scenario, wand=_wand_positions(args.wand_mm))
    if args.led_cone_deg is not None:
        if not 0 < args.led_cone_deg <= 180:
            raise WandCalibError(f"--led-cone-deg must be in (0, 180], got {args.led_cone_deg:g}")
        scenario = dataclasses.replace(scenario, led_cone_deg=args.led_cone_deg)
    rng = np.random.default_rng(args.seed)
    timing: dict[str, dict[str, float]] = {}
    if args.take is not None:
        if not args.take > 0:
            raise WandCalibError("--take must be a positive number of seconds")
        take = _take_options(args, args.take)
        clocks = take.clocks(len(scenario.cameras), rng)
        trajectory = take_trajectory(scenario, take, rng)
        observations = observe(
            scenario.rig.camera_names, film(scenario, trajectory, clocks, take.duration_s, rng), args.noise, rng
        )
        timing = truth_timing(scenario.rig.camera_names, clocks)
    else:
        observations = simulate(scenario, args.noise, rng).observations
    if args.outliers > 0:
        sizes = tuple(c.spec.image_size for c in scenario.cameras)
        observations = corrupt(observations, args.outliers, sizes, rng).observations
    heldout = image_placements(
        scenario, *sample_placements(scenario, HELDOUT_PLACEMENTS, rng), args.noise, rng, first_frame=1_000_000
    )
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    rig = scenario.rig
    if args.known_intrinsics:
        cameras = zip(rig.cameras, scenario.cameras, strict=True)
        rig = dataclasses.replace(rig, cameras=tuple(dataclasses.replace(s, intrinsics=c.model) for s, c in cameras))
    save_rig(rig, out / "cameras.yaml")
    write_observations(observations, out / "observations.csv")
    write_observations(heldout.observations, out / "heldout.csv")
    truth = {
        "reference_camera": scenario.cameras[0].spec.name,
        "scenario": scenario.name,
        "seed": args.seed,
        "noise_px": float(args.noise),
        "outlier_fraction": float(args.outliers),
        "cameras": {c.spec.name: camera_entry(c.model, c.pose) | timing.get(c.spec.name, {}) for c in scenario.cameras},
    }
    write_yaml(truth, out / "truth.yaml")
    print(
        f"simulated '{scenario.name}': {len(scenario.cameras)} cameras, {observations.uv.shape[0]} frames, "
        f"noise {args.noise} px -> {out}/cameras.yaml, observations.csv, heldout.csv, truth.yaml"
    )
    return 0


def _render(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.bags import write_image_bag
    from wand_calib_ros.sim.render import RenderOptions, render_recording, render_take

    if args.frames < 1:
        raise WandCalibError("--frames must be positive")
    scenario = SCENARIOS[args.scenario]()
    if args.wand_mm is not None:
        scenario = dataclasses.replace(scenario, wand=_wand_positions(args.wand_mm))
    rng = np.random.default_rng(args.seed)
    options = RenderOptions(reflection_rate=args.reflections, occlusion_rate=args.occlusions)
    names = scenario.rig.camera_names
    timing: dict[str, dict[str, float]] = {}
    if _timed_take(args):
        if args.independent:
            raise WandCalibError("--independent placements have no clocks: leave out the take options")
        take = _take_options(args, args.frames / min(args.fps))
        clocks = take.clocks(len(names), rng)
        takes = film(scenario, take_trajectory(scenario, take, rng), clocks, take.duration_s, rng)
        recording = render_take(scenario, takes, options, rng)
        timing = truth_timing(names, clocks)
    else:
        fps = _take_options(args, 1.0).fps
        assert isinstance(fps, float)
        recording = render_recording(scenario, args.frames, fps, options, rng, independent=args.independent)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    bag = out / ("bag.bag" if args.storage == "ros1" else "bag")
    if bag.exists():
        raise WandCalibError(f"{bag} exists already; choose another --out")
    write_image_bag(bag, recording.frames, names, storage=args.storage)
    save_rig(scenario.rig, out / "cameras.yaml")
    write_observations(recording.drawn, out / "drawn.csv")
    truth = {
        "reference_camera": names[0],
        "scenario": scenario.name,
        "cameras": {c.spec.name: camera_entry(c.model, c.pose) | timing.get(c.spec.name, {}) for c in scenario.cameras},
    }
    write_yaml(truth, out / "truth.yaml")
    print(f"rendered {len(recording.frames)} images of {len(names)} cameras -> {bag} ({args.storage})")
    return 0


def _image_topics(pattern: str, names: tuple[str, ...]) -> dict[str, str]:
    """Each camera's image topic from ``--topic`` (``{camera}`` is the camera's name)."""
    try:
        topics = {name: pattern.format(camera=name) for name in names}
    except (KeyError, IndexError) as error:
        raise WandCalibError(
            f"--topic {pattern!r}: {{{error.args[0]}}} is not a field; the only one is {{camera}} "
            "(e.g. /{camera}/image_raw)"
        ) from None
    except ValueError as error:
        raise WandCalibError(f"--topic {pattern!r}: {error} (the field is {{camera}}; {{{{ is a brace)") from None
    if len(set(topics.values())) < len(topics):
        raise WandCalibError(
            f"--topic {pattern!r} gives every camera the same topic {topics[names[0]]}: put {{camera}} in it, "
            "or one camera's images would be written as another's"
        )
    return topics


def _detect(args: argparse.Namespace) -> int:
    from wand_calib_ros.detection.recording import detect_recording
    from wand_calib_ros.io.bags import count_images, read_image_frames

    cv2.setNumThreads(1)  # per-image work is small: OpenCV's thread pool only adds overhead here
    rig = load_rig(args.cameras)
    topics = _image_topics(args.topic, rig.camera_names)
    check_writable([args.output])  # before reading the bag
    started = time.perf_counter()
    seen: dict[str, int] = {}
    if args.debug_dir is not None:
        args.debug_dir.mkdir(parents=True, exist_ok=True)

    expected = count_images(args.bag, topics)
    show_progress = not args.quiet and expected > 0

    def inspect(frame, blobs, detection, reason) -> None:  # type: ignore[no-untyped-def]
        count = seen[frame.camera] = seen.get(frame.camera, 0) + 1
        total = sum(seen.values())
        if show_progress and (total % 100 == 0 or total == expected):
            done = min(total / expected, 1.0)
            rate = total / max(time.perf_counter() - started, 1e-9)
            bar = "#" * round(30 * done) + "-" * (30 - round(30 * done))
            end = "\n" if total >= expected else ""
            print(f"\rdetect [{bar}] {total}/{expected} images, {rate:.0f}/s", end=end, file=sys.stderr, flush=True)
        if args.debug_dir is not None and (count - 1) % max(args.debug_every, 1) == 0:
            from wand_calib_ros.detection.overlay import draw_overlay

            picture = draw_overlay(frame.image, frame.encoding, blobs, detection, reason)
            cv2.imwrite(str(args.debug_dir / f"{frame.camera}_{frame.stamp_ns}.png"), picture)

    observations, stats, ambiguous = detect_recording(
        read_image_frames(args.bag, topics), rig, tolerance_ns=int(args.sync_tolerance_ms * 1e6), inspect=inspect
    )
    if ambiguous and len(rig.cameras) >= 2:
        observations = _settle_across_cameras(rig, observations, ambiguous, stats)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_observations(observations, args.output)
    print(f"detected the wand in {args.bag} -> {args.output} ({time.perf_counter() - started:.1f} s)")
    for name, counts in stats.items():
        reasons = ", ".join(f"{reason} {n}" for reason, n in sorted(counts.rejected.items())) or "none"
        print(f"  {name}: {counts.images} images, {counts.detected} with the wand; rejected: {reasons}")
    return 0


def _settle_across_cameras(rig, observations, ambiguous, stats):  # type: ignore[no-untyped-def]
    """Label views that neither their image nor time settled, with a calibration of the settled ones."""
    from wand_calib_ros.detection.consistency import label_across_cameras

    try:
        result = calibrate(rig, observations)
    except WandCalibError as error:
        log.info("no calibration to settle %d ambiguous views across cameras: %s", len(ambiguous), error)
        return observations
    observations, settled = label_across_cameras(observations, ambiguous, result, rig.wand)
    for camera in settled:
        stats[camera].rejected["ambiguous"] -= 1
        stats[camera].detected += 1
    log.info("%d of %d ambiguous views settled by the other cameras", len(settled), len(ambiguous))
    return observations


def _report(args: argparse.Namespace) -> int:
    from wand_calib_ros.report.html import write_report  # matplotlib only when a report is asked for

    rig = load_rig(args.cameras)
    observations = read_observations(
        args.observations, rig.camera_names, image_sizes=rig.image_sizes, labels=rig.wand.labels
    )
    path = write_report(rig, observations, args.result, args.out)
    print(f"report: {path}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.export import WORLD_FORMATS, ExportedCamera, export
    from wand_calib_ros.io.result_yaml import read_world_poses

    reference, geometry = read_result(args.result)
    order = [reference, *(name for name in geometry if name != reference)]  # the reference first
    world = read_world_poses(args.result) if args.format in WORLD_FORMATS else None
    poses = {name: geometry[name].pose for name in order} if world is None else world
    cameras = [ExportedCamera(name, geometry[name].model, poses[name]) for name in order]
    for path in export(cameras, args.format, args.out):
        print(f"wrote {path}")
    return 0


def _refine(args: argparse.Namespace) -> int:
    from wand_calib_ros.core.repair import judge_moved, repair_moved
    from wand_calib_ros.io.result_yaml import with_cameras_replaced, write_yaml
    from wand_calib_ros.io.text import read_yaml

    rig = load_rig(args.cameras)
    _, geometry = read_result(args.result)
    missing = [n for n in rig.camera_names if n not in geometry]
    if missing:
        raise WandCalibError(f"{args.result}: no result for camera(s) {', '.join(missing)} of the rig")
    observations = read_observations(
        args.observations, rig.camera_names, image_sizes=rig.image_sizes, labels=rig.wand.labels
    )
    names = rig.camera_names
    models = tuple(geometry[n].model for n in names)
    poses = tuple(geometry[n].pose for n in names)
    document = read_yaml(args.result)
    try:
        sigma = float(document["metrics"]["sigma_px"])
    except (KeyError, TypeError, ValueError):
        raise FormatError(
            args.result, "no metrics sigma_px (the pixel noise new views are judged against): give the result file "
            "wand-calib wrote"
        ) from None  # fmt: skip
    if args.moved is None:
        moved, lines = judge_moved(names, models, poses, rig.wand, sigma, observations.uv)
        for line in lines:
            print(line)
        if not moved:
            print(f"no camera moved: every camera pair of {args.observations} agrees with {args.result}")
            return 0
    else:
        unknown = [n for n in args.moved.split(",") if n.strip() not in names]
        if unknown:
            raise WandCalibError(f"--moved: {', '.join(unknown)} not in the rig ({', '.join(names)})")
        moved = tuple(names.index(n.strip()) for n in args.moved.split(","))
    check_writable([args.output])
    first, fixed = repair_moved(
        models, poses, rig.wand, sigma, observations.uv, moved, intrinsics=args.with_intrinsics, names=names
    )
    updates = {
        names[c]: (fixed.models[c], fixed.poses[c], float(fixed.rms_px[c]), fixed.parameter_std(c)) for c in moved
    }
    after = f" from frame {int(observations.frames[first])} on" if first else ""
    note = (
        f"{', '.join(names[c] for c in moved)} re-estimated by refine from {args.observations}{after} "
        f"({fixed.placements} placements; every other camera as calibrated)"
    )
    write_yaml(with_cameras_replaced(document, updates, note), args.output)
    for c in moved:
        print(f"{names[c]}: re-estimated, RMS {fixed.rms_px[c]:.3f} px on the new views -> {args.output}")
    return 0


def _import(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.imports.xypts import read_xypts

    rig = load_rig(args.cameras)
    observations = read_xypts(args.points, rig, origin=args.origin)
    check_writable([args.out])
    write_observations(observations, args.out)
    views = int(np.any(np.isfinite(observations.uv), axis=(2, 3)).sum())
    print(f"imported {observations.uv.shape[0]} frames, {views} camera views -> {args.out}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    if args.runs < 1:
        raise WandCalibError("--runs must be positive")
    for path in paper_sweeps(args.out, runs=args.runs, seed=args.seed, quick=args.quick):
        print(f"wrote {path}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``wand-calib``."""
    args = _parser().parse_args(argv)
    level = logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    logging.basicConfig(level=level, format="wand-calib: %(message)s", stream=sys.stderr)
    try:
        commands = {
            "calibrate": _calibrate,
            "simulate": _simulate,
            "sweep": _sweep,
            "report": _report,
            "export": _export,
            "import": _import,
            "refine": _refine,
            "detect": _detect,
            "render": _render,
        }
        return commands[args.command](args)
    except WandCalibError as error:
        print(f"wand-calib: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"wand-calib: error: {error.filename or ''}: {error.strerror}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
