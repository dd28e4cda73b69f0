"""What estimating time offsets costs: ``wand-calib calibrate`` on mocap16 takes, as a user runs it.

Run: .venv/bin/python benchmarks/timing.py [--repeats 3] [--keep DIR]

A continuous take of the 16-camera 1280x1024 rig (100 fps, 100 s: 10,000 frames, 1 px noise) is
filmed twice: by hardware-triggered cameras, and by free-running ones (phases up to half a frame,
latencies up to 8 ms, 0.2 ms jitter). Each observations CSV (with stamps) is calibrated by the CLI
as a whole process (CSV reading included): the synchronised take with the timing held fixed and
with auto (the timing is tested and dropped), the free-running take with the offsets held fixed (the
stamps' phases still modelled) and estimated. Prints the median wall time and peak RSS of each;
target: estimating the offsets costs at most 1.2x holding them fixed.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.scenarios import mocap_scenario

TAKE = {"duration_s": 100.0, "fps": 100.0}


def _write_takes(folder: Path) -> None:
    scenario = mocap_scenario()
    save_rig(scenario.rig, folder / "cameras.yaml")
    for name, free in (("synchronised", False), ("free-running", True)):
        options = TakeOptions(free_running=free, **TAKE)  # type: ignore[arg-type]
        trajectory = take_trajectory(scenario, options, np.random.default_rng(1))
        clocks = options.clocks(len(scenario.cameras), np.random.default_rng(2))
        takes = film(scenario, trajectory, clocks, options.duration_s, np.random.default_rng(3))
        observations = observe(scenario.rig.camera_names, takes, 1.0, np.random.default_rng(4))
        write_observations(observations, folder / f"{name}.csv")
        print(f"  {name}: {observations.uv.shape[0]} frames, {int(np.isfinite(observations.uv[..., 0]).sum())} points")


def _run(folder: Path, take: str, offsets: str) -> tuple[float, float]:
    """Wall time (s) and peak RSS (MB) of one CLI calibration."""
    command = [
        str(Path(sys.executable).parent / "wand-calib"),
        "-q",
        "calibrate",
        "--cameras",
        str(folder / "cameras.yaml"),
        "--observations",
        str(folder / f"{take}.csv"),
        "--output",
        str(folder / f"{take}-{offsets}.yaml"),
        "--time-offsets",
        offsets,
    ]
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return wall, max(peak, before) / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--keep", type=Path, help="write the takes here (default: a temporary directory)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        print(f"filming mocap16 takes ({TAKE['duration_s']:.0f} s at {TAKE['fps']:.0f} fps) into {folder} ...")
        _write_takes(folder)
        figures = {}
        for take, offsets in (
            ("synchronised", "fixed"),
            ("synchronised", "auto"),
            ("free-running", "fixed"),
            ("free-running", "estimate"),
        ):
            runs = [_run(folder, take, offsets) for _ in range(args.repeats)]
            figures[(take, offsets)] = statistics.median(r[0] for r in runs)
            print(
                f"{take:13s} --time-offsets {offsets:8s}: median {figures[(take, offsets)]:.2f} s of {args.repeats} "
                f"(best {min(r[0] for r in runs):.2f} s), peak RSS {max(r[1] for r in runs):.0f} MB"
            )
        estimate = figures[("free-running", "estimate")]
        print(
            f"estimating the offsets costs {estimate / figures[('free-running', 'fixed')]:.2f}x holding them fixed "
            f"on the same take (target <= 1.2x), {estimate / figures[('synchronised', 'auto')]:.2f}x the "
            f"synchronised take; testing a synchronised take costs "
            f"{figures[('synchronised', 'auto')] / figures[('synchronised', 'fixed')]:.2f}x not testing it"
        )


if __name__ == "__main__":
    main()
