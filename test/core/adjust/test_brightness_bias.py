"""A centre bias that grows with brightness, modelled in the adjustment: biased centres calibrate as well as
unbiased ones, the bias is reported where it is, nothing where there is none, and the standard deviations
cover the errors with the bias present.

Each take is simulated once and calibrated twice, with and without the bias drawn (the same noise, the same
placements): the ratio of their errors is the bias's cost alone. Brightness follows the renderer's light model
(1/d^2 and the wand's angle to the line of sight), 0.25 px noise, eighteen seeds: over six, the ratios of a
case scattered from 1.08x to 1.56x from one set of seeds to the next (a spurious shape, or a growth's cost to the
focal lengths, in two or three of its cameras), too much for a claim of 1.3x."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest
from rigs import rms, z_scores

from wand_calib_ros.core.adjust.brightness_bias import MIN_REFERENCE_POINTS, class_noise
from wand_calib_ros.core.adjust.bundle_problem import BundleProblem
from wand_calib_ros.core.model.brightness import brightness_classes
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.centre_bias import DrawnBias, LedLight, with_bias
from wand_calib_ros.sim.detection_score import ERROR_CLASSES, calibration_errors
from wand_calib_ros.sim.scenarios import SCENARIOS, simulate

SEEDS = range(18)
NOISE_PX = 0.25
#: A minute's wave at 30 fps keeps about this many placements: enough that each class's bias is known to a few
#: hundredths of a pixel (0.25 px / sqrt(100) points and their coupling to the camera's other parameters).
PLACEMENTS = 1000
#: The rigs, and how bright their LEDs are (every class from below full scale to 16x populated).
RIGS = {"paper3": LedLight(), "conventional": LedLight(stops_at_1m=5.0), "conventional4": LedLight(stops_at_1m=6.0)}
#: The biases drawn.
KINDS = {
    "a step from 4x full scale": DrawnBias(offset_px=(0.5, 0.0), from_stops=2.0),
    "radial from full scale": DrawnBias(radial_px=0.5),
    "growing per stop": DrawnBias(offset_px=(0.15, 0.1), radial_px=0.1, per_stop=True),
    "a step in one camera": DrawnBias(offset_px=(0.0, -0.5), from_stops=2.0, cameras=(1,)),
    "a step from 4x that grows": DrawnBias(offset_px=(0.3, 0.0), radial_px=0.2, from_stops=2.0, grows=0.5),
}


#: What is short of it, as measured over the eighteen seeds: the conventional pair in four of the five kinds (the
#: paper's fisheyes and the four conventional cameras in none). A pair's cameras are placed only by each other and the
#: wand: a bias along u that grows with brightness in one camera more than in the other is a change of disparity with
#: the LEDs' distance, which the geometry (the baseline, the focal lengths) takes up nearly as well. Where the bias
#: grows, the data know that difference only to +-0.13 px in the 8-16x class (its reported standard deviation; v and
#: the radial part to +-0.03 px): no estimate reports it within 0.1 px every time. Four cameras place one another:
#: there every kind holds.
SHORT = {
    ("conventional", "a step from 4x full scale"): "2 of 144 class reports more than 0.1 px off (0.18 and 0.22 px: one "
    "camera of one seed, whose bright classes the data put 2.5-3 standard deviations low); the calibration "
    "1.05-1.22x, focal z RMS 1.56 (at most 4.4)",
    ("conventional", "radial from full scale"): "3 of 144 class reports more than 0.1 px off (at most 0.27 px); the "
    "calibration 1.09-1.15x",
    ("conventional", "growing per stop"): "focal lengths, positions and curves 1.28-1.48x, 39 of 144 class reports "
    "more than 0.1 px off (at most 0.42 px)",
    ("conventional", "a step from 4x that grows"): "taken for a step (CONSTANT) in every camera: 38 of 144 class "
    "reports more than 0.1 px off (at most 0.27 px), positions 1.41x, curves 1.32x",
}


@pytest.mark.parametrize(
    ("rig", "kind"),
    [
        pytest.param(rig, kind, marks=[pytest.mark.xfail(reason=SHORT[rig, kind], strict=True)])
        if (rig, kind) in SHORT
        else (rig, kind)
        for rig in RIGS
        for kind in KINDS
    ],
)
def test_biased_centres_calibrate_as_unbiased_ones_and_the_bias_is_reported(rig: str, kind: str) -> None:
    scenario, bias, light = SCENARIOS[rig](), KINDS[kind], RIGS[rig]
    errors: dict[str, dict[str, list[float]]] = {"clean": {}, "biased": {}}
    pooled: dict[str, list[float]] = {}
    for seed in SEEDS:
        data = simulate(scenario, NOISE_PX, np.random.default_rng(seed), n=PLACEMENTS)
        for label, drawn in (("clean", None), ("biased", bias)):
            observations = with_bias(scenario, data, drawn, light).observations
            result = calibrate(scenario.rig, observations)
            for key, values in calibration_errors(scenario, result).items():
                errors[label].setdefault(key, []).extend(values)
            if drawn is None:
                assert not any(c.centre_bias for c in result.cameras), (seed, "a bias where none is")
                continue
            for key, values in z_scores(result, scenario).items():
                pooled.setdefault(key, []).extend(values)
            stops = observations.brightness
            assert stops is not None
            for c, camera in enumerate(scenario.cameras):
                reported = {b.klass: b for b in result.camera(camera.spec.name).centre_bias}
                classes = brightness_classes(stops[:, c])
                for klass in range(1, 6):
                    mine = stops[:, c][classes == klass]
                    if mine.size < 30:
                        continue
                    truth = bias.class_truth(c, mine)
                    found = reported.get(klass)
                    if found is None:  # unreported: the class's bias is too small to matter
                        assert np.max(np.abs(truth)) <= 0.1, (seed, camera.spec.name, klass, truth)
                        continue
                    measured = np.array([*found.offset_px, found.radial_px])
                    assert np.max(np.abs(measured - truth)) <= 0.1, (seed, camera.spec.name, klass, measured, truth)
    for key in ERROR_CLASSES:
        ratio = rms(errors["biased"][key]) / rms(errors["clean"][key])
        assert ratio <= 1.3, (key, ratio)
    for key, values in pooled.items():  # the standard deviations cover the errors with the bias present
        assert rms(values) <= 1.6 and np.max(np.abs(values)) <= 4.0, (key, rms(values), np.max(np.abs(values)))


@pytest.mark.parametrize("rig", RIGS)
def test_without_a_bias_its_brightness_changes_nothing(rig: str) -> None:
    """Brightness known, no bias drawn: nothing reported, and the calibration within 1.05x of the same take's
    without the brightness column (today's)."""
    scenario, light = SCENARIOS[rig](), RIGS[rig]
    errors: dict[str, dict[str, list[float]]] = {"known": {}, "unknown": {}}
    for seed in SEEDS:
        data = simulate(scenario, NOISE_PX, np.random.default_rng(100 + seed), n=PLACEMENTS)
        known = with_bias(scenario, data, None, light).observations
        for label, observations in (("known", known), ("unknown", data.observations)):
            result = calibrate(scenario.rig, observations)
            assert not any(c.centre_bias for c in result.cameras)
            for key, values in calibration_errors(scenario, result).items():
                errors[label].setdefault(key, []).extend(values)
    for key in ERROR_CLASSES:
        ratio = rms(errors["known"][key]) / rms(errors["unknown"][key])
        assert ratio <= 1.05, (key, ratio)


def test_a_camera_with_too_few_points_below_full_scale_is_named_and_the_result_is_not_excellent() -> None:
    """LEDs 16,000x over full scale at 1 m: no camera has the points below full scale to measure a bias against
    (MIN_REFERENCE_POINTS), so a 0.5 px radial one cannot be corrected, and the result says so."""
    scenario = SCENARIOS["paper3"]()
    for seed in range(2):
        data = simulate(scenario, NOISE_PX, np.random.default_rng(seed), n=PLACEMENTS)
        observations = with_bias(scenario, data, DrawnBias(radial_px=0.5), LedLight(stops_at_1m=14.0)).observations
        result = calibrate(scenario.rig, observations)
        assert result.quality is not None and result.quality.grade != "excellent"
        stops = observations.brightness
        assert stops is not None
        for c, camera in enumerate(scenario.cameras):
            below = int(np.sum(stops[:, c] < 0.0))
            named = [line for line in result.systematic if line.startswith(f"{camera.spec.name}: ")]
            assert below >= MIN_REFERENCE_POINTS or (named and "cannot be measured" in named[0]), (seed, below)
            assert not result.camera(camera.spec.name).centre_bias or below >= MIN_REFERENCE_POINTS


def test_each_brightness_class_is_weighed_by_its_own_noise() -> None:
    """Residuals of 0.5 px below full scale and 0.2 px above it in one camera, 0.3 px throughout in the other: each
    class's noise relative to its camera's, within what its count of points allows (3 / sqrt(2 n))."""
    rng = np.random.default_rng(5)
    m = 6000
    camera = rng.integers(0, 2, m)
    stops = rng.uniform(-1.5, 5.5, m)
    sigma = np.where(camera == 1, 0.3, np.where(stops < 0.0, 0.5, 0.2))
    res = rng.normal(size=(m, 2)) * sigma[:, None]
    problem = BundleProblem(SCENARIOS["paper3"]().wand, 2, m, camera, np.arange(m), np.zeros(m, dtype=np.int64),
                            np.zeros((m, 2)), None, stops)  # fmt: skip
    state = SimpleNamespace(bias_noise=None)
    noise = class_noise(SimpleNamespace(state=state, residuals=res), problem)  # type: ignore[arg-type]
    classes = brightness_classes(stops)
    for c in range(2):
        overall = np.sqrt(np.mean(sigma[camera == c] ** 2))
        for k in range(6):
            n = int(np.sum((camera == c) & (classes == k)))
            expected = np.sqrt(np.mean(sigma[(camera == c) & (classes == k)] ** 2)) / overall
            assert abs(noise[c, k] / expected - 1.0) <= 3.0 / np.sqrt(2 * n), (c, k, noise[c, k], expected)


def test_what_estimating_a_bias_costs_the_geometry_is_said_where_the_views_cannot_tell_them_apart() -> None:
    """A bias growing per stop on the conventional pair: estimating it leaves cam1's position 1.69-1.77x less precise
    than a known bias would (beyond BIAS_COST: no calibration that corrects it is within 1.3x there), and the result
    says so; the four conventional cameras with the same bias, and the pair without one, say nothing of it."""
    kind = KINDS["growing per stop"]
    cases = (("conventional", kind, True), ("conventional4", kind, False), ("conventional", None, False))
    for rig, drawn, said in cases:
        scenario = SCENARIOS[rig]()
        for seed in range(2):
            data = simulate(scenario, NOISE_PX, np.random.default_rng(seed), n=PLACEMENTS)
            result = calibrate(scenario.rig, with_bias(scenario, data, drawn, RIGS[rig]).observations)
            costs = [line for line in result.warnings if "hard to tell apart" in line]
            if not said:
                assert not costs, (rig, seed, costs)
                continue
            position = [line for line in costs if line.startswith("cam1: its centre bias and its position")]
            assert position, (seed, costs)
            found = re.search(r"(\d+\.\d+)x less precise", position[0])
            assert found is not None, position
            factor = float(found.group(1))
            assert 1.5 <= factor <= 2.0, (seed, factor)
