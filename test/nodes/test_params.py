"""Start-up validation: every unusable parameter is one clear error naming it."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import Ros

from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

rclpy = pytest.importorskip("rclpy")

from rclpy.parameter import Parameter  # noqa: E402

from wand_calib_ros.io.errors import FormatError  # noqa: E402
from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402
from wand_calib_ros.nodes.collector import CollectorNode  # noqa: E402
from wand_calib_ros.nodes.detector import DetectorNode  # noqa: E402
from wand_calib_ros.nodes.params import SettingsError  # noqa: E402
from wand_calib_ros.nodes.runner import EXIT_SETTINGS  # noqa: E402


@pytest.mark.parametrize(
    ("node", "overrides", "message"),
    [
        (CollectorNode, {}, "wand_calib_collector's parameter cameras_file is required (in its section"),
        (CollectorNode, {"cameras_file": "missing.yaml"}, "no such file"),
        (CollectorNode, {"sync_tolerance_ms": 5}, "sync_tolerance_ms must be a number with a decimal point (write 5.0"),
        (CollectorNode, {"buffer_capacity": 5}, "buffer_capacity must lie in [100"),
        (CollectorNode, {"input": "video"}, "input must be one of images, points"),
        (CollectorNode, {"min_image_fraction": 1.5}, "min_image_fraction must lie in [0.0, 1.0]"),
        (
            CalibratorNode,
            {"commit_to_drivers": "yes"},
            "wand_calib_calibrator's parameter commit_to_drivers must be true",
        ),
        (CalibratorNode, {"export_formats": "opencv, mat"}, "export_formats: unknown format(s) mat; known: opencv"),
        (DetectorNode, {}, "parameter camera is required"),
        (DetectorNode, {"camera": "cam7"}, "'cam7' is not in"),
    ],
)
def test_bad_parameters_are_named(ros: Ros, tmp_path: Path, node: type, overrides: dict, message: str) -> None:
    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    values = {"cameras_file": str(tmp_path / "cameras.yaml"), "output_dir": str(tmp_path / "out")}
    if node is CollectorNode and not overrides:
        values.pop("cameras_file")
    values |= {k: (str(tmp_path / v) if k == "cameras_file" else v) for k, v in overrides.items()}
    with pytest.raises(SettingsError) as raised:
        node(context=ros.context, parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
    assert message in str(raised.value)


def test_a_broken_rig_file_is_a_format_error(ros: Ros, tmp_path: Path) -> None:
    (tmp_path / "cameras.yaml").write_text("wand: {L1: 400}\n")
    with pytest.raises(FormatError, match="'wand' must be a mapping with L1 and L2"):
        CollectorNode(
            context=ros.context, parameter_overrides=[Parameter("cameras_file", value=str(tmp_path / "cameras.yaml"))]
        )


def test_main_turns_a_bad_parameter_into_exit_code_2(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    from wand_calib_ros.nodes.collector import main

    code = main(["collector", "--ros-args", "-p", f"cameras_file:={tmp_path / 'none.yaml'}"])
    assert code == EXIT_SETTINGS
    err = capfd.readouterr().err
    assert "no such file" in err and "Traceback" not in err


@pytest.mark.parametrize("name", ["collector", "calibrator", "detector"])
def test_shipped_params_files_name_only_declared_parameters(name: str) -> None:
    import yaml

    from wand_calib_ros.nodes import calibrator, collector, detector

    declared = {
        "wand_calib_collector": {p.name for p in collector.PARAMS},
        "wand_calib_calibrator": {p.name for p in calibrator.PARAMS},
        "wand_calib_detector": {p.name for p in detector.PARAMS},
    }
    document = yaml.safe_load((Path(__file__).parents[2] / "config" / f"{name}.params.yaml").read_text())
    for node, section in document.items():
        keys = set(section["ros__parameters"])
        allowed = set.union(*declared.values()) if node == "/**" else declared[node.removeprefix("/**/")]
        assert keys <= allowed, (node, keys - allowed)


def test_start_up_parameters_refuse_a_later_set_with_a_reason(ros: Ros, tmp_path: Path) -> None:
    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    overrides = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
    ]
    collector = ros.add(CollectorNode(context=ros.context, parameter_overrides=overrides))
    calibrator = ros.add(CalibratorNode(context=ros.context, parameter_overrides=overrides))
    for node, name, value in ((collector, "input", "bogus"), (calibrator, "commit_to_drivers", True)):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and "read-only" in result.reason and "restart the node" in result.reason
    assert collector.get_parameter("input").value == "images"
    assert calibrator.drivers == {}  # not committing: no set_camera_info clients to list
    assert not any("set_camera_info" in name for name, _ in ros.helper.get_service_names_and_types())


def test_feedback_keeps_flowing_with_sim_time_and_no_clock(ros: Ros, tmp_path: Path) -> None:
    from conftest import wait_until
    from diagnostic_msgs.msg import DiagnosticArray

    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    overrides = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("use_sim_time", value=True),  # and nobody publishes /clock
    ]
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    ros.add(CollectorNode(context=ros.context, parameter_overrides=overrides, namespace="rig1"))
    assert wait_until(lambda: len(diagnostics) >= 2, 10)
    names = {status.name for status in diagnostics[-1].status}  # which collector: an aggregator tells rigs apart
    assert {"rig1/wand_calib_collector: cam0", "rig1/wand_calib_collector: rig"} <= names


def test_a_relative_rig_path_is_also_looked_up_in_the_installed_share_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from wand_calib_ros.nodes.params import existing_file

    prefix = tmp_path / "install"
    (prefix / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (prefix / "share" / "ament_index" / "resource_index" / "packages" / "wand_calib_ros").touch()
    (prefix / "share" / "wand_calib_ros" / "config").mkdir(parents=True)
    save_rig(paper_fisheye_scenario().rig, prefix / "share" / "wand_calib_ros" / "config" / "rig.yaml")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    monkeypatch.chdir(tmp_path)
    found = existing_file({"cameras_file": "config/rig.yaml"}, "cameras_file")
    assert found == prefix / "share" / "wand_calib_ros" / "config" / "rig.yaml"
    (tmp_path / "config").mkdir()
    save_rig(paper_fisheye_scenario().rig, tmp_path / "config" / "rig.yaml")  # the working directory wins
    assert existing_file({"cameras_file": "config/rig.yaml"}, "cameras_file") == Path("config/rig.yaml")
    with pytest.raises(SettingsError, match=r"no such file config/none.yaml \(nor in .*share/wand_calib_ros\)"):
        existing_file({"cameras_file": "config/none.yaml"}, "cameras_file")


def test_an_in_process_calibrator_takes_the_collectors_settings_and_folder(
    ros: Ros, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    # A params file with a section for the collector only; or a calibrator section naming another output_dir.
    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    collector_values = {"cameras_file": str(tmp_path / "cameras.yaml"), "output_dir": str(tmp_path / "rig")}
    alone = ros.add(CalibratorNode(context=ros.context, collector_values=collector_values))
    assert alone.output_dir == tmp_path / "rig" and alone.rig.camera_names == ("cam0", "cam1")
    other = Parameter("output_dir", value=str(tmp_path / "elsewhere"))
    node = CalibratorNode(context=ros.context, collector_values=collector_values, parameter_overrides=[other])
    ros.add(node)
    assert node.output_dir == tmp_path / "rig"
    assert (
        f"output_dir {tmp_path / 'elsewhere'} of wand_calib_calibrator is not its collector's" in capfd.readouterr().err
    )


def test_a_second_collector_on_the_same_folder_refuses(ros: Ros, tmp_path: Path) -> None:
    from wand_calib_ros.collection.errors import CollectionError

    save_rig(paper_fisheye_scenario().rig, tmp_path / "cameras.yaml")
    overrides = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("with_calibrator", value=False),
        Parameter("running_estimate", value=False),
    ]
    first = ros.add(CollectorNode(context=ros.context, parameter_overrides=overrides))
    with pytest.raises(
        CollectionError, match=r"output_dir .*out is being written by another collector \(process \d+\)"
    ):
        CollectorNode(context=ros.context, parameter_overrides=overrides)
    first.close()  # its folder is free again
    again = CollectorNode(context=ros.context, parameter_overrides=overrides)
    again.close()
