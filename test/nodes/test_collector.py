"""The collector and calibrator in-process: rendered images in, /calibrate, CameraInfo and files out."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import LATCHED, Ros, publish_images, wait_until

from wand_calib_ros import cli
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import TransformStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402
from wand_calib_ros.nodes.collector import CollectorNode  # noqa: E402


def test_collect_calibrate_and_publish(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 150, 30.0, RenderOptions(), np.random.default_rng(0))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    overrides = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("min_placements", value=50),
        Parameter("min_theta_fraction", value=0.5),
        Parameter("min_image_fraction", value=0.3),
        Parameter("min_depth_ratio", value=1.1),  # 5 s of waving reach about 1.2
    ]
    collector = ros.add(
        CollectorNode(context=ros.context, parameter_overrides=[*overrides, Parameter("image_qos", value="reliable")])
    )
    exports = Parameter("export_formats", value="anipose, kalibr")
    ros.add(
        CalibratorNode(context=ros.context, parameter_overrides=[*overrides, exports], before_calibrate=collector.flush)
    )
    infos = ros.collect(CameraInfo, "wand_calib/cam1/camera_info", LATCHED)
    transforms = ros.collect(TransformStamped, "wand_calib/cam1/extrinsics", LATCHED)
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    heat_maps = ros.collect(Image, "wand_calib/cam0/coverage", 1)
    publish_images(ros, collector, recording, scenario.rig.camera_names)

    client = ros.helper.create_client(Trigger, "calibrate")
    assert client.wait_for_service(timeout_sec=5)
    response = client.call(Trigger.Request(), timeout_sec=120)
    assert response.success, response.message
    assert str(tmp_path / "out" / "result.yaml") in response.message
    assert wait_until(lambda: bool(infos and transforms and diagnostics and heat_maps), 5)

    # The published results match the truth.
    centre = scenario.cameras[1].pose.center / 1000.0  # camera 1 in camera 0's frame, metres
    moved = transforms[-1].transform.translation
    assert (transforms[-1].header.frame_id, transforms[-1].child_frame_id) == ("cam0", "cam1")
    assert np.linalg.norm(np.array([moved.x, moved.y, moved.z]) - centre) < 0.01
    assert infos[-1].distortion_model == "equidistant"
    truth = scenario.cameras[1].model
    assert abs(infos[-1].k[0] - truth.focal_px[0]) < 0.5
    assert abs(infos[-1].k[2] - truth.principal_point[0]) < 1.0
    # Every image was accounted for, and nothing the labeller held back was lost at /calibrate.
    stream = collector.session.streams["cam0"]
    assert stream.stats.detected + sum(stream.stats.rejected.values()) == 150
    assert not stream.labeller.flush()

    # wand-calib calibrate on the persisted buffer computes exactly what /calibrate did.
    out = tmp_path / "out"
    offline = [
        "calibrate",
        "--cameras",
        str(tmp_path / "cameras.yaml"),
        "--observations",
        str(out / "observations.csv"),
    ]
    assert cli.main(["-q", *offline, "--output", str(tmp_path / "offline.yaml")]) == 0
    _, written = read_result(out / "result.yaml")
    _, again = read_result(tmp_path / "offline.yaml")
    for name, camera in again.items():
        assert np.array_equal(written[name].model.intrinsic_vector(), camera.model.intrinsic_vector())
        assert np.array_equal(written[name].pose.translation, camera.pose.translation)
    assert yaml.safe_load((out / "camera_info" / "cam1.yaml").read_text())["distortion_model"] == "equidistant"
    assert wait_until((out / "report" / "index.html").exists, 30)  # drawn after the answer
    assert (out / "export" / "anipose" / "calibration.toml").exists()
    assert (
        yaml.safe_load((out / "export" / "kalibr" / "camchain.yaml").read_text())["cam1"]["camera_model"] == "pinhole"
    )

    # Feedback: per camera diagnostics with counts, a heat map shaped like the image.
    names = {status.name for status in diagnostics[-1].status}
    assert {"wand_calib_collector: cam0", "wand_calib_collector: cam1", "wand_calib_collector: rig"} <= names
    cam1 = next(s for s in diagnostics[-1].status if s.name == "wand_calib_collector: cam1")
    values = {kv.key: kv.value for kv in cam1.values}
    assert abs(float(values["frame_rate_hz"]) - 30.0) < 0.1 and float(values["phase_ms"]) == 0.0  # triggered
    stored = read_observations(tmp_path / "out" / "observations.csv", scenario.rig.camera_names)
    assert stored.stamps is not None and np.all(np.isfinite(stored.stamps[np.isfinite(stored.uv[..., 0, 0])]))
    assert heat_maps[-1].encoding == "bgr8" and heat_maps[-1].width == 320


def test_calibrate_answers_clearly_when_busy_short_of_data_or_reset(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    overrides = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
    ]
    gate = threading.Event()
    collector = ros.add(CollectorNode(context=ros.context, parameter_overrides=overrides))
    ros.add(CalibratorNode(context=ros.context, parameter_overrides=overrides, before_calibrate=lambda: gate.wait(10)))
    client = ros.helper.create_client(Trigger, "calibrate")
    assert client.wait_for_service(timeout_sec=5)
    first = client.call_async(Trigger.Request())
    time.sleep(0.5)
    busy = client.call(Trigger.Request(), timeout_sec=5)
    assert not busy.success and "already running" in busy.message
    gate.set()
    assert wait_until(first.done, 10)
    assert not first.result().success and "nothing collected yet" in first.result().message

    data = simulate(scenario, 0.5, np.random.default_rng(0), n=30)
    for k, uv in enumerate(data.observations.uv):
        collector.session.buffer.offer(uv, np.full(len(scenario.cameras), 1.7e9 + k / 30.0))
    short = client.call(Trigger.Request(), timeout_sec=30)
    assert not short.success
    assert "coverage insufficient" in short.message and "cam0: 30 of 100 placements" in short.message

    reset = ros.helper.create_client(Trigger, "reset")
    assert reset.wait_for_service(timeout_sec=5)
    assert reset.call(Trigger.Request(), timeout_sec=10).success
    assert len(read_observations(next((tmp_path / "out").glob("observations.*.bak.csv"))).frames) == 30
    assert not collector.session.buffer.frames


def test_a_two_led_wand_live_from_images_to_the_calibration(ros: Ros, tmp_path: Path) -> None:
    from dataclasses import replace

    from wand_calib_ros.core.model.rig import WandSpec
    from wand_calib_ros.sim.scenarios import paper_three_camera_scenario

    scenario = replace(paper_three_camera_scenario(), wand=WandSpec((0.0, 600.0)))
    recording = render_recording(scenario, 150, 30.0, RenderOptions(), np.random.default_rng(3))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    overrides = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("require_coverage", value=False),
        Parameter("write_report", value=False),
    ]
    collector = ros.add(
        CollectorNode(context=ros.context, parameter_overrides=[*overrides, Parameter("image_qos", value="reliable")])
    )
    ros.add(CalibratorNode(context=ros.context, parameter_overrides=overrides, before_calibrate=collector.flush))
    publish_images(ros, collector, recording, scenario.rig.camera_names)
    response = ros.helper.create_client(Trigger, "calibrate").call(Trigger.Request(), timeout_sec=120)
    assert response.success, response.message
    buffer = (tmp_path / "out" / "observations.csv").read_text().splitlines()
    assert {row.split(",")[2] for row in buffer[1:]} == {"A", "B"}
    result = yaml.safe_load((tmp_path / "out" / "result.yaml").read_text())
    assert result["wand"] == {"points_mm": [0.0, 600.0]} and result["metrics"]["wand_length_rms_mm"] < 1.0
    for camera in scenario.cameras:
        pp = np.array(result["cameras"][camera.spec.name]["principal_point"])
        assert np.linalg.norm(pp - camera.model.principal_point) < 1.0
