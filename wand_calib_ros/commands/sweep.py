"""``wand-calib sweep``: the paper's Figs. 4-6 reproduced (CSV and PNG)."""

from __future__ import annotations

import argparse
from pathlib import Path

from wand_calib_ros.errors import WandCalibError

HELP = "reproduce the paper's Figs. 4-6 (CSV and PNG)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("--out", required=True, type=Path, help="directory for fig4-6 CSV and PNG files")
    parser.add_argument("--runs", type=int, default=10, help="simulations per sweep value (default 10, as the paper)")
    parser.add_argument("--seed", type=int, default=0, help="base random seed (default 0)")
    parser.add_argument("--quick", action="store_true", help="only the first, middle and last value of each sweep")


def run(args: argparse.Namespace) -> int:
    from wand_calib_ros.sim.sweeps import paper_sweeps

    if args.runs < 1:
        raise WandCalibError("--runs must be positive")
    for path in paper_sweeps(args.out, runs=args.runs, seed=args.seed, quick=args.quick):
        print(f"wrote {path}")
    return 0
