"""Result YAML and camera_info YAML."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from rigs import scenario_data

from wand_calib_ros.core.camera_model import to_opencv_fisheye
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.result_yaml import read_result, write_camera_infos, write_result


@pytest.fixture(scope="module")
def result():  # type: ignore[no-untyped-def]
    scenario, data, _ = scenario_data("paper", 1)
    return calibrate(scenario.rig, data.observations)


def test_result_round_trip_keeps_the_geometry(tmp_path: Path, result) -> None:  # type: ignore[no-untyped-def]
    write_result(result, tmp_path / "result.yaml")
    reference, cameras = read_result(tmp_path / "result.yaml")
    assert reference == "cam0"
    for camera in result.cameras:
        back = cameras[camera.name]
        assert np.array_equal(back.model.k, camera.model.k)
        assert np.array_equal(back.model.principal_point, camera.model.principal_point)
        assert np.array_equal(back.pose.rotation, camera.pose.rotation)
        assert np.array_equal(back.pose.translation, camera.pose.translation)
    document = yaml.safe_load((tmp_path / "result.yaml").read_text())
    entry = document["cameras"]["cam1"]
    assert {"rms_reprojection_px", "std", "opencv_equidistant", "m"} <= set(entry)
    assert document["metrics"]["wand_length_rms_mm"] == pytest.approx(result.wand_length_rms_mm)
    assert "equidistant" in document["conventions"]["equivalence"]


def test_camera_info_files_follow_camera_calibration(tmp_path: Path, result) -> None:  # type: ignore[no-untyped-def]
    paths = write_camera_infos(result, tmp_path / "info")
    assert [p.name for p in paths] == ["cam0.yaml", "cam1.yaml"]
    info = yaml.safe_load(paths[1].read_text())
    model = result.camera("cam1").model
    opencv = to_opencv_fisheye(model)
    assert info["distortion_model"] == "equidistant"
    assert info["image_width"] == 640 and info["image_height"] == 480
    assert np.allclose(np.reshape(info["camera_matrix"]["data"], (3, 3)), opencv.camera_matrix)
    assert np.allclose(info["distortion_coefficients"]["data"], opencv.distortion)
    assert info["projection_matrix"]["cols"] == 4


def test_reading_something_else_is_a_format_error(tmp_path: Path) -> None:
    path = tmp_path / "x.yaml"
    path.write_text("a: 1\n")
    with pytest.raises(FormatError, match="not a wand_calib_ros result"):
        read_result(path)
