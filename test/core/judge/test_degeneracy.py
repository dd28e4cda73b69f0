"""Intrinsics the data do not determine: refused naming the camera, its uncertainties and what would fix it."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS
from wand_calib_ros.core.errors import DegenerateDataError
from wand_calib_ros.core.judge.degeneracy import check_uncertainty
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec, WandSpec
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario


def _undetermined(spec: CameraSpec) -> None:
    """check_uncertainty on one camera whose focal is known to +-200 % and principal point to +-5000 px."""
    model = paper_fisheye_scenario().cameras[0].model
    std = np.zeros((1, N_CAMERA_PARAMS))
    std[0, 0], std[0, 5], std[0, 6] = 2.0 * model.k[0], 5000.0, 5000.0
    rig = RigSpec(WandSpec.from_lengths(400.0, 200.0), (spec,))
    check_uncertainty(rig, SimpleNamespace(state=SimpleNamespace(models=(model,)), camera_std=std))  # type: ignore[arg-type]


def test_a_narrow_camera_is_told_to_give_its_focal_and_a_wide_one_to_wave_more() -> None:
    wide = paper_fisheye_scenario().rig.cameras[0]
    with pytest.raises(DegenerateDataError, match=r"camera 'cam0': .* wave the wand through more of its view"):
        _undetermined(wide)
    narrow = replace(wide, nominal_focal_mm=43.0, max_view_angle_deg=1.5)
    with pytest.raises(DegenerateDataError, match=r"field of view is narrow \(6\.0 deg across\): give its focal"):
        _undetermined(narrow)
