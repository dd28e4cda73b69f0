"""The detector in a real room (issues 32 and 38, on our own renders): over four seeds of each scene, what
``wand-calib detect`` makes of the images against the truth, in every brightness class of the views' brightest LED,
and the calibration from its views against the calibration from the right views alone.

Scenes: the paper's three fisheyes in mono8 at 6 ms with two lamps and a window; a fisheye and a conventional
camera sending JPEG colour at 12 ms with three lamps; harder, 16 ms streaks, four lamps of which three in a row (a
static false wand) and one beside the wand's path, a window in every camera; the three fisheyes in a small room, the
wand 0.4-1.4 m from them, its LEDs 1-30x over full scale and blooming, a window across its path; two conventional
cameras over a lab floor with a painted track, and over a glossy floor with broad reflections. With saturated
spots drawn 0.5 px off on purpose, the calibration measures the bias from the spots' brightness and corrects it.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from rigs import rms, z_scores

from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.detection_score import (
    DetectionScore,
    brightness_classes,
    calibration_errors,
    centre_bias_by_class,
    detect_room_recording,
    right_and_labelled,
    score,
)
from wand_calib_ros.sim.room import RoomRecording
from wand_calib_ros.sim.room_layout import ROOM_SCENES, scene_scenario
from wand_calib_ros.sim.room_take import room_take
from wand_calib_ros.sim.scenarios import Scenario

SEEDS = range(4)
SECONDS = 8.0
SCENES = ("lamps_window", "colour_jpeg", "hard", "near_fisheye", "painted_floor", "glossy_floor")
#: A brightness class is judged on its own once it holds this many clearly visible views over the seeds: enough to
#: tell a recall of 95 % from one of 90 % (2.8 binomial standard deviations; the first tenth of a second of a take,
#: before the structure is learned, counts twice as much in an 8 s take as in a minute's).
CLASS_VIEWS = 150


@cache
def _take(scene: str, seed: int) -> tuple[Scenario, RoomRecording, WandObservations]:
    scenario = scene_scenario(scene)
    recording = room_take(scenario, ROOM_SCENES[scene](), SECONDS, np.random.default_rng(seed))
    observations, _ = detect_room_recording(recording, scenario.rig)
    return scenario, recording, observations


@pytest.mark.parametrize("scene", SCENES)
def test_views_are_found_right_and_labelled_in_a_room(scene: str) -> None:
    total: DetectionScore | None = None
    classes = brightness_classes()
    by_class: dict[str, DetectionScore] = {}
    for seed in SEEDS:
        _, recording, observations = _take(scene, seed)
        measured = score(observations, recording.truth)
        total = measured if total is None else total + measured
        for name, chosen in classes.items():
            part = score(observations, recording.truth, chosen)
            by_class[name] = by_class[name] + part if name in by_class else part
    assert total is not None and total.clearly_visible > 500
    assert total.recall >= 0.95, total
    assert total.false_rate <= 0.005, total
    assert total.centre_rms_px / np.sqrt(2) <= 0.2, total  # per image coordinate, as the calibration's sigma
    assert total.labels_right >= 0.99, total
    for name, part in by_class.items():  # in every brightness class of the views' brightest LED
        if part.clearly_visible >= CLASS_VIEWS:
            assert part.recall >= 0.95, (name, part)
            assert part.centre_rms_px / np.sqrt(2) <= 0.2, (name, part)


@pytest.mark.parametrize("scene", ["lamps_window", "hard", "near_fisheye", "painted_floor"])
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


@cache
def _near_calibrations(seed: int) -> tuple[Scenario, CalibrationResult, CalibrationResult]:
    """The small room's take of ``seed`` calibrated from its detections: with every spot over full scale drawn
    0.5 px further out from the principal point (a lens's coma), and without."""
    scenario, _, biased = _take("near_biased", seed)
    _, _, unbiased = _take("near_fisheye", seed)
    return scenario, calibrate(scenario.rig, biased), calibrate(scenario.rig, unbiased)


def test_saturated_centres_drawn_off_on_purpose_are_measured_and_corrected() -> None:
    # 2-10 % of each camera's spots stay below full scale. The detector's brightness carries the bias to the
    # adjustment: each camera reports it, the calibration is within 1.3x of the unbiased take's in every error
    # class (measured 1.07-1.27x, curves 0.99x), and the standard deviations cover the errors: |error| / std at most
    # 3 (z RMS 0.65-0.99, at most 2.24; they are widened 1.36-1.79x for centre errors that follow one another,
    # without which the focal lengths' z RMS was 1.55 over these seeds, 1.74 over eight, up to 3.4).
    biased: dict[str, list[float]] = {}
    unbiased: dict[str, list[float]] = {}
    pooled: dict[str, list[float]] = {}
    for seed in SEEDS:
        scenario, with_bias, without = _near_calibrations(seed)
        for camera in scenario.cameras:
            reported = with_bias.camera(camera.spec.name).centre_bias
            assert reported and min(b.radial_px for b in reported) > 0.3, (seed, camera.spec.name, reported)
        for label, result in ((biased, with_bias), (unbiased, without)):
            for key, values in calibration_errors(scenario, result).items():
                label.setdefault(key, []).extend(values)
        for key, values in z_scores(with_bias, scenario).items():
            pooled.setdefault(key, []).extend(values)
    for key in biased:
        assert rms(biased[key]) <= 1.3 * rms(unbiased[key]), (key, rms(biased[key]), rms(unbiased[key]))
    for key in pooled:
        assert rms(pooled[key]) <= 1.3 and np.max(np.abs(pooled[key])) <= 3.0, (key, pooled[key])


def test_each_class_is_reported_within_a_tenth_of_a_pixel_of_what_its_centres_carry() -> None:
    # Against the drawn truth, per brightness class relative to the spots below full scale: the 0.5 px drawn out from
    # the principal point in the biased take, and what the detector adds near a camera in both (up to 0.1 px in
    # cam2, its brighter spots a little to the left; the cause is not found yet). Measured: every reported class
    # within 0.088 px of it; the takes without a drawn bias report one only there (cam2, seed 1: 0.17 px for
    # centres that carry 0.085 px), and leave unreported only what is under 0.07 px (0.069).
    for seed in SEEDS:
        for scene in ("near_biased", "near_fisheye"):
            scenario, recording, observations = _take(scene, seed)
            result = _near_calibrations(seed)[1 if scene == "near_biased" else 2]
            for camera in scenario.cameras:
                mine = result.camera(camera.spec.name)
                carried = centre_bias_by_class(
                    observations, recording.truth, camera.spec.name, np.asarray(mine.model.principal_point)
                )
                reported = {b.klass: (*b.offset_px, b.radial_px) for b in mine.centre_bias}
                for klass, values in reported.items():
                    gap = np.max(np.abs(np.subtract(values, carried[klass])))
                    assert gap <= 0.1, (scene, seed, camera.spec.name, klass, values, carried[klass])
                if scene == "near_fisheye":  # (a class of the biased take may hold too few points to have a term)
                    for klass in set(carried) - set(reported):
                        assert np.max(np.abs(carried[klass])) <= 0.1, (seed, camera.spec.name, klass, carried[klass])
