"""End-to-end time and peak memory of multi-camera calibrations (simulated, 1 px noise).

Run: .venv/bin/python benchmarks/multi_camera.py [paper3 ring6 mocap16]
Each case runs in a fresh child process so peak RSS is its own. Targets on this
2-core machine: paper3 < 0.5 s, ring6 < 2 s, mocap16 (16 cameras x 10,000
placements) < 10 s and < 1 GB.
"""

from __future__ import annotations

import json
import logging
import resource
import statistics
import subprocess
import sys
import time

import numpy as np

TARGETS = {"paper3": (0.5, None), "ring6": (2.0, None), "mocap16": (10.0, 1024.0)}
REPEATS = {"paper3": 7, "ring6": 5, "mocap16": 3}


def _child(name: str) -> None:
    from wand_calib_ros.core.pipeline import calibrate
    from wand_calib_ros.sim.scenarios import SCENARIOS, simulate

    logging.disable(logging.WARNING)
    scenario = SCENARIOS[name]()
    data = simulate(scenario, 1.0, np.random.default_rng(1))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    times = []
    for _ in range(REPEATS[name]):
        start = time.perf_counter()
        result = calibrate(scenario.rig, data.observations)
        times.append(time.perf_counter() - start)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    figures = {
        "best": min(times),
        "median": statistics.median(times),
        "runs": len(times),
        "peak_mb": peak,
        "before_mb": before,
        "cameras": len(scenario.cameras),
        "placements": result.placements_used,
        "observations": result.dof[0] // 2,
        "sigma": result.sigma_px,
    }
    print(json.dumps(figures))


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        _child(sys.argv[2])
        return
    names = sys.argv[1:] or list(TARGETS)
    for name in names:
        out = subprocess.run([sys.executable, __file__, "--child", name], capture_output=True, text=True, check=True)
        figures = json.loads(out.stdout.strip().splitlines()[-1])
        seconds_target, memory_target = TARGETS[name]
        memory = f", peak RSS {figures['peak_mb']:.0f} MB" + (
            f" (target < {memory_target:.0f} MB)" if memory_target else ""
        )
        print(
            f"{name}: {figures['cameras']} cameras, {figures['placements']} placements, "
            f"{figures['observations']} points: best {figures['best']:.2f} s, median {figures['median']:.2f} s "
            f"of {figures['runs']} runs (target < {seconds_target} s){memory}; "
            f"sigma {figures['sigma']:.3f} px"
        )


if __name__ == "__main__":
    main()
