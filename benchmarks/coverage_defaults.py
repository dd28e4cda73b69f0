"""What a minute of waving reaches: the coverage measures of simulated takes, the defaults' basis.

Each seed waves the wand for 60 s at 30 fps (median LED speed 1 m/s) through the volume the rig's
cameras see together (as `wand-calib render` and `simulate --take` do) and prints, per rig, the
smallest value over cameras and seeds of each coverage measure the collector checks: complete
views, share of the 8 x 8 image grid, widest off-axis angle over what the image offers, direction
sectors and depth ratio, at 20 s and at 60 s.

    python benchmarks/coverage_defaults.py [--seeds 4]
"""

from __future__ import annotations

import argparse

import numpy as np

from wand_calib_ros.collection.coverage import DIRECTIONS, CoverageTracker
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.scenarios import SCENARIOS

RIGS = ("paper", "mixed", "paper3", "mixed3", "ring6")


def measures(name: str, seed: int, seconds: float) -> list[tuple[float, float, float, int, float]]:
    """Per camera (placements, image fraction, theta fraction, direction sectors, depth ratio)."""
    scenario = SCENARIOS[name]()
    rng = np.random.default_rng(seed)
    options = TakeOptions(duration_s=seconds, free_running=False)
    clocks = options.clocks(len(scenario.cameras), rng)
    takes = film(scenario, take_trajectory(scenario, options, rng), clocks, seconds, rng)
    observations = observe(scenario.rig.camera_names, takes, 0.3, rng)
    tracker = CoverageTracker(scenario.rig)
    for uv in observations.uv:
        tracker.add(uv)
    status = tracker.status()
    out = []
    for c, camera in enumerate(status.cameras):
        sectors = int((tracker.directions[c] > 0).sum())
        out.append(
            (
                camera.placements,
                camera.image_fraction,
                camera.max_theta_deg / camera.reach_theta_deg,
                sectors,
                tracker._depth_ratio(c),
            )
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=4)
    args = parser.parse_args()
    print(f"| rig | take | placements | image fraction | theta fraction | directions (of {DIRECTIONS}) | depth ratio |")
    print("|---|---|---|---|---|---|---|")
    for name in RIGS:
        for seconds in (20.0, 60.0):
            rows = np.array([m for seed in range(args.seeds) for m in measures(name, seed, seconds)])
            low = rows.min(axis=0)
            cells = f"{low[0]:.0f} | {low[1]:.2f} | {low[2]:.2f} | {low[3]:.0f} | {low[4]:.2f}"
            print(f"| {name} | {seconds:.0f} s | {cells} |")


if __name__ == "__main__":
    main()
