"""``wand-calib import``: another tool's wand points read into an observations CSV, or its intrinsics into the rig
file as given intrinsics."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.io.outputs import check_writable
from wand_calib_ros.io.rig_yaml import load_rig

HELP = "read another tool's wand points into an observations CSV (or its intrinsics into the rig file)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument(
        "--format",
        required=True,
        choices=("xypts", "anipose"),
        help="xypts: easyWand/Argus/DLTdv *xypts.csv (points); anipose: aniposelib's calibration.toml (intrinsics, "
        "as anipose, caliscope and freemocap write it)",
    )
    parser.add_argument(
        "--points", required=True, type=Path, help="the other tool's file (points, or calibration.toml)"
    )
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (camera C = its C-th camera)")
    parser.add_argument(
        "--out", required=True, type=Path, help="observations CSV to write (anipose: the rig file with the intrinsics)"
    )
    parser.add_argument(
        "--as-start",
        action="store_true",
        help="anipose: the intrinsics are a start the calibration refines (fixed: false), not held fixed",
    )
    parser.add_argument(
        "--origin",
        choices=("bottom-left", "top-left"),
        default="bottom-left",
        help="the file's pixel origin: bottom-left, y up (Argus, DLTdv; default) or top-left (OpenCV)",
    )


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.imports.xypts import read_xypts

    if args.format == "anipose":
        return _intrinsics(args)
    rig = load_rig(args.cameras)
    observations = read_xypts(args.points, rig, origin=args.origin)
    check_writable([args.out])
    write_observations(observations, args.out)
    views = int(np.any(np.isfinite(observations.uv), axis=(2, 3)).sum())
    print(f"imported {observations.uv.shape[0]} frames, {views} camera views -> {args.out}")
    return 0


def _intrinsics(args: argparse.Namespace) -> int:
    """anipose: the rig file with each camera's intrinsics from calibration.toml (matched by name, else by order)."""
    from wand_calib_ros.errors import WandCalibError
    from wand_calib_ros.io.imports.anipose import read_anipose
    from wand_calib_ros.io.outputs import write_together
    from wand_calib_ros.io.result_yaml import yaml_text
    from wand_calib_ros.io.text import read_yaml

    rig = load_rig(args.cameras)
    given = read_anipose(args.points)
    by_name = {camera.name: camera for camera in given}
    if all(name in by_name for name in rig.camera_names):
        matched, how = [by_name[name] for name in rig.camera_names], "by name"
    elif len(given) == len(rig.cameras):
        matched, how = given, "in order (its names are not the rig's)"
    else:
        raise WandCalibError(
            f"{args.points}: its cameras {', '.join(by_name)} are neither the rig's ({', '.join(rig.camera_names)}) "
            f"nor as many ({len(given)} against {len(rig.cameras)})"
        )
    for spec, camera in zip(rig.cameras, matched, strict=True):
        if camera.image_size != spec.image_size:
            raise WandCalibError(
                f"{args.points}: camera '{camera.name}' is {camera.image_size[0]}x{camera.image_size[1]}, the rig's "
                f"'{spec.name}' {spec.image_size[0]}x{spec.image_size[1]}: intrinsics are for one image size"
            )
    document = read_yaml(args.cameras)
    for item, camera in zip(document["cameras"], matched, strict=True):
        item["intrinsics"] = {
            "K": [list(row) for row in camera.camera_matrix],
            "D": list(camera.distortion),
            "distortion_model": camera.distortion_model,
            "fixed": not args.as_start,
        }
    check_writable([args.out])
    write_together({args.out: yaml_text(document)})
    load_rig(args.out)  # what was written is a rig file this package reads
    pairs = ", ".join(f"{c.name} -> {s.name} ({c.distortion_model})" for c, s in zip(matched, rig.cameras, strict=True))
    kind = "as a start" if args.as_start else "held fixed"
    print(f"imported the intrinsics of {len(matched)} cameras {how}, {kind}: {pairs} -> {args.out}")
    return 0
