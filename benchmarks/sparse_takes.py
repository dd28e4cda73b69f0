"""Real recordings as users have them: sparse takes and plumb_bob cameras, against the floor.

Prints two tables (RMS over seeds and cameras; the floor is the bundle adjustment started from the
truth on the same placements, with the same terms held):

- the sparse four-camera take of ``simulate sparse4`` (two-LED wand of 289.6 mm, 2560x1600 cameras with
  16 mm plumb_bob lenses, 1 px; labels swapped in a random half of the views): with the true intrinsics
  given, and with them estimated (plumb_bob stated) on 100 and on 200 frames, how many seeds calibrate or
  are refused, E_r, E_t, the held-out wand length D_RMS and the wand-length spread (std / mean);
- plumb_bob on the paper's conventional pair and mixed rig (true plumb_bob lenses): stated by the rig,
  given as intrinsics, and chosen by the data (at 0.2 px, where their tangential terms show).

    python benchmarks/sparse_takes.py [--seeds 8]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

from rigs import errors_against_truth, in_truth_frame, rms, truth_bundle

from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.scenarios import SCENARIOS, Scenario, simulate

KINDS = ("focal", "principal point", "E_r", "E_t", "D_RMS")


def _given(scenario: Scenario) -> RigSpec:
    cameras = zip(scenario.rig.cameras, scenario.cameras, strict=True)
    return replace(scenario.rig, cameras=tuple(replace(spec, intrinsics=c.model) for spec, c in cameras))


def _stated(scenario: Scenario) -> RigSpec:
    cameras = zip(scenario.rig.cameras, scenario.cameras, strict=True)
    return replace(scenario.rig, cameras=tuple(replace(s, camera_model=c.model.distortion_model) for s, c in cameras))


def _chosen(scenario: Scenario) -> RigSpec:
    return scenario.rig


def _run(
    make: Callable[[int], tuple[Scenario, np.ndarray, np.ndarray, object, object]],
    rig_of: Callable[[Scenario], RigSpec],
    held: bool,
    seeds: int,
) -> tuple[dict[str, list[float]], dict[str, list[float]], list[float], int, float]:
    """(our errors, the floor's, wand-length spreads %, refusals, seconds per calibration) over the seeds."""
    ours: dict[str, list[float]] = {k: [] for k in KINDS}
    floor: dict[str, list[float]] = {k: [] for k in KINDS}
    spreads, refused, seconds = [], 0, []
    for seed in range(seeds):
        scenario, observed, true_uv, data, held_out = make(seed)
        started = time.perf_counter()
        try:
            result = calibrate(rig_of(scenario), data.observations.with_uv(observed))  # type: ignore[attr-defined]
        except (InsufficientDataError, DegenerateDataError):
            refused += 1
            continue
        seconds.append(time.perf_counter() - started)
        spreads.append(100 * result.wand_length_std_mm / result.wand_length_mean_mm)
        truth = replace(data, observations=data.observations.with_uv(true_uv))  # type: ignore[type-var]
        usable = truth.observations.complete.sum(axis=1) >= 2
        fixed = tuple(result.camera(c.spec.name).fixed_coefficients for c in scenario.cameras)
        adjusted = truth_bundle(scenario, truth, fixed, held=held, placements=usable)
        for errors, pooled in (
            (errors_against_truth(scenario, held_out, *in_truth_frame(result, scenario)), ours),  # type: ignore[arg-type]
            (errors_against_truth(scenario, held_out, adjusted.state.models, adjusted.state.poses), floor),  # type: ignore[arg-type]
        ):
            for key, value in errors.items():
                for kind in KINDS:
                    if key.endswith(kind):
                        pooled[kind].append(value)
    return ours, floor, spreads, refused, float(np.median(seconds)) if seconds else float("nan")


def _sparse(frames: int) -> Callable[[int], tuple[Scenario, np.ndarray, np.ndarray, object, object]]:
    def make(seed: int) -> tuple[Scenario, np.ndarray, np.ndarray, object, object]:
        scenario = SCENARIOS["sparse4"](n_placements=frames)
        rng = np.random.default_rng(seed)
        data = simulate(scenario, 1.0, rng)
        held = simulate(replace(scenario, view_rates=None, marker_loss=0.0), 1.0, rng, n=100)
        uv = data.observations.uv
        swap = np.random.default_rng(100 + seed).random(uv.shape[:2]) < 0.5
        observed = uv.copy()
        observed[swap] = uv[swap][:, ::-1]
        return scenario, observed, uv, data, held

    return make


def _pinhole(name: str, noise: float) -> Callable[[int], tuple[Scenario, np.ndarray, np.ndarray, object, object]]:
    def make(seed: int) -> tuple[Scenario, np.ndarray, np.ndarray, object, object]:
        scenario = SCENARIOS[name](pinhole=True)
        rng = np.random.default_rng(seed)
        data = simulate(scenario, noise, rng)
        return scenario, data.observations.uv, data.observations.uv, data, simulate(scenario, noise, rng, n=100)

    return make


def _cell(ours: list[float], floor: list[float], digits: str) -> str:
    if not ours:
        return "-"
    if rms(floor) == 0:
        return f"{rms(ours):{digits}} (given)"
    return f"{rms(ours):{digits}} / {rms(floor):{digits}} ({rms(ours) / rms(floor):.2f}x)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=8)
    args = parser.parse_args()
    formats = {"focal": ".2f", "principal point": ".1f", "E_r": ".3f", "E_t": ".4f", "D_RMS": ".2f"}
    header = "| focal (px) | principal point (px) | E_r (deg) | E_t | D_RMS (mm) |"
    print(f"Sparse take (sparse4, 1 px, {args.seeds} seeds): ours / floor")
    print(f"| frames | intrinsics | calibrated | {header[2:]} wand spread | time |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for frames, label, rig_of, held in (
        (100, "given", _given, True),
        (100, "estimated (plumb_bob)", _stated, False),
        (200, "estimated (plumb_bob)", _stated, False),
    ):
        ours, floor, spreads, refused, seconds = _run(_sparse(frames), rig_of, held, args.seeds)
        cells = " | ".join(_cell(ours[k], floor[k], formats[k]) for k in KINDS)
        spread = f"{np.mean(spreads):.2f} %" if spreads else "-"
        print(
            f"| {frames} | {label} | {args.seeds - refused} of {args.seeds} (refused {refused}) | {cells} | "
            f"{spread} | {seconds:.2f} s |"
        )
    print()
    print(f"plumb_bob lenses ({args.seeds} seeds): ours / floor")
    print(f"| rig | noise | plumb_bob | {header[2:]}")
    print("|---|---|---|---|---|---|---|---|")
    for name in ("conventional", "mixed"):
        for noise, label, rig_of, held in (
            (1.0, "stated", _stated, False),
            (1.0, "given", _given, True),
            (0.2, "chosen by the data", _chosen, False),
        ):
            ours, floor, _, _, _ = _run(_pinhole(name, noise), rig_of, held, args.seeds)
            print(
                f"| {name} | {noise} px | {label} | "
                + " | ".join(_cell(ours[k], floor[k], formats[k]) for k in KINDS)
                + " |"
            )


if __name__ == "__main__":
    main()
