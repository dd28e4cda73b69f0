"""The full two-camera pipeline against ground truth.

"Truth BA" is the bundle adjustment of the same data started from the true
cameras and placements: the best any initialisation can reach. The pipeline
must land within 1.15x of its errors (focal, principal point, E_r, E_t and
the wand-length error D_RMS on held-out placements).
"""

from __future__ import annotations

import numpy as np
import pytest
from rigs import errors_against_truth, fixed_of, in_truth_frame, scenario_data, truth_bundle

from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import calibrate

RATIO = 1.15


def _compare(name: str, seed: int, **kwargs: float | tuple[float, float]) -> tuple[dict, dict, object]:  # type: ignore[type-arg]
    scenario, data, held = scenario_data(name, seed, **kwargs)
    result = calibrate(scenario.rig, data.observations)
    mine = errors_against_truth(scenario, held, *in_truth_frame(result, scenario))
    reference = truth_bundle(scenario, data, fixed_of(result, scenario))
    best = errors_against_truth(scenario, held, reference.state.models, reference.state.poses)
    return mine, best, result


def _assert_within(mine: dict[str, float], best: dict[str, float]) -> None:
    for key, value in mine.items():
        # The absolute slack covers solver tolerance only (1e-4 px, 1e-5 deg).
        assert value <= RATIO * best[key] + 1e-4, f"{key}: pipeline {value:.5g} vs truth BA {best[key]:.5g}"


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_paper_fisheye_pair_reaches_the_truth_started_bundle_adjustment(seed: int) -> None:
    mine, best, result = _compare("paper", seed)
    _assert_within(mine, best)
    m, p = result.dof
    expected = 1.0 * np.sqrt(1 - p / m)  # sigma = 1 px
    counts = np.array([c.n_observations for c in result.cameras])
    overall = np.sqrt(np.sum(counts * np.array([c.rms_reprojection_px for c in result.cameras]) ** 2) / counts.sum())
    assert overall == pytest.approx(expected, rel=0.05)
    for camera in result.cameras:  # the parameters' share of each camera's residuals differs a little
        assert camera.rms_reprojection_px == pytest.approx(expected, rel=0.12)
    assert result.sigma_px == pytest.approx(1.0, rel=0.05)


@pytest.mark.parametrize("name", ["conventional", "mixed"])
def test_conventional_and_mixed_pairs_reach_the_truth_started_bundle_adjustment(name: str) -> None:
    mine, best, result = _compare(name, 4)
    _assert_within(mine, best)
    assert result.sigma_px == pytest.approx(1.0, rel=0.06)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"true_focal_mm": 1.5, "nominal_focal_mm": 2.0},
        {"true_focal_mm": 2.5, "nominal_focal_mm": 2.0},
        {"principal_point": (270.0, 190.0)},
        {"principal_point": (370.0, 290.0)},
    ],
    ids=["focal1.5", "focal2.5", "pp-50", "pp+50"],
)
def test_converges_from_the_paper_initial_offsets(kwargs: dict) -> None:  # type: ignore[type-arg]
    mine, best, _ = _compare("paper", 5, **kwargs)
    _assert_within(mine, best)


def test_reduced_distortion_model_is_no_worse_than_the_full_model_on_average() -> None:
    # Fixing insignificant k3..k5 must not cost accuracy against a truth-started BA with all of them free.
    totals_mine: dict[str, float] = {}
    totals_full: dict[str, float] = {}
    for seed in range(1, 9):  # an average: single draws go either way
        scenario, data, held = scenario_data("paper", seed)
        result = calibrate(scenario.rig, data.observations)
        full = truth_bundle(scenario, data)
        for key, value in errors_against_truth(scenario, held, *in_truth_frame(result, scenario)).items():
            totals_mine[key] = totals_mine.get(key, 0.0) + value**2
        for key, value in errors_against_truth(scenario, held, full.state.models, full.state.poses).items():
            totals_full[key] = totals_full.get(key, 0.0) + value**2
    for key in totals_mine:
        assert np.sqrt(totals_mine[key]) <= RATIO * np.sqrt(totals_full[key]), key


def test_result_reports_uncertainty_for_every_estimated_parameter() -> None:
    scenario, data, _ = scenario_data("paper", 1)
    result = calibrate(scenario.rig, data.observations)
    reference, other = result.cameras
    assert set(reference.parameter_std) >= {"k1", "k2", "u0", "v0"}
    assert not {"rx", "tx"} & set(reference.parameter_std)
    assert set(other.parameter_std) >= {"k1", "k2", "u0", "v0", "rx", "ry", "rz", "tx", "ty", "tz"}
    for camera in result.cameras:
        assert all(np.isfinite(v) and v > 0 for v in camera.parameter_std.values())
        for name in camera.fixed_coefficients:
            assert name not in camera.parameter_std and camera.model.k[int(name[1]) - 1] == 0.0
    assert result.lens_trials and all(np.isfinite(t.wand_rms_mm) for t in result.lens_trials)


def test_too_few_placements_is_a_clear_error() -> None:
    scenario, data, _ = scenario_data("paper", 1)
    few = data.observations.select_frames(np.arange(data.observations.frames.size) < 10)
    with pytest.raises(InsufficientDataError, match="only 10 placements"):
        calibrate(scenario.rig, few)


def test_wand_held_still_is_degenerate() -> None:
    scenario, data, _ = scenario_data("paper", 1)
    uv = np.repeat(data.observations.uv[:1], 50, axis=0) + np.random.default_rng(0).normal(
        scale=0.5, size=(50, 2, 3, 2)
    )
    still = WandObservations(np.arange(50), data.observations.camera_names, uv)
    with pytest.raises(DegenerateDataError, match="hardly moved"):
        calibrate(scenario.rig, still)


def test_camera_without_observations_is_named() -> None:
    scenario, data, _ = scenario_data("paper", 1)
    only_one = data.observations.select_cameras(("cam0",))
    with pytest.raises(InsufficientDataError, match="'cam1' has no observations"):
        calibrate(scenario.rig, only_one)


def test_a_camera_whose_chained_start_is_off_is_corrected_not_dropped() -> None:
    # Frames a collector stored while 41 % of the best-effort images were lost (benchmarks/live_collector.py,
    # 4 x 1280x1024): the chained start of cam02 makes its placements reconstruct 14 mm too long, and the
    # |AC| gate used to set all of them aside; cam03, seen only with it, then kept no view at all and was
    # reported with RMS NaN.
    from pathlib import Path

    from wand_calib_ros.io.observations_csv import read_observations
    from wand_calib_ros.io.rig_yaml import load_rig

    data = Path(__file__).parents[1] / "data" / "dropped_frames"
    rig = load_rig(data / "cameras.yaml")
    observations = read_observations(data / "observations.csv", rig.camera_names)
    result = calibrate(rig, observations)
    multi = observations.complete.sum(axis=1) >= 2
    for c, name in enumerate(rig.camera_names):
        camera = result.camera(name)
        assert camera.n_views >= 0.9 * (observations.complete[multi, c]).sum(), name
        assert np.isfinite(camera.rms_reprojection_px) and camera.rms_reprojection_px < 0.05


def test_a_camera_left_without_views_is_an_error_naming_it() -> None:
    from wand_calib_ros.core.judge.degeneracy import check_camera_views

    scenario, data, _ = scenario_data("paper", 1)
    used = data.observations.uv.copy()
    used[3:, 1] = np.nan  # cam1 keeps three views
    with pytest.raises(InsufficientDataError, match="camera 'cam1': only 3 of its 300 views fit the solution"):
        check_camera_views(scenario.rig, data.observations.uv, used)
