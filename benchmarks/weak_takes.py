"""Weak takes like the recordings of other tools (issue 33): a narrow-field rig with its nominal focal 2.5x off,
a small far wand with given plumb_bob intrinsics, a short sparse take with its intrinsics estimated.

Prints per case over the seeds: how many calibrate, ours / the floor (the adjustment of the same data
started from the truth with what the case holds held the same way) as RMS over seeds and cameras for the
focal length, E_r, E_t and the held-out wand D_RMS, the wand score (100 x std / mean of the triangulated
wand, the other tools' figure) ours and the floor's, and error / reported std RMS over focal, principal
point, rotation and translation:

    python benchmarks/weak_takes.py [--seeds 8]
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

from rigs import errors_against_truth, fixed_of, in_truth_frame, rms, scenario_data, truth_bundle, z_scores

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import BundleProblem, BundleState, default_free_mask
from wand_calib_ros.core.adjust.narrow_field import DISTORTION, PRINCIPAL_POINT, pinhole_at_centre
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.errors import CoreError
from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.scenarios import Scenario, SimulatedData


def _centre_floor(scenario: Scenario, data: SimulatedData, fixed: bool) -> BundleResult:
    """The truth's adjustment with the principal point held at the image centre (and the focal, ``fixed``)."""
    starts = tuple(pinhole_at_centre(camera.model) for camera in scenario.cameras)
    free = default_free_mask(len(starts), 0, starts)
    free[:, DISTORTION] = free[:, PRINCIPAL_POINT] = False
    free[:, 0] = not fixed
    state = BundleState(starts, tuple(c.pose for c in scenario.cameras), data.wand_a, data.wand_direction)
    return bundle_adjust(state, BundleProblem.from_dense(scenario.wand, data.observations.uv), free)


def _given(scenario: Scenario, fixed: bool, centre: bool = False) -> RigSpec:
    cameras = tuple(
        replace(spec, intrinsics=pinhole_at_centre(c.model) if centre else c.model, intrinsics_fixed=fixed)
        for spec, c in zip(scenario.rig.cameras, scenario.cameras, strict=True)
    )
    return replace(scenario.rig, cameras=cameras)


def _wand_score(models, poses, uv) -> float:  # type: ignore[no-untyped-def]
    points = triangulate_placements(tuple(models), tuple(poses), uv)
    lengths = np.linalg.norm(points[:, -1] - points[:, 0], axis=-1)
    lengths = lengths[np.isfinite(lengths)]
    return float(100 * np.std(lengths) / np.mean(lengths))


Case = tuple[str, str, dict[str, object], float, Callable[[Scenario], RigSpec], Callable[..., BundleResult]]
CASES: list[Case] = [
    ("narrow4, nominal 2.5x off, estimated", "narrow4", {}, 0.5, lambda s: s.rig,
     lambda s, d, r: _centre_floor(s, d, False)),
    ("narrow4, focal given as a start", "narrow4", {}, 0.5, lambda s: _given(s, False, True),
     lambda s, d, r: _centre_floor(s, d, False)),
    ("narrow4, focal given and held", "narrow4", {}, 0.5, lambda s: _given(s, True, True),
     lambda s, d, r: _centre_floor(s, d, True)),
    ("action2, plumb_bob given, small far wand", "action2", {}, 1.0, lambda s: _given(s, True),
     lambda s, d, r: truth_bundle(s, d, held=True)),
    ("sparse4, 200 frames, estimated", "sparse4", {"n_placements": 200}, 1.0, lambda s: s.rig,
     lambda s, d, r: truth_bundle(s, d, fixed_of(r, s), placements=d.observations.complete.sum(axis=1) >= 2)),
]  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=8)
    args = parser.parse_args()
    print("| case | calibrated | focal | E_r | E_t | D_RMS | wand score % (floor) | error/std | s per take |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, name, kwargs, noise, rig_of, floor_of in CASES:
        ours: dict[str, list[float]] = {}
        floor: dict[str, list[float]] = {}
        scores, floor_scores, z, seconds, calibrated = [], [], [], [], 0
        for seed in range(args.seeds):
            scenario, data, held = scenario_data(name, seed, noise, **kwargs)  # type: ignore[arg-type]
            start = time.perf_counter()
            try:
                result = calibrate(rig_of(scenario), data.observations)
            except CoreError:
                continue
            seconds.append(time.perf_counter() - start)
            calibrated += 1
            models, poses = in_truth_frame(result, scenario)
            truth = floor_of(scenario, data, result)
            for found, errors in (
                (ours, errors_against_truth(scenario, held, models, poses)),
                (floor, errors_against_truth(scenario, held, truth.state.models, truth.state.poses)),
            ):
                for kind in ("focal", "E_r", "E_t", "D_RMS"):
                    found.setdefault(kind, []).extend(v for k, v in errors.items() if k.endswith(kind))  # fmt: skip
            uv = data.observations.uv
            scores.append(_wand_score(models, poses, uv))
            floor_scores.append(_wand_score(truth.state.models, truth.state.poses, uv))
            z.extend(v for values in z_scores(result, scenario).values() for v in values)
        cells = []
        for kind in ("focal", "E_r", "E_t", "D_RMS"):
            given = ("given" in label and kind == "focal" and "held" in label) or (
                name == "action2" and kind == "focal"
            )
            cells.append("given" if given else f"{rms(ours[kind]) / rms(floor[kind]):.2f}x")
        print(
            f"| {label} | {calibrated} of {args.seeds} | " + " | ".join(cells)
            + f" | {np.mean(scores):.2f} ({np.mean(floor_scores):.2f}) | {rms(z):.2f} | {np.median(seconds):.2f} |"
        )  # fmt: skip


if __name__ == "__main__":
    main()
