"""The calibration at the physical limit (issue 41): each figure a user sees, with its target and a floor
measured in the same run.

Run: .venv/bin/python benchmarks/limits.py [--repeats 5] [--with-64]

- ``wand-calib calibrate`` as a whole process (CSV read, result written; median of ``--repeats``, peak RSS)
  on mocap16, 16 cameras x 10,000 placements with LEDs seen from everywhere (about 452,000 rows; target
  <= 1.5 s, <= 300 MB and <= 3.5x the floor) and with the default LEDs (about 189,000 rows; <= 1.0 s);
  with ``--with-64`` also stage64, 64 cameras x 50,000 placements (<= 12 s, <= 1.2 GB; it takes minutes).
- The floor: a Python process that imports numpy and pandas and reads the same CSV into arrays.
- ``wand-calib --help`` against ``python -c 'import numpy'`` (<= 0.2 s, <= 2x).
Where each calibration's time goes: ``benchmarks/stages.py --cameras ... --observations ...``.
The live ``/calibrate`` figure (<= 0.5 s on a 60 s, 4-camera, 30 fps buffer) needs ROS: not measured here.
"""

from __future__ import annotations

import argparse
import compileall
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from scaling import calibrate_process
from startup import median_seconds

ROOT = Path(__file__).resolve().parents[1]
#: (label, scenario, placements, LED cone (deg) or None, seconds, MB or None, times the floor or None)
CASES = (
    ("mocap16, LEDs seen from everywhere", "mocap16", 10_000, 180, 1.5, 300.0, 3.5),
    ("mocap16", "mocap16", 10_000, None, 1.0, None, None),
)
LARGE = ("stage64", "stage64", 50_000, None, 12.0, 1200.0, None)
FLOOR = (
    "import sys, numpy, pandas\n"
    "table = pandas.read_csv(sys.argv[1])\n"
    "arrays = [table[name].to_numpy() for name in table.columns]\n"
)


def _simulate(folder: Path, scenario: str, placements: int, cone: int | None) -> int:
    command = [sys.executable, "-m", "wand_calib_ros.cli", "-q", "simulate", scenario, "--seed", "1", "--noise", "1.0"]
    command += ["--placements", str(placements), "--out", str(folder)]
    command += ["--led-cone-deg", str(cone)] if cone is not None else []
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return sum(1 for _ in (folder / "observations.csv").open()) - 1


def _verdict(ok: bool) -> str:
    return "ok" if ok else "over"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--with-64", action="store_true", help="also 64 cameras x 50,000 placements (minutes)")
    args = parser.parse_args()
    compileall.compile_dir(ROOT / "wand_calib_ros", quiet=1)
    for label, scenario, placements, cone, seconds_target, mb_target, ratio_target in (
        *CASES,
        *((LARGE,) if args.with_64 else ()),
    ):
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            rows = _simulate(folder, scenario, placements, cone)
            runs = [calibrate_process(folder, folder / "result.yaml", None) for _ in range(args.repeats)]
            seconds = statistics.median(run[0] for run in runs)
            peak = max(run[1] for run in runs)
            csv = str(folder / "observations.csv")
            floor = median_seconds([sys.executable, "-c", FLOOR, csv], args.repeats)
        figures = [f"{seconds:.2f} s (target <= {seconds_target:g} s: {_verdict(seconds <= seconds_target)})"]
        if mb_target is not None:
            figures.append(f"{peak:.0f} MB (<= {mb_target:g} MB: {_verdict(peak <= mb_target)})")
        else:
            figures.append(f"{peak:.0f} MB")
        ratio = seconds / floor
        figures.append(
            f"{ratio:.1f}x the floor {floor:.2f} s"
            + (f" (<= {ratio_target:g}x: {_verdict(ratio <= ratio_target)})" if ratio_target is not None else "")
        )
        print(f"{label} ({rows:,} rows), median of {args.repeats}: " + ", ".join(figures), flush=True)
    script = Path(sys.executable).parent / "wand-calib"
    cli = [str(script)] if script.exists() else [sys.executable, "-m", "wand_calib_ros.cli"]
    numpy_floor = median_seconds([sys.executable, "-c", "import numpy"], args.repeats * 2)
    help_s = median_seconds([*cli, "--help"], args.repeats * 2)
    print(
        f"wand-calib --help: {help_s:.3f} s (<= 0.2 s: {_verdict(help_s <= 0.2)}), {help_s / numpy_floor:.2f}x "
        f"python -c 'import numpy' {numpy_floor:.3f} s (<= 2x: {_verdict(help_s <= 2 * numpy_floor)})"
    )


if __name__ == "__main__":
    main()
