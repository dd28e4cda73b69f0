"""``wand-calib export``: a result in another tool's format."""

from __future__ import annotations

import argparse
from pathlib import Path

from wand_calib_ros.io.export import FORMATS as EXPORT_FORMATS

HELP = "write a result in another tool's format"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("--result", required=True, type=Path, help="result YAML of 'calibrate'")
    parser.add_argument(
        "--format",
        required=True,
        choices=EXPORT_FORMATS,
        help="opencv: FileStorage YAML per camera (cv2.fisheye); anipose: calibration.toml (aniposelib, "
        "caliscope, freemocap); kalibr: camchain.yaml; camera_info: ROS camera_info YAML per camera; dlt: "
        "easyWand/Argus/DLTdv coefficients (pinhole cameras, a calibration with a floor)",
    )
    parser.add_argument("--out", required=True, type=Path, help="directory for the file(s)")


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.export import WORLD_FORMATS, export
    from wand_calib_ros.io.export.cameras import ExportedCamera
    from wand_calib_ros.io.result_yaml import read_result, read_world_poses

    reference, geometry = read_result(args.result)
    order = [reference, *(name for name in geometry if name != reference)]  # the reference first
    world = read_world_poses(args.result) if args.format in WORLD_FORMATS else None
    poses = {name: geometry[name].pose for name in order} if world is None else world
    cameras = [ExportedCamera(name, geometry[name].model, poses[name]) for name in order]
    for path in export(cameras, args.format, args.out):
        print(f"wrote {path}")
    return 0
