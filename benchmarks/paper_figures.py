"""Regenerate the paper's simulation figures (Figs. 4-6) as CSV and PNG into docs/figures.

Run: .venv/bin/python benchmarks/paper_figures.py [--runs 10] [--out docs/figures]
(The same as `wand-calib sweep --out docs/figures`; about 3 minutes with 10 runs per point.)
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from wand_calib_ros.sim.sweeps import paper_sweeps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    start = time.perf_counter()
    for path in paper_sweeps(args.out, runs=args.runs):
        print(f"wrote {path}")
    print(f"{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
