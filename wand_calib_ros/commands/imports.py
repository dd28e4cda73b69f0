"""``wand-calib import``: another tool's wand points read into an observations CSV."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.io.outputs import check_writable
from wand_calib_ros.io.rig_yaml import load_rig

HELP = "read another tool's wand points into an observations CSV"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("--format", required=True, choices=("xypts",), help="xypts: easyWand/Argus/DLTdv *xypts.csv")
    parser.add_argument("--points", required=True, type=Path, help="the other tool's point file")
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (camera C = its C-th camera)")
    parser.add_argument("--out", required=True, type=Path, help="observations CSV to write")
    parser.add_argument(
        "--origin",
        choices=("bottom-left", "top-left"),
        default="bottom-left",
        help="the file's pixel origin: bottom-left, y up (Argus, DLTdv; default) or top-left (OpenCV)",
    )


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.imports.xypts import read_xypts

    rig = load_rig(args.cameras)
    observations = read_xypts(args.points, rig, origin=args.origin)
    check_writable([args.out])
    write_observations(observations, args.out)
    views = int(np.any(np.isfinite(observations.uv), axis=(2, 3)).sum())
    print(f"imported {observations.uv.shape[0]} frames, {views} camera views -> {args.out}")
    return 0
