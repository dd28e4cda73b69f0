"""What the launch file starts, and the command-line conventions every node executable follows."""

from __future__ import annotations

from pathlib import Path

import pytest

from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

pytest.importorskip("rclpy")

from wand_calib_ros.nodes.launch_plan import plan
from wand_calib_ros.nodes.params import SettingsError
from wand_calib_ros.nodes.runner import second_node_arguments, wants_help

ROOT = Path(__file__).resolve().parents[2]
PARAMS = str(ROOT / "config" / "collector.params.yaml")
DETECTOR_PARAMS = str(ROOT / "config" / "detector.params.yaml")


def test_the_default_launch_is_the_collector_with_its_params_file() -> None:
    (collector,) = plan(PARAMS, DETECTOR_PARAMS)
    assert (collector.executable, collector.name, collector.namespace) == ("collector", "wand_calib_collector", "")
    assert collector.params_files == (PARAMS,) and collector.overrides == {}


def test_detectors_run_in_their_cameras_namespaces_and_the_collector_takes_points(tmp_path: Path) -> None:
    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    rig = str(tmp_path / "cameras.yaml")
    collector, *detectors = plan(PARAMS, DETECTOR_PARAMS, cameras_file=rig, detectors="all", namespace="/rig1")
    assert collector.namespace == "/rig1"
    assert collector.params_files == (PARAMS,)
    assert collector.overrides == {"cameras_file": rig, "input": "points"}
    assert [(d.executable, d.name, d.namespace) for d in detectors] == [
        ("detector", "wand_calib_detector", "/rig1/cam0"),
        ("detector", "wand_calib_detector", "/rig1/cam1"),
    ]
    assert detectors[1].params_files == (DETECTOR_PARAMS,)
    assert detectors[1].overrides == {"cameras_file": rig, "camera": "cam1"}
    (only,) = plan(PARAMS, cameras_file=rig, detectors="cam1")[1:]
    assert only.params_files == () and only.overrides == {"cameras_file": rig, "camera": "cam1"}


def test_the_rig_of_the_params_file_is_found_in_the_share_folder_as_the_nodes_find_it() -> None:
    # The shipped params file names config/paper_fisheye_pair.yaml relative to the share folder.
    _, *detectors = plan(PARAMS, detectors="cam0", resolve=(ROOT,))
    assert [d.namespace for d in detectors] == ["cam0"]
    assert detectors[0].overrides == {"cameras_file": "config/paper_fisheye_pair.yaml", "camera": "cam0"}


def test_a_detector_for_a_camera_the_rig_lacks_is_refused_by_name(tmp_path: Path) -> None:
    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    with pytest.raises(SettingsError, match=r"detectors: cam7 not in .*cameras.yaml \(cameras: cam0, cam1\)"):
        plan(PARAMS, cameras_file=str(tmp_path / "cameras.yaml"), detectors="cam0, cam7")
    (tmp_path / "bare.params.yaml").write_text("/**:\n  ros__parameters:\n    output_dir: out\n")
    with pytest.raises(SettingsError, match=r"no cameras_file in .*bare.params.yaml; give cameras_file:=FILE"):
        plan(str(tmp_path / "bare.params.yaml"), detectors="all")


def test_a_second_node_keeps_everything_but_the_main_nodes_new_name() -> None:
    args = ["collector", "--ros-args", "-r", "__node:=mine", "-r", "__ns:=/rig1", "--params-file", "p.yaml"]
    args += ["--", "other", "--ros-args", "--remap", "__name:=x", "-p", "a:=1", "-r", "cal:__node:=c2"]
    assert second_node_arguments(args) == [
        "--ros-args",
        "-r",
        "__ns:=/rig1",
        "--params-file",
        "p.yaml",
        "-p",
        "a:=1",
        "-r",
        "cal:__node:=c2",
    ]


def test_help_is_asked_before_the_ros_arguments_only() -> None:
    assert wants_help(["collector", "--help"]) and wants_help(["collector", "-h", "--ros-args", "-p", "a:=1"])
    assert not wants_help(["collector", "--ros-args", "-p", "name:=-h"]) and not wants_help(["collector"])


@pytest.mark.parametrize("executable", ["collector", "calibrator", "detector", "replay"])
def test_every_node_executable_has_a_help_listing_its_parameters(
    executable: str, capsys: pytest.CaptureFixture[str]
) -> None:
    import importlib

    module = importlib.import_module(f"wand_calib_ros.nodes.{executable}")
    assert module.main([executable, "--help"]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"usage: ros2 run wand_calib_ros {executable} --ros-args")
    params = getattr(module, "PARAMS", None) or module.REPLAY_PARAMS
    for param in params:
        assert f"  {param.name} (" in text, param.name
    if executable == "collector":  # the in-process calibrator's parameters too
        assert "parameters of wand_calib_calibrator" in text and "  world_frame (str, default 'world')" in text
