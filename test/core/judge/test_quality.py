"""The quality verdict: graded against the pixel noise the calibration estimated, in plain words."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wand_calib_ros.core.judge.quality import GRADES, POOR, judge, noise_wand_error
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.scenarios import paper_three_camera_scenario, simulate

ORDER = [name for name, _ in GRADES] + [POOR]


@pytest.mark.parametrize(("noise", "grade"), [(0.2, "excellent"), (1.0, "acceptable")])
def test_the_grade_follows_the_pixel_noise_and_the_world_error_is_the_noises(noise: float, grade: str) -> None:
    scenario = paper_three_camera_scenario()
    ratios = []
    for seed in (1, 2, 3):
        data = simulate(scenario, noise, np.random.default_rng(seed))
        result = calibrate(scenario.rig, data.observations)
        verdict = result.quality
        assert verdict is not None and verdict.grade == grade, verdict.line() if verdict else None
        assert verdict.line().startswith(f"quality {grade}: world error ")
        ratios.append(verdict.world_error_mm / verdict.world_noise_mm)
        if grade != "excellent":
            assert any("pixel noise" in reason for reason in verdict.limited_by), verdict.limited_by
        for camera in verdict.cameras:  # a right model: each camera fits at the noise
            assert 0.7 < camera.noise_ratio < 1.1, camera
    # An exact calibration's wand-length error is what its noise causes (RMS over seeds within 15 %).
    assert abs(float(np.sqrt(np.mean(np.square(ratios)))) - 1.0) < 0.15, ratios


def test_a_camera_moved_during_the_take_lowers_the_grade() -> None:
    scenario = paper_three_camera_scenario()
    cameras = list(scenario.cameras)
    pose = cameras[1].pose
    cameras[1] = replace(cameras[1], pose=Pose(pose.rotation, pose.translation + np.array([5.0, 0.0, 0.0])))
    moved = replace(scenario, cameras=tuple(cameras))
    for seed in (1, 2, 3):
        before = simulate(scenario, 0.2, np.random.default_rng(seed)).observations
        after = simulate(moved, 0.2, np.random.default_rng(seed + 10)).observations
        half = before.uv.shape[0] // 2
        take = WandObservations(
            np.arange(2 * half), before.camera_names, np.concatenate([before.uv[:half], after.uv[:half]])
        )
        still, bumped = calibrate(scenario.rig, before).quality, calibrate(scenario.rig, take).quality
        assert still is not None and bumped is not None
        assert ORDER.index(bumped.grade) > ORDER.index(still.grade), (still.line(), bumped.line())
        assert bumped.limited_by  # and it says why


def test_the_noise_wand_error_is_seeded_and_grows_with_the_noise() -> None:
    scenario = paper_three_camera_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(4))
    result = calibrate(scenario.rig, data.observations)
    names, uv = scenario.rig.camera_names, data.observations.uv
    assert noise_wand_error(result, names, uv) == noise_wand_error(result, names, uv)
    louder = noise_wand_error(replace(result, sigma_px=2 * result.sigma_px), names, uv)
    assert louder == pytest.approx(2 * noise_wand_error(result, names, uv), rel=0.1)
    assert judge(result, float("nan")).world_noise_mm != judge(result, float("nan")).world_noise_mm  # NaN: unjudged
