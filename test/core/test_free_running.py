"""Free-running cameras against their synchronised twins: the timing model at the statistical floor.

Each seed films one wave of the wand (20 s at 30 fps, LEDs at a median 1 m/s through the volume the
cameras share) twice: by hardware-triggered global-shutter cameras, and by free-running ones (phases
up to +-half a frame, stamp latencies up to +-8 ms, 0.2 ms stamp jitter), with global or rolling
shutters (20 ms readout). Pixel noise is 0.25 px, the noise of the real eWand recording. Errors are
pooled over cameras and seeds (RMS) per measure.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from rigs import rms, timed_calibration, timed_take

from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
from wand_calib_ros.sim.clocks import CameraClock, TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.scenarios import SCENARIOS

SEEDS = range(12)
NOISE = 0.25
MEASURES = ("focal", "principal point", "curve", "E_r", "E_t", "D_RMS")
SYNCHRONISED = TakeOptions(free_running=False)


def _pooled(name: str, options: TakeOptions) -> dict[str, list[float]]:
    pooled: dict[str, list[float]] = {}
    for seed in SEEDS:
        for key, values in timed_calibration(name, seed, NOISE, options).items():
            pooled.setdefault(key, []).extend(values)
    return pooled


@pytest.mark.parametrize("readout_s", [0.0, 0.02], ids=["global shutter", "rolling shutter"])
@pytest.mark.parametrize("name", ["paper3", "mixed3"])
def test_free_running_cameras_calibrate_within_1_3x_of_their_synchronised_twins(name: str, readout_s: float) -> None:
    twin = _pooled(name, SYNCHRONISED)
    free = _pooled(name, TakeOptions(readout_s=readout_s))
    ratios = {measure: rms(free[measure]) / rms(twin[measure]) for measure in MEASURES}
    assert all(ratio <= 1.3 for ratio in ratios.values()), ratios
    assert rms(free["offset"]) < 0.0005  # offsets between cameras, RMS over cameras and seeds
    if readout_s:
        assert rms(free["readout"]) < 0.001
    assert rms(free["offset z"]) < 3.0  # the reported uncertainty is about right


def test_synchronised_takes_give_exactly_the_result_of_fixed_timing() -> None:
    for seed in range(3):
        scenario, observations, _ = timed_take("paper3", seed, NOISE, SYNCHRONISED)
        auto = calibrate(scenario.rig, observations)
        fixed = calibrate(scenario.rig, observations, CalibrationOptions(time_offsets="fixed", rolling_shutter="fixed"))
        assert auto.timing is not None and auto.timing.time_offsets == "fixed"
        assert "tested: not significant" in auto.timing.notes[-1]
        for camera in fixed.cameras:
            mine = auto.camera(camera.name)
            assert np.array_equal(mine.model.intrinsic_vector(), camera.model.intrinsic_vector())
            assert np.array_equal(mine.pose.translation, camera.pose.translation)


def test_triggered_global_shutters_are_left_synchronised_on_one_linearisation_and_rolling_ones_are_found(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Hardware-triggered cameras (simultaneous stamps, ``auto``): global shutters mostly show no timing on the
    linearisation at the synchronised solution already (no adjustment of it: each statistic below half its 99 %
    quantile: 4 of these 6 takes of three cameras), and are left synchronised either way; rolling shutters
    (20 ms) never pass that way, and the adjustments that test them keep and estimate their readout times."""
    import wand_calib_ros.core.refine as refine

    tested: list[int] = []
    adjusted_test = refine._test_timing

    def counted(*args: Any) -> Any:
        tested.append(1)
        return adjusted_test(*args)

    monkeypatch.setattr(refine, "_test_timing", counted)
    for seed in range(6):
        scenario, observations, _ = timed_take("paper3", seed, NOISE, SYNCHRONISED)
        result = calibrate(scenario.rig, observations)
        assert result.timing is not None and "tested: not significant" in result.timing.notes[-1]
    assert len(tested) <= 3
    tested.clear()
    for seed in range(2):
        rolling = TakeOptions(free_running=False, readout_s=0.02)
        scenario, observations, _ = timed_take("paper3", seed, NOISE, rolling)
        result = calibrate(scenario.rig, observations)
        assert result.timing is not None and result.timing.rolling_shutter == dict.fromkeys(
            scenario.rig.camera_names, "estimated"
        )
        assert all(abs(camera.readout - 0.02) < 0.002 for camera in result.cameras)
    assert len(tested) == 2


