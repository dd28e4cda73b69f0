"""Rig descriptions, views and results that cannot be physically right are refused, naming the cause."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rigs import scenario_data

from wand_calib_ros.core.errors import PlausibilityError
from wand_calib_ros.core.judge.plausibility import check_result, check_rig, check_views
from wand_calib_ros.core.model.rig import RigSpec, WandSpec
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.scenarios import SCENARIOS


def _with_wand(rig: RigSpec, l1: float, l2: float) -> RigSpec:
    return replace(rig, wand=WandSpec.from_lengths(l1, l2))


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_the_simulated_rigs_and_their_views_pass(name: str) -> None:
    for seed in range(3):
        scenario, data, _ = scenario_data(name, seed)
        check_rig(scenario.rig)
        check_views(scenario.rig, data.observations)


def test_wand_lengths_in_metres_are_named() -> None:
    scenario, data, _ = scenario_data("paper", 0)
    with pytest.raises(PlausibilityError, match=r"cam0.*in metres or cm\? write them in mm \(e\.g\. 400 and 200"):
        check_views(_with_wand(scenario.rig, 0.4, 0.2), data.observations)


def test_wand_lengths_in_micrometres_are_named() -> None:
    scenario, data, _ = scenario_data("paper", 0)
    with pytest.raises(PlausibilityError, match="micrometres"):
        check_views(_with_wand(scenario.rig, 400_000.0, 200_000.0), data.observations)


@pytest.mark.parametrize("name", ["paper", "mixed", "ring6"])
def test_equal_segments_declared_for_a_2_to_1_wand_are_named(name: str) -> None:
    scenario, data, _ = scenario_data(name, 1)
    with pytest.raises(
        PlausibilityError,
        match=r"median image ratio \|AB\|/\|BC\| is (1\.9|2\.0).*L1/L2 = 300/300 = 1\.00: "
        r".* L1: (39|40)\d, L2: (19|20)\d",
    ):
        check_views(_with_wand(scenario.rig, 300.0, 300.0), data.observations)


@pytest.mark.parametrize("name", ["paper", "mixed", "ring6"])
def test_swapped_segments_are_named(name: str) -> None:
    scenario, data, _ = scenario_data(name, 2)
    with pytest.raises(PlausibilityError, match=r"L1 and L2 are swapped .*write L1: 400, L2: 200"):
        check_views(_with_wand(scenario.rig, 200.0, 400.0), data.observations)


def test_an_absurd_nominal_focal_is_named_with_the_focal_that_fits() -> None:
    scenario, _, _ = scenario_data("paper", 0)
    cameras = list(scenario.rig.cameras)
    cameras[1] = replace(cameras[1], nominal_focal_mm=1000.0)
    with pytest.raises(PlausibilityError, match=r"camera 'cam1': nominal_focal_mm 1000 .*a focal near 1\.\d+ mm"):
        check_rig(replace(scenario.rig, cameras=tuple(cameras)))


def test_results_with_a_wrong_focal_a_bad_camera_or_a_non_rigid_wand_are_refused() -> None:
    scenario, data, _ = scenario_data("mixed", 0)
    result = calibrate(scenario.rig, data.observations)
    uv = data.observations.uv
    check_result(scenario.rig, result, uv)  # the real result passes
    cam1 = result.camera("cam1")

    def with_cam1(**changes: object) -> object:
        cameras = tuple(replace(c, **changes) if c.name == "cam1" else c for c in result.cameras)
        return replace(result, cameras=cameras)

    far = cam1.model.with_intrinsic_vector(np.r_[cam1.model.k * 3.0, cam1.model.principal_point])
    with pytest.raises(PlausibilityError, match=r"camera 'cam1': the calibration puts its focal at 12\.\d mm"):
        check_result(scenario.rig, with_cam1(model=far), uv)  # type: ignore[arg-type]
    with pytest.raises(PlausibilityError, match=r"camera 'cam1': its reprojection RMS is 7\.50 px"):
        check_result(scenario.rig, with_cam1(rms_reprojection_px=7.5), uv)  # type: ignore[arg-type]
    with pytest.raises(PlausibilityError, match=r"wand: \|AC\| comes out 60 mm RMS away from 600 mm \(10 %, \d+x what"):
        check_result(scenario.rig, replace(result, wand_length_rms_mm=60.0), uv)


@pytest.mark.parametrize(("name", "seed"), [("paper", 0), ("paper", 1), ("mixed", 2), ("ring6", 3)])
def test_a_segment_given_10_percent_off_is_refused_naming_where_the_images_put_the_marker(name: str, seed: int) -> None:
    # The adjustment holds the wrong segment by bending the cameras (its pixel noise grows, the wand's overall
    # length still fits): the freely triangulated B shows where it is.
    scenario, data, _ = scenario_data(name, seed, noise=0.3)
    assert scenario.rig.wand.positions_mm == (0.0, 400.0, 600.0)
    refused = r"wand: the images put B 40[01]\.\d mm from A \(\+-0\.\d, \d+ placements\), the rig description 440 mm: "
    with pytest.raises(PlausibilityError, match=refused + "a segment length is wrong"):
        calibrate(_with_wand(scenario.rig, 440.0, 160.0), data.observations)
