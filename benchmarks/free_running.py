"""Free-running cameras against their synchronised twins: the table in docs/timing.md.

Run: .venv/bin/python benchmarks/free_running.py [--seeds 12]

Each seed films one wave (20 s at 30 fps, LEDs at a median 1 m/s, 0.25 px noise) of paper3 and
mixed3 by synchronised global-shutter cameras and by free-running ones (phases up to +-half a frame,
latencies up to +-8 ms, 0.2 ms jitter; global or 20 ms rolling shutters). Each free-running take is
calibrated with its stamps ignored (the views of a frame taken as simultaneous) and with the timing
modelled (``auto``). Prints per rig and case the RMS over seeds and cameras of each error against
the truth, its ratio to the synchronised twin, and the RMS errors of the offsets and readout times
(ms). The calibrations are the ones ``test/core/test_free_running.py`` asserts on.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

import rigs  # the tests' synthetic takes and error measures

from wand_calib_ros.sim.clocks import TakeOptions

MEASURES = ("focal", "principal point", "curve", "E_r", "E_t", "D_RMS")
CASES = (("free-running", TakeOptions()), ("free-running, rolling 20 ms", TakeOptions(readout_s=0.02)))


def _without_stamps(name: str, seed: int, noise: float, options: TakeOptions) -> tuple:  # type: ignore[type-arg]
    scenario, observations, clocks = _take(name, seed, noise, options)
    return scenario, replace(observations, stamps=None), clocks


_take = rigs.timed_take


def _pooled(name: str, options: TakeOptions, seeds: int, *, stamps: bool = True) -> dict[str, list[float]]:
    rigs.timed_take = _take if stamps else _without_stamps  # timed_calibration films through this
    timing = ("auto", "auto") if stamps else ("fixed", "fixed")
    pooled: dict[str, list[float]] = {}
    try:
        for seed in range(seeds):
            for key, values in rigs.timed_calibration.__wrapped__(name, seed, 0.25, options, timing).items():
                pooled.setdefault(key, []).extend(values)
    finally:
        rigs.timed_take = _take
    return pooled


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=12)
    args = parser.parse_args()
    header = " | ".join(MEASURES)
    print(f"| rig | cameras | {header} | offsets RMS (ms) | readout RMS (ms) |")
    print("|---" * (len(MEASURES) + 4) + "|")
    for name in ("paper3", "mixed3"):
        twin = _pooled(name, TakeOptions(free_running=False), args.seeds)
        cells = " | ".join(f"{rigs.rms(twin[m]):.3g}" for m in MEASURES)
        print(f"| {name} | synchronised, global shutter | {cells} | - | - |", flush=True)
        for label, options in CASES:
            for how, stamps in (("not modelled", False), ("estimated", True)):
                pooled = _pooled(name, options, args.seeds, stamps=stamps)
                cells = " | ".join(
                    f"{rigs.rms(pooled[m]):.3g} ({rigs.rms(pooled[m]) / rigs.rms(twin[m]):.2f}x)" for m in MEASURES
                )
                offsets = f"{rigs.rms(pooled['offset']) * 1e3:.2f}" if stamps else "-"
                readout = f"{rigs.rms(pooled['readout']) * 1e3:.2f}" if stamps and options.readout_s else "-"
                print(f"| {name} | {label}, {how} | {cells} | {offsets} | {readout} |", flush=True)


if __name__ == "__main__":
    main()
