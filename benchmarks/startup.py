"""How fast ``wand-calib`` answers before any work: ``--help`` and an argument error, as a user starts it.

Run: .venv/bin/python benchmarks/startup.py [--repeats 9]

Prints the median wall time of each (a fresh process every time, the package's bytecode compiled first) and
the floor measured in the same run: a process that only imports numpy. Target (issue 41): ``--help`` <= 0.2 s
and <= 2x the floor.
"""

from __future__ import annotations

import argparse
import compileall
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 0.2
TARGET_RATIO = 2.0


def median_seconds(argv: list[str], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        subprocess.run(argv, capture_output=True, check=False)
        times.append(time.perf_counter() - began)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args()
    compileall.compile_dir(ROOT / "wand_calib_ros", quiet=1)
    script = Path(sys.executable).parent / "wand-calib"  # the installed command, as a user starts it
    cli = [str(script)] if script.exists() else [sys.executable, "-m", "wand_calib_ros.cli"]
    floor = median_seconds([sys.executable, "-c", "import numpy"], args.repeats)
    rows = {
        "wand-calib --help": median_seconds([*cli, "--help"], args.repeats),
        "wand-calib calibrate --help": median_seconds([*cli, "calibrate", "--help"], args.repeats),
        "wand-calib calibrate (argument error)": median_seconds([*cli, "calibrate"], args.repeats),
    }
    print(f"floor: python -c 'import numpy'  {floor:.3f} s (median of {args.repeats})")
    for label, seconds in rows.items():
        verdict = "ok" if seconds <= TARGET_S and seconds <= TARGET_RATIO * floor else "over"
        print(
            f"{label:<40} {seconds:.3f} s  {seconds / floor:.2f}x the floor  "
            f"(target <= {TARGET_S} s and <= {TARGET_RATIO:g}x: {verdict})"
        )


if __name__ == "__main__":
    main()
