"""Result YAML and camera_info YAML."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from rigs import scenario_data, timed_take

from wand_calib_ros.core.model.camera_model import (
    PLUMB_BOB,
    RATIONAL_POLYNOMIAL,
    CameraModel,
    from_opencv_pinhole,
    project,
    to_opencv_fisheye,
)
from wand_calib_ros.core.model.rig import RigSpec, WandSpec
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.result_yaml import camera_info_dict, read_result, write_calibration, write_result, yaml_text
from wand_calib_ros.io.rig_yaml import load_rig, save_rig
from wand_calib_ros.sim.clocks import TakeOptions
from wand_calib_ros.sim.scenarios import SCENARIOS, simulate


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
    paths = write_calibration(result, tmp_path / "result.yaml", tmp_path / "info")[1:]
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


def test_results_without_stamps_give_their_timing_in_frames(tmp_path: Path, result) -> None:  # type: ignore[no-untyped-def]
    write_result(result, tmp_path / "result.yaml")
    document = yaml.safe_load((tmp_path / "result.yaml").read_text())
    # simulated independent placements: no continuous motion, so nothing could be estimated
    assert document["timing"]["time_offsets"] == "fixed" and document["timing"]["unit"] == "frames"
    assert "continuous motion" in document["timing"]["notes"][0]
    for entry in document["cameras"].values():  # keys only for what was estimated: none here
        assert "time_offset_frames" not in entry and "rolling_shutter_readout_frames" not in entry
        assert "time_offset_frames" not in entry["std"]
    _, cameras = read_result(tmp_path / "result.yaml")  # read back as zeros
    assert all(c.time_offset == 0.0 and c.readout == 0.0 for c in cameras.values())


def test_estimated_time_offsets_are_written_in_seconds_with_their_std(tmp_path: Path) -> None:
    scenario, observations, _ = timed_take("paper3", 0, 0.5, TakeOptions(duration_s=10.0, readout_s=0.02))
    result = calibrate(scenario.rig, observations)
    write_result(result, tmp_path / "result.yaml")
    document = yaml.safe_load((tmp_path / "result.yaml").read_text())
    timing = document["timing"]
    assert timing["unit"] == "s" and timing["time_offsets"] == "estimated"
    assert set(timing["rolling_shutter"].values()) == {"estimated"}
    assert timing["frame_period_s"] == pytest.approx(1 / 30, rel=0.01)
    reference = document["reference_camera"]
    assert document["cameras"][reference]["time_offset_s"] == 0.0
    for name, entry in document["cameras"].items():
        assert entry["rolling_shutter_readout_s"] == pytest.approx(0.02, abs=0.003)
        assert 0 < entry["std"]["rolling_shutter_readout_s"] < 0.003
        if name != reference:
            assert 0 < entry["std"]["time_offset_s"] < 0.001
    _, cameras = read_result(tmp_path / "result.yaml")
    assert cameras["cam1"].time_offset == document["cameras"]["cam1"]["time_offset_s"]
    assert cameras["cam1"].readout == document["cameras"]["cam1"]["rolling_shutter_readout_s"]


def test_files_are_the_text_pyyaml_itself_writes(tmp_path: Path, result) -> None:  # type: ignore[no-untyped-def]
    # libyaml's emitter, where PyYAML has it, writes the same text as PyYAML's own (long warnings,
    # special floats and nested lists included).
    paths = write_calibration(result, tmp_path / "result.yaml", tmp_path / "info")
    documents = [yaml.safe_load(path.read_text()) for path in paths]
    documents[0]["warnings"] = ["cam1: a warning long enough to wrap " * 6 + "(a: b # c)", "multi\nline", ""]
    documents[0]["special"] = [float("nan"), float("inf"), -0.0, 1e-300, None, True]
    for document in documents:
        assert yaml_text(document) == yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=120)
    assert paths[0].read_text() == yaml.safe_dump(
        yaml.safe_load(paths[0].read_text()), sort_keys=False, default_flow_style=None, width=120
    )


@pytest.fixture(scope="module")
def pinhole_result():  # type: ignore[no-untyped-def]
    """The mixed rig with a plumb_bob conventional camera, calibrated in that model (the rig says so)."""
    scenario = SCENARIOS["mixed"](pinhole=True)
    data = simulate(scenario, 1.0, np.random.default_rng(5))
    rig = dataclasses.replace(
        scenario.rig,
        cameras=(scenario.rig.cameras[0], dataclasses.replace(scenario.rig.cameras[1], camera_model=PLUMB_BOB)),
    )
    return calibrate(rig, data.observations)


def _same_camera(a: CameraModel, b: CameraModel) -> None:
    """Two models of one camera: the same model, parameters to the last bits, projections to 1e-9 px."""
    assert a.distortion_model == b.distortion_model and a.image_size == b.image_size
    for x, y in ((a.k, b.k), (a.principal_point, b.principal_point), (a.lens_vector(), b.lens_vector())):
        assert np.allclose(x, y, rtol=1e-15, atol=1e-300)
    rays = np.random.default_rng(0).normal(size=(200, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0]
    assert np.abs(project(a, rays) - project(b, rays)).max() < 1e-9


def test_a_plumb_bob_camera_round_trips_through_the_result_and_camera_info(tmp_path: Path, pinhole_result) -> None:  # type: ignore[no-untyped-def]
    result = pinhole_result
    assert result.camera("cam1").model.distortion_model == PLUMB_BOB
    paths = write_calibration(result, tmp_path / "result.yaml", tmp_path / "info")
    _, cameras = read_result(paths[0])
    for camera in result.cameras:  # read back exactly
        back = cameras[camera.name].model
        assert back.distortion_model == camera.model.distortion_model
        assert np.array_equal(back.k, camera.model.k) and np.array_equal(back.lens_vector(), camera.model.lens_vector())
    entry = yaml.safe_load(paths[0].read_text())["cameras"]["cam1"]
    assert entry["camera_model"] == PLUMB_BOB and "opencv_equidistant" not in entry
    assert entry["opencv"]["distortion_model"] == PLUMB_BOB and len(entry["opencv"]["distortion"]) == 5
    info = yaml.safe_load((tmp_path / "info" / "cam1.yaml").read_text())
    assert info["distortion_model"] == PLUMB_BOB and info["distortion_coefficients"]["cols"] == 5
    # a driver's camera_info is what a rig description can give back: the same camera
    scenario = SCENARIOS["mixed"](pinhole=True)
    rig = dataclasses.replace(scenario.rig, cameras=tuple(
        dataclasses.replace(spec, intrinsics=result.camera(spec.name).model) for spec in scenario.rig.cameras
    ))  # fmt: skip
    save_rig(rig, tmp_path / "cameras.yaml")
    text = (tmp_path / "cameras.yaml").read_text()
    document = yaml.safe_load(text)
    document["cameras"][1]["intrinsics"] = {"camera_info": str(tmp_path / "info" / "cam1.yaml")}
    (tmp_path / "from_info.yaml").write_text(yaml.safe_dump(document))
    for path in (tmp_path / "cameras.yaml", tmp_path / "from_info.yaml"):
        loaded = load_rig(path).cameras[1].intrinsics
        assert loaded is not None
        _same_camera(loaded, result.camera("cam1").model)


def test_a_rational_polynomial_camera_info_round_trips(tmp_path: Path) -> None:
    camera_matrix = np.array([[800.0, 0.0, 322.0], [0.0, 803.0, 251.0], [0.0, 0.0, 1.0]])
    distortion = np.array([-0.2, 0.05, 1e-3, -2e-3, 0.01, 0.1, 0.02, 0.003])
    spec = SCENARIOS["conventional"]().rig.cameras[0]
    m = np.array([spec.m[0], spec.m[0] * 803 / 800])
    model = from_opencv_pinhole(camera_matrix, distortion, m, spec.image_size, RATIONAL_POLYNOMIAL)
    (tmp_path / "cam0.yaml").write_text(yaml_text(camera_info_dict("cam0", model)))
    rig = RigSpec(WandSpec.from_lengths(400, 200), (dataclasses.replace(spec, intrinsics=model),))
    save_rig(rig, tmp_path / "cameras.yaml")
    document = yaml.safe_load((tmp_path / "cameras.yaml").read_text())
    assert document["cameras"][0]["intrinsics"]["distortion_model"] == RATIONAL_POLYNOMIAL
    document["cameras"][0]["intrinsics"] = "cam0.yaml"
    (tmp_path / "cameras.yaml").write_text(yaml.safe_dump(document))
    loaded = load_rig(tmp_path / "cameras.yaml").cameras[0].intrinsics
    assert loaded is not None
    _same_camera(loaded, model)
    info = yaml.safe_load((tmp_path / "cam0.yaml").read_text())
    assert np.allclose(info["distortion_coefficients"]["data"], distortion, rtol=1e-15)
