"""End-to-end time of the two-fisheye calibration (the paper's simulation, 300 placements, 1 px noise).

Run: .venv/bin/python benchmarks/two_camera.py [--repeats N]
Prints the median and best wall time of ``calibrate`` (input already in memory) and of the whole
``wand-calib calibrate`` command path (reading files, writing the result), and the peak RSS.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from wand_calib_ros.cli import main as cli_main
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate


def _time(fn, repeats: int) -> list[float]:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    logging.disable(logging.WARNING)  # time the solver, not the console
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 1.0, np.random.default_rng(1))
    calibrate(scenario.rig, data.observations)  # warm-up (imports, caches)
    core = _time(lambda: calibrate(scenario.rig, data.observations), args.repeats)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        with contextlib.redirect_stdout(io.StringIO()):
            cli_main(["-q", "simulate", "paper", "--seed", "1", "--out", str(out)])
        argv = [
            "-q",
            "calibrate",
            "--cameras",
            str(out / "cameras.yaml"),
            "--observations",
            str(out / "observations.csv"),
            "--output",
            str(out / "result.yaml"),
        ]
        with contextlib.redirect_stdout(io.StringIO()):
            command = _time(lambda: cli_main(argv), args.repeats)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"two-fisheye calibration (paper, 300 placements, 2 cameras), {args.repeats} runs:")
    print(f"  calibrate():            median {statistics.median(core):.3f} s, best {min(core):.3f} s (target < 0.5 s)")
    print(f"  wand-calib calibrate:   median {statistics.median(command):.3f} s, best {min(command):.3f} s")
    print(f"  peak RSS of this process: {peak_mb:.0f} MB")


if __name__ == "__main__":
    main()
