"""The running estimate: rounds on the buffer so far, warm-started, as good as the final result within 2x by
the time coverage is ready; its worker process stays out of the node's way and goes away with it."""

from __future__ import annotations

import time

import numpy as np
import pytest
from rigs import in_truth_frame, rms

from wand_calib_ros.collection.coverage import CoverageTracker
from wand_calib_ros.collection.estimate import MIN_FRAMES, RunningEstimate, converged, round_input
from wand_calib_ros.collection.estimate_round import calibrate_round
from wand_calib_ros.core.judge.metrics import camera_errors
from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.scenarios import SCENARIOS

FPS = 30
PERIOD_FRAMES = 3 * FPS  # a round every 3 s of frames


def _take(name: str, seed: int, seconds: float = 60.0):  # type: ignore[no-untyped-def]
    scenario = SCENARIOS[name]()
    rng = np.random.default_rng(seed)
    options = TakeOptions(duration_s=seconds, free_running=False)
    takes = film(
        scenario, take_trajectory(scenario, options, rng), options.clocks(len(scenario.cameras), rng), seconds, rng
    )
    return scenario, observe(scenario.rig.camera_names, takes, 1.0, rng)


def _errors(scenario, result) -> dict[str, list[float]]:  # type: ignore[no-untyped-def]
    models, poses = in_truth_frame(result, scenario)
    out: dict[str, list[float]] = {"focal px": [], "principal point px": [], "E_r deg": [], "E_t %": []}
    for c, camera in enumerate(scenario.cameras):
        e = camera_errors(models[c], poses[c], camera.model, camera.pose)
        out["focal px"].append(e.focal_px)
        out["principal point px"].append(e.principal_point_px)
        if c > 0:
            out["E_r deg"].append(e.rotation_deg)
            out["E_t %"].append(100 * e.translation)
    return out


@pytest.mark.parametrize("name", ["paper3", "mixed"])
def test_the_estimate_when_coverage_is_ready_is_within_2x_of_the_final_result(name: str) -> None:
    estimated: dict[str, list[float]] = {}
    final: dict[str, list[float]] = {}
    for seed in (1, 2, 3):
        scenario, observations = _take(name, seed)
        tracker = CoverageTracker(scenario.rig)
        ready = None
        for f, uv in enumerate(observations.uv):
            tracker.add(uv)
            if tracker.status().ready:
                ready = f + 1
                break
        assert ready is not None, tracker.status().messages()
        latest = None  # the rounds the node would have run every 3 s up to then, each warm from the last
        for end in range(PERIOD_FRAMES, ready + 1, PERIOD_FRAMES):
            chosen = round_input(scenario.rig, observations.select_frames(np.arange(end)), 400)
            if chosen is None:
                continue
            done = calibrate_round(scenario.rig, chosen, CalibrationOptions(start=latest), end)
            latest = done.result if done.result is not None else None
        assert latest is not None
        whole = calibrate(scenario.rig, observations.select_frames(np.arange(ready)))
        for key, values in _errors(scenario, latest).items():
            estimated.setdefault(key, []).extend(values)
        for key, values in _errors(scenario, whole).items():
            final.setdefault(key, []).extend(values)
    for key in final:
        assert rms(estimated[key]) <= 2.0 * rms(final[key]), (key, rms(estimated[key]), rms(final[key]))


def test_rounds_wait_for_enough_frames_and_keep_to_the_placement_bound() -> None:
    scenario, observations = _take("paper3", 4, 20.0)
    assert round_input(scenario.rig, observations.select_frames(np.arange(10)), 400) is None
    chosen = round_input(scenario.rig, observations, 200)
    assert chosen is not None and chosen.frames.size == 200
    assert np.all(chosen.complete.sum(axis=1) >= 2)
    assert MIN_FRAMES <= 200


def test_the_worker_process_computes_rounds_and_goes_away_on_close() -> None:
    scenario, whole = _take("paper3", 5, 20.0)
    buffers = [whole.select_frames(np.arange(whole.frames.size // 2)), whole]  # the buffer grows between rounds
    estimates = RunningEstimate(scenario.rig, CalibrationOptions(), period_s=0.5)
    try:
        arrived = []
        deadline = time.monotonic() + 60
        while len(arrived) < 2 and time.monotonic() < deadline:
            new = estimates.step(time.monotonic(), lambda: buffers[len(arrived)])
            if new is not None:
                arrived.append(new)
            time.sleep(0.05)
        assert len(arrived) == 2, estimates.failure
        assert [a.round.frames for a in arrived] == [b.frames.size for b in buffers]
        settled = time.monotonic() + 1.5  # three periods on a buffer that no longer grows: no round
        while time.monotonic() < settled:
            assert estimates.step(time.monotonic(), lambda: whole) is None and not estimates._busy
            time.sleep(0.05)
        first, second = arrived
        assert first.round.result is not None and second.round.result is not None
        assert first.round.scene is not None and first.round.scene.frustums.shape == (3, 5, 3)
        assert all(first.improving.values())  # a first result improves on nothing
        assert converged(second.round.result, 100.0, 1000.0) and not converged(second.round.result, 0.0, 0.0)
        process = estimates._process
        assert process is not None and process.is_alive()
    finally:
        estimates.close()
    assert not process.is_alive()


def test_a_worker_that_dies_is_replaced_without_an_error_in_the_node() -> None:
    scenario, observations = _take("paper3", 6, 20.0)
    estimates = RunningEstimate(scenario.rig, CalibrationOptions(), period_s=0.2)
    try:
        assert estimates.step(time.monotonic(), lambda: observations) is None  # the first round starts
        first = estimates._process
        assert first is not None
        first.kill()
        first.join(5)
        deadline = time.monotonic() + 60
        arrived = None
        while arrived is None and time.monotonic() < deadline:
            arrived = estimates.step(time.monotonic(), lambda: observations)  # never raises
            time.sleep(0.05)
        assert arrived is not None and arrived.round.result is not None
        assert estimates._process is not None and estimates._process is not first
    finally:
        estimates.close()
