"""``wand-calib refine``: cameras that moved since a calibration re-estimated from new views."""

from __future__ import annotations

import argparse
from pathlib import Path

from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.observations_csv import read_rig_observations
from wand_calib_ros.io.outputs import check_writable

HELP = "re-estimate cameras that moved since a calibration, from new views"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    parser.add_argument("--result", required=True, type=Path, help="the calibration's result YAML")
    parser.add_argument("--observations", required=True, type=Path, help="observations CSV of new wand views")
    parser.add_argument("--output", required=True, type=Path, help="result YAML to write")
    parser.add_argument(
        "--moved", help="cameras to re-estimate, comma-separated (default: those the new views show moved)"
    )
    parser.add_argument("--with-intrinsics", action="store_true", help="re-estimate their k1, k2, u0, v0 too")


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.core.after.repair import judge_moved, repair_moved
    from wand_calib_ros.io.result_yaml import read_result, with_cameras_replaced, write_yaml
    from wand_calib_ros.io.rig_yaml import load_rig
    from wand_calib_ros.io.text import read_yaml

    rig = load_rig(args.cameras)
    _, geometry = read_result(args.result)
    missing = [n for n in rig.camera_names if n not in geometry]
    if missing:
        raise WandCalibError(f"{args.result}: no result for camera(s) {', '.join(missing)} of the rig")
    observations = read_rig_observations(args.observations, rig)
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
