"""The detector in a real room (issue 32's acceptance, on our own renders): over four seeds of each scene, what
``wand-calib detect`` makes of the images against the truth, and the calibration from its views against the
calibration from the right views alone.

Scenes: the paper's three fisheyes in mono8 at 6 ms with two lamps and a window; a fisheye and a conventional
camera sending JPEG colour at 12 ms with three lamps; and harder, 16 ms streaks, four lamps of which three in a
row (a static false wand) and one beside the wand's path, a window in every camera.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.detection_score import (
    DetectionScore,
    calibration_errors,
    detect_room_recording,
    right_and_labelled,
    score,
)
from wand_calib_ros.sim.room import RoomRecording
from wand_calib_ros.sim.room_layout import ROOM_SCENES
from wand_calib_ros.sim.room_take import room_take
from wand_calib_ros.sim.scenarios import Scenario, mixed_pair_scenario, paper_three_camera_scenario

SEEDS = range(4)
SECONDS = 8.0
SCENES = {
    "lamps_window": paper_three_camera_scenario,
    "colour_jpeg": mixed_pair_scenario,
    "hard": paper_three_camera_scenario,
}


@cache
def _take(scene: str, seed: int) -> tuple[Scenario, RoomRecording, WandObservations]:
    scenario = SCENES[scene]()
    recording = room_take(scenario, ROOM_SCENES[scene](), SECONDS, np.random.default_rng(seed))
    observations, _ = detect_room_recording(recording, scenario.rig)
    return scenario, recording, observations


@pytest.mark.parametrize("scene", SCENES)
def test_views_are_found_right_and_labelled_in_a_room(scene: str) -> None:
    total: DetectionScore | None = None
    for seed in SEEDS:
        _, recording, observations = _take(scene, seed)
        measured = score(observations, recording.truth)
        total = measured if total is None else total + measured
    assert total is not None and total.clearly_visible > 1000
    assert total.recall >= 0.95, total
    assert total.false_rate <= 0.005, total
    assert total.centre_rms_px / np.sqrt(2) <= 0.2, total  # per image coordinate, as the calibration's sigma
    assert total.labels_right >= 0.99, total


@pytest.mark.parametrize("scene", ["lamps_window", "hard"])
def test_the_calibration_from_the_detections_is_at_the_floor_of_the_right_views(scene: str) -> None:
    found: dict[str, list[float]] = {}
    floor: dict[str, list[float]] = {}
    for seed in SEEDS:
        scenario, recording, observations = _take(scene, seed)
        right = right_and_labelled(observations, recording.truth)
        alone = observations.with_uv(np.where(right[..., None, None], observations.uv, np.nan))
        for kind, views in ((found, observations), (floor, alone)):
            for key, values in calibration_errors(scenario, calibrate(scenario.rig, views)).items():
                kind.setdefault(key, []).extend(values)
    for key in found:
        ratio = np.sqrt(np.mean(np.square(found[key]))) / np.sqrt(np.mean(np.square(floor[key])))
        assert ratio <= 1.3, (key, ratio)
