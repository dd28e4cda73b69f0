"""The detector in a real room: per scene, what ``wand-calib detect`` finds in rendered takes and what the
calibration from its views is worth.

For every scene of :data:`wand_calib_ros.sim.room_layout.ROOM_SCENES` and several seeds: a wand waved for
--seconds in front of the scene's rig (:data:`wand_calib_ros.sim.room_layout.ROOM_RIGS`: the paper's three
fisheyes, in a small room for the near scenes, the mixed pair for colour_jpeg, two conventional cameras over the
painted and glossy floors), rendered, detected as ``wand-calib detect`` detects a bag (its images decoded, the
pipeline, the labels checked across cameras), then scored against the truth, overall and per brightness class of
each view's brightest LED (its peak before clipping over full scale: <4x, 4-8x, 8-16x, >16x):

- recall: the clearly visible views (every LED drawn, none on a lamp or a window, 6 px inside the image,
  15 px apart, 10 grey levels and 5 noise sigmas above their background) with a right view returned;
- false: returned views with a point more than 3 px from its LED in either order;
- centres: RMS of the right views' points, per image coordinate (as the calibration's sigma) and 2D;
- labels: right views with A and C in the right order;
- calibration: the calibration from the detections against the calibration from the right views alone (the
  floor), RMS over seeds and cameras of each error class (focal, principal point, E_r, E_t, distortion curve).

Run: .venv/bin/python benchmarks/detection_rooms.py [--seeds 4] [--seconds 20] [--scenes lamps_window ...]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.detection_score import (
    ERROR_CLASSES,
    DetectionScore,
    brightness_classes,
    calibration_errors,
    detect_room_recording,
    right_and_labelled,
    score,
)
from wand_calib_ros.sim.room_layout import ROOM_SCENES, scene_scenario
from wand_calib_ros.sim.room_take import room_take


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--scenes", nargs="+", default=[*ROOM_SCENES])
    args = parser.parse_args()
    print(
        f"{'scene':18s} {'rig':7s} {'clear':>6s} {'recall':>7s} {'false':>7s} {'centre px':>10s} {'(2D)':>6s} "
        f"{'labels':>7s}  calibration / floor: " + " ".join(f"{k:>6s}" for k in ERROR_CLASSES) + "   s/seed"
    )
    for scene in args.scenes:
        scenario = scene_scenario(scene)
        total: DetectionScore | None = None
        by_class: dict[str, DetectionScore] = {}
        found: dict[str, list[float]] = {k: [] for k in ERROR_CLASSES}
        floor: dict[str, list[float]] = {k: [] for k in ERROR_CLASSES}
        started = time.perf_counter()
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            recording = room_take(scenario, ROOM_SCENES[scene](), args.seconds, rng)
            observations, _ = detect_room_recording(recording, scenario.rig)
            measured = score(observations, recording.truth)
            total = measured if total is None else total + measured
            for name, chosen in brightness_classes().items():
                part = score(observations, recording.truth, chosen)
                by_class[name] = by_class[name] + part if name in by_class else part
            right = right_and_labelled(observations, recording.truth)
            alone = observations.with_uv(np.where(right[..., None, None], observations.uv, np.nan))
            for kind, views in ((found, observations), (floor, alone)):
                for key, values in calibration_errors(scenario, calibrate(scenario.rig, views)).items():
                    kind[key] += values
        assert total is not None
        ratios = [np.sqrt(np.mean(np.square(found[k]))) / np.sqrt(np.mean(np.square(floor[k]))) for k in ERROR_CLASSES]
        rig = scenario.name
        print(
            f"{scene:18s} {rig:7s} {total.clearly_visible:6d} {100 * total.recall:6.1f}% "
            f"{100 * total.false_rate:6.2f}% {total.centre_rms_px / np.sqrt(2):10.3f} {total.centre_rms_px:6.3f} "
            f"{100 * total.labels_right:6.1f}%  "
            f"{'':21s}"
            + " ".join(f"{r:6.2f}" for r in ratios)
            + f"   {(time.perf_counter() - started) / args.seeds:5.1f}"
        )
        for name, part in by_class.items():
            if part.clearly_visible and set(by_class) != {name}:
                print(
                    f"  brightest LED {name:7s} {'':7s} {part.clearly_visible:6d} {100 * part.recall:6.1f}% "
                    f"{100 * part.false_rate:6.2f}% {part.centre_rms_px / np.sqrt(2):10.3f} {part.centre_rms_px:6.3f} "
                    f"{100 * part.labels_right:6.1f}%"
                )


if __name__ == "__main__":
    main()
