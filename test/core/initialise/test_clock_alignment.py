"""Clocks that disagree by seconds, lined up from the wand's motion (the paper's fisheyes, four of them, free-running
at 30 fps over a 20 s wave at 0.25 px): found to within a millisecond, the take calibrated as well as the same take
with the clocks as they were, with stamps or with frame ids alone; takes whose clocks agree are left exactly as
they are; a motion that repeats itself is said, not guessed."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest
from rigs import TRUTH_MEASURES, in_truth_frame, rms, truth_errors

from wand_calib_ros.core.errors import TimingError
from wand_calib_ros.core.initialise.clock_alignment import align_clocks, shifted
from wand_calib_ros.core.judge.metrics import camera_errors
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.scenarios import SCENARIOS, Scenario

SEEDS = range(6)
NOISE = 0.25
#: (camera, seconds its clock is ahead) of each case: two of the four cameras moved.
MOVES = {
    "0.3 s": ((1, 0.3), (3, 0.3)),
    "2.3 s": ((1, 2.3), (3, 2.3)),
    "-7 s": ((2, -7.0), (3, -7.0)),
}
#: The lined-up take may differ from the one whose clocks agreed only in which of two images half a frame from a
#: frame's time joins it (free-running phases): its errors stay within this of the other's, RMS over the seeds.
SAME_TAKE = 1.15
#: The offsets found, whole (seconds and the timing model's sub-frame part), against the truth.
OFFSET_S = 0.001


@cache
def _take(seed: int, moves: tuple[tuple[int, float], ...]) -> tuple[Scenario, WandObservations, dict[str, float]]:
    """paper4 filmed by free-running cameras, the cameras in ``moves`` stamping that many seconds ahead (their frame
    ids counted from the moved stamps, as a collector on their clocks would count them); the true offsets."""
    scenario = SCENARIOS["paper4"]()
    options = TakeOptions()
    trajectory = take_trajectory(scenario, options, np.random.default_rng(seed))
    clocks = options.clocks(len(scenario.cameras), np.random.default_rng(seed + 1))
    ahead = dict(moves)
    clocks = tuple(replace(c, latency_s=c.latency_s + ahead.get(k, 0.0)) for k, c in enumerate(clocks))
    takes = film(scenario, trajectory, clocks, options.duration_s, np.random.default_rng(seed + 2))
    observations = observe(scenario.rig.camera_names, takes, NOISE, np.random.default_rng(seed + 3))
    waved = np.stack([trajectory.middle - trajectory.half, trajectory.middle + trajectory.half])
    truth = {name: clock.latency_s for name, clock in zip(scenario.rig.camera_names, clocks, strict=True)}
    return replace(scenario, volume=waved), observations, truth


def _errors(seed: int, moves: tuple[tuple[int, float], ...], frames: bool = False) -> dict[str, list[float]]:
    """Errors against the truth of calibrating a take: per measure over the cameras, and each camera's whole time
    offset against the truth (s; frames with frame ids alone)."""
    scenario, observations, truth = _take(seed, moves)
    if frames:
        observations = replace(observations, stamps=None)
    result = calibrate(scenario.rig, observations)
    out = {**truth_errors(result, scenario), "offset": []}
    if not frames:
        reference = truth[result.reference_camera]
        out["offset"] = [camera.time_offset - (truth[camera.name] - reference) for camera in result.cameras]
    return out


def _pooled(moves: tuple[tuple[int, float], ...], frames: bool = False) -> dict[str, list[float]]:
    pooled: dict[str, list[float]] = {}
    for seed in SEEDS:
        for key, values in _errors(seed, moves, frames).items():
            pooled.setdefault(key, []).extend(values)
    return pooled


@pytest.mark.parametrize("case", list(MOVES))
def test_clocks_seconds_apart_calibrate_as_the_take_whose_clocks_agreed(case: str) -> None:
    agreed = _pooled(())
    moved = _pooled(MOVES[case])
    ratios = {measure: rms(moved[measure]) / rms(agreed[measure]) for measure in TRUTH_MEASURES}
    assert all(ratio <= SAME_TAKE for ratio in ratios.values()), ratios
    assert np.max(np.abs(moved["offset"])) <= OFFSET_S  # the whole offset: seconds and the sub-frame part


def test_what_was_found_is_said_once_per_moved_camera() -> None:
    scenario, observations, _ = _take(0, MOVES["2.3 s"])
    result = calibrate(scenario.rig, observations)
    assert result.timing is not None
    assert result.timing.clocks == (
        "cam1's clock is 2.301 s ahead of cam0's, found from the wand's motion",
        "cam3's clock is 2.301 s ahead of cam0's, found from the wand's motion",
    )


def test_clocks_that_agree_are_left_exactly_as_they_are() -> None:
    for seed in range(3):
        scenario, observations, _ = _take(seed, ())
        for views in (observations, replace(observations, stamps=None)):
            aligned, found = align_clocks(scenario.rig, views)
            assert aligned is views and not found.moved.any() and found.lines == ()


def _frame_ids_moved(observations: WandObservations, moves: dict[int, int]) -> WandObservations:
    """Synchronised views whose cameras count frames from other starts: camera c's id of a frame is the true one
    plus ``moves[c]``."""
    offsets = np.array([-moves.get(c, 0) for c in range(observations.uv.shape[1])], dtype=np.float64)
    return shifted(observations, offsets)


def test_frame_ids_that_disagree_are_lined_up_to_the_frame() -> None:
    scenario = SCENARIOS["paper4"]()
    options = TakeOptions(free_running=False)
    errors: dict[str, dict[str, list[float]]] = {"agreed": {}, "moved": {}}
    for seed in range(4):
        trajectory = take_trajectory(scenario, options, np.random.default_rng(seed))
        clocks = options.clocks(len(scenario.cameras), np.random.default_rng(seed + 1))
        takes = film(scenario, trajectory, clocks, options.duration_s, np.random.default_rng(seed + 2))
        agreed = replace(observe(scenario.rig.camera_names, takes, NOISE, np.random.default_rng(seed + 3)), stamps=None)
        moved = _frame_ids_moved(agreed, {1: 69, 2: -210})
        _, found = align_clocks(scenario.rig, moved)
        assert found.unit == "frames"
        assert np.array_equal(found.relative_to(0), [0.0, 69.0, -210.0, 0.0])  # whole frames, exactly
        volume = np.stack([trajectory.middle - trajectory.half, trajectory.middle + trajectory.half])
        waved = replace(scenario, volume=volume)
        for name, views in (("agreed", agreed), ("moved", moved)):
            result = calibrate(scenario.rig, views)
            models, poses = in_truth_frame(result, waved)
            for c, camera in enumerate(scenario.cameras):
                e = camera_errors(models[c], poses[c], camera.model, camera.pose)
                errors[name].setdefault("focal", []).append(e.focal_px)
                errors[name].setdefault("principal point", []).append(e.principal_point_px)
            if name == "moved":  # the whole offset, in frames: the ids' and the sub-frame part (none here)
                truth = {"cam0": 0.0, "cam1": 69.0, "cam2": -210.0, "cam3": 0.0}
                for camera in result.cameras:
                    assert abs(camera.time_offset - (truth[camera.name] - truth[result.reference_camera])) < 0.1
    for measure in ("focal", "principal point"):
        assert rms(errors["moved"][measure]) <= SAME_TAKE * rms(errors["agreed"][measure])


def test_a_motion_that_repeats_itself_is_said_not_guessed() -> None:
    scenario, observations, _ = _take(0, ())
    stamps = observations.stamps
    assert stamps is not None
    # the first 3 s of the wave, waved again and again: every lag a whole number of 3 s apart fits alike
    first = np.nanmin(stamps)
    keep = np.all(stamps < first + 3.0, axis=1)
    repeats = 7
    uv = np.concatenate([observations.uv[keep]] * repeats)
    again = np.concatenate([stamps[keep] + 3.0 * k for k in range(repeats)])
    periodic = WandObservations(np.arange(uv.shape[0]), observations.camera_names, uv, again)
    moved = shifted(periodic, np.array([0.0, -4.1, 0.0, 0.0]))  # cam1 4.1 s ahead
    with pytest.raises(TimingError, match="fits two clock offsets alike") as raised:
        align_clocks(scenario.rig, moved)
    assert "cam1" in str(raised.value) and "wave the wand less evenly" in str(raised.value)


def test_a_take_too_short_to_line_the_clocks_up_says_so_when_the_calibration_fails() -> None:
    scenario = SCENARIOS["paper"]()
    options = TakeOptions(duration_s=2.5)
    clocks = options.clocks(2, np.random.default_rng(1))
    clocks = (clocks[0], replace(clocks[1], latency_s=clocks[1].latency_s + 1.2))  # cam1 1.2 s ahead
    takes = film(scenario, take_trajectory(scenario, options, np.random.default_rng(0)), clocks, 2.5,
                 np.random.default_rng(2))  # fmt: skip
    observations = observe(scenario.rig.camera_names, takes, NOISE, np.random.default_rng(3))
    with pytest.raises(Exception, match="the clocks could not be checked") as raised:
        calibrate(scenario.rig, observations)
    assert "too few to line its clock up from the wand's motion" in str(raised.value)
