"""The world frame against the truth: two lays of the wand on the floor, or an L-frame, at 1 px.

Prints, per rig and floor, the RMS over seeds of the origin and normal errors in the reference frame
(the world as the result states it) and as the rig measures the floor (the true floor triangulated by
the calibrated cameras, in the result's world), and the errors over the reported standard deviations.

    python benchmarks/floor.py [--seeds 8]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

from rigs import floor_errors


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    seeds = range(parser.parse_args().seeds)
    print("| Rig | Floor | Reference frame: origin, normal | Measured: origin, normal | Error / std (origin, normal) |")
    print("|---|---|---|---|---|")
    for name in ("mocap16", "ring6"):
        for tool in (False, True):
            started = time.perf_counter()
            e = floor_errors(name, tool=tool, seeds=seeds)
            print(
                f"| {name} | {'L-frame' if tool else 'two lays'} | {e['origin']:.2f} mm, {e['normal']:.3f} deg | "
                f"{e['measured origin']:.2f} mm, {e['measured normal']:.3f} deg | {e['z origin']:.2f}, "
                f"{e['z normal']:.2f} |  ({time.perf_counter() - started:.0f} s)",
                flush=True,
            )


if __name__ == "__main__":
    main()
