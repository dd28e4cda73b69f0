"""``wand-calib report``: an HTML report with figures of a result and the observations it came from."""

from __future__ import annotations

import argparse
from pathlib import Path

from wand_calib_ros.io.observations_csv import read_rig_observations

HELP = "write an HTML calibration report with figures"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("--result", required=True, type=Path, help="result YAML of 'calibrate'")
    parser.add_argument("--observations", required=True, type=Path, help="observations CSV it was computed from")
    parser.add_argument("--cameras", required=True, type=Path, help="rig description (cameras.yaml)")
    parser.add_argument("--out", required=True, type=Path, help="directory for index.html and the PNG figures")


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.io.rig_yaml import load_rig
    from wand_calib_ros.report.html import write_report  # matplotlib only when a report is asked for

    rig = load_rig(args.cameras)
    observations = read_rig_observations(args.observations, rig)
    path = write_report(rig, observations, args.result, args.out, args.observations)
    print(f"report: {path}")
    return 0
