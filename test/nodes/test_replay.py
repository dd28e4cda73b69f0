"""Recorded bags (mcap, sqlite3, ROS 1 converted) replayed through the nodes in one process."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import LATCHED, Ros, wait_until
from rigs import compare_with_true_projections

from wand_calib_ros.io.bags import write_image_bag
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

rclpy = pytest.importorskip("rclpy")

from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import CameraInfo  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402
from wand_calib_ros.nodes.collector import CollectorNode  # noqa: E402
from wand_calib_ros.nodes.replay import ReplayNode  # noqa: E402


def _bag(tmp_path: Path, frames: list, cameras: tuple[str, ...], storage: str) -> Path:
    if storage != "ros1":
        write_image_bag(tmp_path / "bag", frames, cameras, storage=storage)
        return tmp_path / "bag"
    write_image_bag(tmp_path / "in.bag", frames, cameras, storage="ros1")
    convert = shutil.which("rosbags-convert", path=str(Path(sys.executable).parent))
    assert convert is not None
    subprocess.run(
        [convert, "--src", str(tmp_path / "in.bag"), "--dst", str(tmp_path / "bag")], check=True, timeout=120
    )
    return tmp_path / "bag"


@pytest.mark.parametrize("storage", ["mcap", "sqlite3", "ros1"])
def test_replayed_bag_calibrates_as_well_as_the_true_projections(ros: Ros, tmp_path: Path, storage: str) -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 300, 30.0, RenderOptions(reflection_rate=0.05), np.random.default_rng(11))
    bag = _bag(tmp_path, recording.frames, scenario.rig.camera_names, storage)
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    common = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("min_theta_fraction", value=0.5),
    ]
    collector = ros.add(
        CollectorNode(context=ros.context, parameter_overrides=[*common, Parameter("image_qos", value="reliable")])
    )
    ros.add(
        CalibratorNode(
            context=ros.context,
            parameter_overrides=[*common, Parameter("write_report", value=False)],
            before_calibrate=collector.flush,
        )
    )
    infos = ros.collect(CameraInfo, "wand_calib/cam0/camera_info", LATCHED)
    replay = ros.add(
        ReplayNode(
            context=ros.context,
            parameter_overrides=[common[0], Parameter("bag", value=str(bag)), Parameter("rate", value=4.0)],
        )
    )
    received = collector.session.received
    assert wait_until(lambda: sum(received.values()) == len(recording.frames), 20), received
    assert replay.published == len(recording.frames)

    client = ros.helper.create_client(Trigger, "calibrate")
    assert client.wait_for_service(timeout_sec=5)
    answer = client.call(Trigger.Request(), timeout_sec=120)
    assert answer.success, answer.message
    assert wait_until(lambda: bool(infos), 5)

    from wand_calib_ros.core.pipeline import calibrate

    observations = read_observations(tmp_path / "out" / "observations.csv", scenario.rig.camera_names)
    result = calibrate(scenario.rig, observations)  # what /calibrate computed from the same file
    _, written = read_result(tmp_path / "out" / "result.yaml")
    assert np.allclose(written["cam1"].model.intrinsic_vector(), result.camera("cam1").model.intrinsic_vector())
    assert infos[-1].k[0] == pytest.approx(result.camera("cam0").model.focal_px[0], rel=1e-9)
    assert compare_with_true_projections(scenario, recording.drawn, observations, result, factor=1.5) == []
