"""Extrinsics with the true intrinsics given (held fixed) against estimating everything, same takes.

Prints per rig the RMS over seeds and cameras of E_r (deg) and E_t (the paper's relative
translation error) and the held-out wand-length RMS D_RMS (mm), at 1 px noise:

    python benchmarks/known_intrinsics.py [--seeds 8]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

from rigs import errors_against_truth, in_truth_frame, rms, scenario_data

from wand_calib_ros.core.pipeline import calibrate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=8)
    args = parser.parse_args()
    print("| rig | E_r estimated / given (deg) | E_t estimated / given | D_RMS estimated / given (mm) |")
    print("|---|---|---|---|")
    for name in ("paper", "mixed", "paper3", "ring6"):
        found: dict[str, list[float]] = {}
        for seed in range(args.seeds):
            scenario, data, held = scenario_data(name, seed, noise=1.0)
            cameras = zip(scenario.rig.cameras, scenario.cameras, strict=True)
            specs = tuple(replace(spec, intrinsics=camera.model) for spec, camera in cameras)
            for label, rig in (("estimated", scenario.rig), ("given", replace(scenario.rig, cameras=specs))):
                result = calibrate(rig, data.observations)
                errors = errors_against_truth(scenario, held, *in_truth_frame(result, scenario))
                for kind in ("E_r", "E_t", "D_RMS"):
                    found.setdefault(f"{label} {kind}", []).extend(v for k, v in errors.items() if k.endswith(kind))
        cells = [f"{rms(found[f'estimated {k}']):{f}} / {rms(found[f'given {k}']):{f}}" for k, f in
                 (("E_r", ".3f"), ("E_t", ".4f"), ("D_RMS", ".2f"))]  # fmt: skip
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
