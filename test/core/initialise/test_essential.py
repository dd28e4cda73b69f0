"""Step 2: essential matrix on the unit sphere, decomposition and scale."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.initialise.essential import epipolar_angles, relative_pose
from wand_calib_ros.core.model.camera_model import unproject
from wand_calib_ros.core.model.geometry import Pose, rotation_error_deg, rotvec_from_rotation, skew, translation_error
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate


def _bearings(scenario, data):  # type: ignore[no-untyped-def]
    uv = data.observations.uv
    return unproject(scenario.cameras[0].model, uv[:, 0]), unproject(scenario.cameras[1].model, uv[:, 1])


def test_noise_free_fisheye_pair_gives_the_exact_pose() -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.0, np.random.default_rng(0), n=60)
    b0, b1 = _bearings(scenario, data)
    assert np.degrees(np.arccos(b1[..., 2])).max() > 40  # wide rays in camera 1
    result = relative_pose(b0, b1, scenario.wand.L, threshold_rad=1e-3, rng=np.random.default_rng(0))
    truth = scenario.cameras[1].pose
    # the angle of the rotation between them: the paper's E_r (arccos of a cosine near 1) cannot
    # resolve less than about 1e-6 deg
    assert np.degrees(np.linalg.norm(rotvec_from_rotation(truth.rotation.T @ result.pose.rotation))) < 1e-8
    assert translation_error(truth.translation, result.pose.translation) < 1e-9
    assert result.inliers.all() and result.scale_spread < 1e-9


def test_rays_beyond_ninety_degrees_are_handled() -> None:
    rng = np.random.default_rng(5)
    truth = Pose.from_rotvec(np.array([0.0, np.radians(150.0), 0.0]), np.array([0.0, 0.0, -1000.0]))
    a = rng.normal(scale=600.0, size=(30, 3)) + np.array([900.0, 0.0, -500.0])
    n = rng.normal(size=(30, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    points = a[:, None, :] + np.array([0.0, 400.0, 600.0])[None, :, None] * n[:, None, :]  # (30, 3, 3)
    b0 = points / np.linalg.norm(points, axis=-1, keepdims=True)
    in1 = truth.apply(points)
    b1 = in1 / np.linalg.norm(in1, axis=-1, keepdims=True)
    assert (b0[..., 2] < 0).sum() > 10 and (b1[..., 2] < 0).sum() > 10
    result = relative_pose(b0, b1, 600.0, threshold_rad=1e-4, rng=np.random.default_rng(1))
    # the rotation's angle from its rotation vector: E_r's arccos cannot resolve below ~1e-6 deg, and which side
    # of that a noise-free result falls depends on the CPU's rounding (1.2e-6 with numpy's SSE kernels)
    assert np.degrees(np.linalg.norm(rotvec_from_rotation(truth.rotation.T @ result.pose.rotation))) < 1e-8
    assert translation_error(truth.translation, result.pose.translation) < 1e-9


def test_outliers_are_flagged_and_do_not_move_the_pose() -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(1), n=100)
    b0, b1 = _bearings(scenario, data)
    bad = np.random.default_rng(2).choice(100, 10, replace=False)
    b1 = b1.copy()
    b1[bad, 0] = b1[bad, 0][::-1]  # point A swapped between placements
    result = relative_pose(b0, b1, scenario.wand.L, threshold_rad=5 / 357.0, rng=np.random.default_rng(0))
    placement_inlier = result.inliers.reshape(-1, 3).all(axis=1)
    assert not placement_inlier[bad].any()
    assert placement_inlier.sum() >= 85
    assert rotation_error_deg(scenario.cameras[1].pose.rotation, result.pose.rotation) < 0.5


def test_epipolar_angle_is_zero_on_the_truth() -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.0, np.random.default_rng(3), n=20)
    b0, b1 = _bearings(scenario, data)
    pose = scenario.cameras[1].pose
    essential = skew(pose.translation) @ pose.rotation
    assert np.max(epipolar_angles(essential, b0.reshape(-1, 3), b1.reshape(-1, 3))) < 1e-12


def test_too_few_and_degenerate_correspondences_are_errors() -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.0, np.random.default_rng(3), n=20)
    b0, b1 = _bearings(scenario, data)
    with pytest.raises(InsufficientDataError, match="at least 8"):
        relative_pose(b0[:2], b1[:2], 600.0, threshold_rad=1e-3, rng=np.random.default_rng(0))
    noise = np.random.default_rng(4).normal(size=b1.shape)
    with pytest.raises(DegenerateDataError):
        relative_pose(
            b0,
            noise / np.linalg.norm(noise, axis=-1, keepdims=True),
            600.0,
            threshold_rad=1e-6,
            rng=np.random.default_rng(0),
        )