@pytest.mark.parametrize("fps", [(30.0, 25.0, 30.0), (60.0, 30.0, 30.0)], ids=["30-25-30", "60-30-30"])
def test_cameras_at_different_frame_rates_work_from_the_stamps(fps: tuple[float, ...]) -> None:
    # The slowest camera anchors the frames: the others' extra images pair with nothing, so there is
    # less to calibrate from than in a 30 fps twin; what there is must be used without bias.
    runs = [timed_calibration("paper3", seed, NOISE, TakeOptions(fps=fps)) for seed in range(4)]
    assert rms([v for run in runs for v in run["offset"]]) < 0.0005
    z = [v for run in runs for v in run["intrinsics z"]]
    assert rms(z) < 2.0 and np.max(np.abs(z)) < 4.5  # errors consistent with the reported uncertainty


def test_an_offset_beyond_a_frame_is_estimated_and_warned_about() -> None:
    scenario = SCENARIOS["paper3"]()
    clocks = (
        CameraClock(30.0),
        CameraClock(30.0, phase_s=0.01, latency_s=0.045),  # a driver that queues its images 45 ms
        CameraClock(30.0, phase_s=-0.005, latency_s=0.002),
    )
    trajectory = take_trajectory(scenario, TakeOptions(), np.random.default_rng(0))
    takes = film(scenario, trajectory, clocks, 20.0, np.random.default_rng(1))
    result = calibrate(scenario.rig, observe(scenario.rig.camera_names, takes, NOISE, np.random.default_rng(2)))
    latency = {name: clock.latency_s for name, clock in zip(scenario.rig.camera_names, clocks, strict=True)}
    for camera in result.cameras:
        assert abs(camera.time_offset - (latency[camera.name] - latency[result.reference_camera])) < 0.001
    warned = [w for w in result.warnings if "more than a frame" in w]
    assert warned and all(w.split(":")[0] in ("cam0", "cam1", "cam2") for w in warned)


def test_a_readout_is_never_negative() -> None:
    # Global shutters whose readout is estimated anyway: about half the unconstrained estimates would fall below
    # zero by noise; the bound holds them at zero and reports them fixed, the others stay estimated.
    below = 0
    for seed in range(4):
        scenario, observations, _ = timed_take("paper3", seed, NOISE, TakeOptions(duration_s=8.0, readout_s=0.0))
        result = calibrate(scenario.rig, observations, CalibrationOptions(rolling_shutter="estimate"))
        assert result.timing is not None
        for camera in result.cameras:
            assert camera.readout >= 0.0
            held = result.timing.rolling_shutter[camera.name] == "fixed"
            below += held
            assert held == ("readout" not in camera.parameter_std) and (not held or camera.readout == 0.0)
    assert below > 0  # the bound was met (12 cameras' estimates around a true zero)


def test_at_a_low_noise_the_low_order_lens_does_not_pass_for_timing() -> None:
    # 0.02 px, a rendered live buffer's noise: the robust pass tests the timing with k3 free. Tested at the low
    # order alone (k1, k2), the lens curve's misfit had passed for readout times and offsets (mixed3 seeds 0 and 1,
    # dropped again only by the least-squares model order; a live buffer: readout times of -1 ms at 10 sigma).
    for seed in range(3):
        scenario, observations, _ = timed_take("mixed3", seed, 0.02, SYNCHRONISED)
        auto = calibrate(scenario.rig, observations)
        fixed = calibrate(scenario.rig, observations, CalibrationOptions(time_offsets="fixed", rolling_shutter="fixed"))
        assert auto.timing is not None and "tested: not significant" in auto.timing.notes[-1], auto.timing
        for camera in fixed.cameras:
            mine = auto.camera(camera.name)
            assert np.array_equal(mine.model.intrinsic_vector(), camera.model.intrinsic_vector())
            assert np.array_equal(mine.pose.translation, camera.pose.translation)
