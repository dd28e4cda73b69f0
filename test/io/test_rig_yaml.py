"""Rig description: round trip and clear errors."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest
import yaml

from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.rig_yaml import load_rig, save_rig
from wand_calib_ros.sim.scenarios import mixed_pair_scenario

GOOD = """wand: {L1: 400.0, L2: 200.0}
cameras:
  - {name: cam0, image_size: [640, 480], pixel_size_um: [5.6, 5.6], nominal_focal_mm: 1.8, max_view_angle_deg: 92.5}
  - {name: cam1, image_size: [640, 480], pixel_size_um: [5.6, 5.6], nominal_focal_mm: 1.8, max_view_angle_deg: 92.5,
     lens: fisheye, image_topic: /cam1/image_raw}
"""


def test_reads_the_contract_example(tmp_path: Path) -> None:
    path = tmp_path / "cameras.yaml"
    path.write_text(GOOD)
    rig = load_rig(path)
    assert rig.wand.L == 600.0 and rig.camera_names == ("cam0", "cam1")
    assert rig.cameras[1].lens == "fisheye" and rig.cameras[0].lens is None
    assert rig.cameras[0].m[0] == pytest.approx(1000 / 5.6)


def test_write_read_round_trip(tmp_path: Path) -> None:
    rig = mixed_pair_scenario().rig
    save_rig(rig, tmp_path / "rig.yaml")
    assert load_rig(tmp_path / "rig.yaml") == rig
    rolling = RigSpec(rig.wand, (replace(rig.cameras[0], readout_ms=18.5), rig.cameras[1]))
    save_rig(rolling, tmp_path / "rolling.yaml")
    back = load_rig(tmp_path / "rolling.yaml")
    assert back == rolling and back.cameras[0].readout_ms == 18.5 and back.cameras[1].readout_ms is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (GOOD.replace("L1: 400.0", "L1: 0.0"), "wand lengths must be positive"),
        (GOOD.replace("L2: 200.0", "L2: -5"), "wand lengths must be positive"),
        (GOOD.replace("wand: {L1: 400.0, L2: 200.0}", "wand: {L1: 400.0}"), "L1 and L2"),
        (GOOD.replace("nominal_focal_mm: 1.8, max", "max"), "camera 'cam0' lacks nominal_focal_mm"),
        (GOOD.replace("lens: fisheye", "lens: pinhole"), "lens must be one of"),
        (GOOD.replace("max_view_angle_deg: 92.5}", "max_view_angle_deg: 200}"), "must be < 180"),
        (
            GOOD.replace(
                "[640, 480], pixel_size_um: [5.6, 5.6], nominal_focal_mm: 1.8, max_view_angle_deg: 92.5}",
                "[640, 480], pixel_size_um: [5.6], nominal_focal_mm: 1.8, max_view_angle_deg: 92.5}",
                1,
            ),
            "pixel_size_um must be a list of two numbers",
        ),
        (GOOD.replace("name: cam1", "name: cam0"), "repeated: cam0"),
        (GOOD.replace("lens: fisheye", "lens: fisheye, readout_ms: -3"), "camera 'cam1' readout_ms is the rolling"),
        (GOOD.replace("lens: fisheye", "lens: fisheye, readout_ms: fast"), "camera 'cam1' readout_ms must be a number"),
        ("cameras: [", "not valid YAML"),
        ("- 1\n- 2\n", "expected a mapping"),
    ],
)
def test_bad_rig_descriptions_name_the_problem(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "cameras.yaml"
    path.write_text(text)
    with pytest.raises(FormatError, match=message) as error:
        load_rig(path)
    assert str(path) in str(error.value)


def test_missing_file_is_a_format_error(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="cannot read"):
        load_rig(tmp_path / "nope.yaml")


def test_a_binary_file_is_a_format_error(tmp_path: Path) -> None:
    path = tmp_path / "cameras.yaml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    with pytest.raises(FormatError, match=r"cameras.yaml: not UTF-8 text \(it holds the byte 0x89\)"):
        load_rig(path)


def test_frame_ids_default_to_the_camera_names_and_are_checked(tmp_path: Path) -> None:
    from wand_calib_ros.io.rig_yaml import load_camera_endpoints

    path = tmp_path / "cameras.yaml"
    save_rig(mixed_pair_scenario().rig, path)
    assert {n: e.frame_id for n, e in load_camera_endpoints(path).items()} == {"cam0": "cam0", "cam1": "cam1"}
    text = path.read_text()
    path.write_text(text.replace("- name: cam1\n", "- name: cam1\n  frame_id: cam1_optical_frame\n"))
    assert load_camera_endpoints(path)["cam1"].frame_id == "cam1_optical_frame"
    path.write_text(text.replace("- name: cam1\n", "- name: cam1\n  frame_id: /cam1\n"))
    with pytest.raises(FormatError, match="camera 'cam1' frame_id must be a tf frame name"):
        load_camera_endpoints(path)


def test_known_intrinsics_round_trip_and_come_from_a_camera_info_file(tmp_path: Path) -> None:
    import numpy as np

    from wand_calib_ros.io.result_yaml import camera_info_dict, write_yaml
    from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

    scenario = paper_fisheye_scenario()
    truth = scenario.cameras[1].model
    given = replace(scenario.rig.cameras[1], intrinsics=truth, intrinsics_fixed=False)
    rig = RigSpec(scenario.rig.wand, (scenario.rig.cameras[0], given))
    save_rig(rig, tmp_path / "rig.yaml")
    back = load_rig(tmp_path / "rig.yaml").cameras[1]
    assert back.intrinsics is not None and not back.intrinsics_fixed and not back.holds_intrinsics
    assert np.allclose(back.intrinsics.intrinsic_vector(), truth.intrinsic_vector(), rtol=1e-12, atol=1e-12)
    # a ROS camera_info YAML (as camera_calibration or this package writes it), relative to cameras.yaml
    (tmp_path / "info").mkdir()
    write_yaml(camera_info_dict("cam1", truth), tmp_path / "info" / "cam1.yaml")
    document = yaml.safe_load((tmp_path / "rig.yaml").read_text())
    document["cameras"][1]["intrinsics"] = "info/cam1.yaml"
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(document))
    from_file = load_rig(tmp_path / "rig.yaml").cameras[1]
    assert from_file.holds_intrinsics and from_file.intrinsics is not None
    assert np.allclose(from_file.intrinsics.intrinsic_vector(), truth.intrinsic_vector(), rtol=1e-9)


@pytest.mark.parametrize(
    ("intrinsics", "message"),
    [
        ("{K: [800, 0, 320, 0, 800, 240, 0, 0, 1]}", "camera 'cam0' intrinsics lacks D"),
        ("{K: [800, 0, 320, 0, 800], D: [0, 0, 0, 0]}", "camera 'cam0' intrinsics K must be a list of 9 numbers"),
        ("{K: [800, 0, 320, 0, 800, 240, 0, 0, 1], D: [0, 0, 0, 0], fixed: yes please}", "fixed must be true or false"),
        ("{K: [800, 0, 320, 0, 800, 240, 0, 0, 1], D: [0, 0, 0]}", "equidistant distortion has 4 coefficients"),
        (
            "{K: [800, 0, 320, 0, 800, 240, 0, 0, 1], D: [0, 0, 0, 0], distortion_model: kb8}",
            "distortion model 'kb8' is not supported",
        ),
        (  # converted to the equidistant model only where the rig asks for it, and only when it converts
            "{K: [300, 0, 320, 0, 300, 240, 0, 0, 1], D: [-0.05, 0, 0.002, 0], distortion_model: plumb_bob}, "
            "camera_model: equidistant",
            "camera 'cam0': the plumb_bob intrinsics differ",
        ),
        (
            "{K: [300, 0, 320, 0, 300, 240, 0, 0, 1], D: [-0.05, 0, 0, 0, 0, 0, 0, 0], distortion_model: plumb_bob}",
            "plumb_bob distortion has 4 or 5 (k1, k2, p1, p2[, k3]), got 8",
        ),
        (
            "{K: [300, 0, 320, 0, 300, 240, 0, 0, 1], D: [-0.05, 0, 0, 0], distortion_model: rational_polynomial}",
            "rational_polynomial distortion has 8 coefficients",
        ),
        ("{K: [800, 0, 320, 0, 800, 240, 0, 0, 1], D: [0, 0, 0, 0]}, camera_model: kb8", "camera_model must be one of"),
        (
            "{K: [800, 0, 320, 0, 800, 240, 0, 0, 1], D: [0, 0, 0, 0, 0], distortion_model: plumb_bob}, "
            "camera_model: plumb_bob",
            "camera_model plumb_bob is a pinhole model, which images no ray at 90 deg or more",
        ),
        ("missing.yaml", "camera 'cam0' intrinsics: no such camera_info file"),
        ("wrong_size.yaml", "is for 1280x1024 images, the camera's image_size is 640x480"),
    ],
)
def test_known_intrinsics_that_cannot_be_used_are_named(tmp_path: Path, intrinsics: str, message: str) -> None:
    (tmp_path / "wrong_size.yaml").write_text(
        "image_width: 1280\nimage_height: 1024\ncamera_matrix: {data: [800, 0, 640, 0, 800, 512, 0, 0, 1]}\n"
        "distortion_model: equidistant\ndistortion_coefficients: {data: [0, 0, 0, 0]}\n"
    )
    text = GOOD.replace("max_view_angle_deg: 92.5}", f"max_view_angle_deg: 92.5, intrinsics: {intrinsics}}}", 1)
    (tmp_path / "cameras.yaml").write_text(text)
    with pytest.raises(FormatError, match=re.escape(message)) as raised:
        load_rig(tmp_path / "cameras.yaml")
    assert "cameras.yaml" in str(raised.value) or "wrong_size" in str(raised.value)


def test_a_floor_tool_round_trips_and_is_the_floor_key(tmp_path: Path) -> None:
    rig = replace(mixed_pair_scenario().rig, floor_tool=((0.0, 0.0, 0.0), (500.0, 0.0, 0.0), (0.0, 300.0, 0.0)))
    save_rig(rig, tmp_path / "rig.yaml")
    document = yaml.safe_load((tmp_path / "rig.yaml").read_text())
    assert document["floor"] == {"points_mm": [[0.0, 0.0, 0.0], [500.0, 0.0, 0.0], [0.0, 300.0, 0.0]]}
    assert load_rig(tmp_path / "rig.yaml") == rig
    path = tmp_path / "cameras.yaml"
    path.write_text(GOOD + "floor: {points_mm: [[0, 0, 0], [500, 0, 0], [0, 300, 0]]}\n")
    assert load_rig(path).floor_tool == ((0.0, 0.0, 0.0), (500.0, 0.0, 0.0), (0.0, 300.0, 0.0))
