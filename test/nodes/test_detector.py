"""Detector nodes publish wand points; the collector in points mode stores what detection finds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import Ros, publish_images

from wand_calib_ros.collection.recording import detect_recording
from wand_calib_ros.io.bags import ImageFrame
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import PolygonStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from wand_calib_ros.nodes.collector import POINTS_QOS, CollectorNode  # noqa: E402
from wand_calib_ros.nodes.detector import DetectorNode  # noqa: E402


def test_detectors_feed_a_points_collector(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 120, 30.0, RenderOptions(reflection_rate=0.2), np.random.default_rng(4))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    rig_file = Parameter("cameras_file", value=str(tmp_path / "cameras.yaml"))
    for name in scenario.rig.camera_names:
        ros.add(
            DetectorNode(
                context=ros.context,
                cli_args=["--ros-args", "-r", f"__node:=detector_{name}"],
                parameter_overrides=[
                    rig_file,
                    Parameter("camera", value=name),
                    Parameter("image_qos", value="reliable"),
                ],
            )
        )
    collector = ros.add(
        CollectorNode(
            context=ros.context,
            parameter_overrides=[
                rig_file,
                Parameter("output_dir", value=str(tmp_path / "out")),
                Parameter("input", value="points"),
                Parameter("with_calibrator", value=False),
            ],
        )
    )
    points = ros.collect(PolygonStamped, "/cam0/wand_points", POINTS_QOS)
    publish_images(ros, collector, recording, scenario.rig.camera_names)
    collector.flush()

    # One PolygonStamped per image, stamped like it: three points or empty.
    assert sorted(p.header.stamp.sec * 10**9 + p.header.stamp.nanosec for p in points) == sorted(
        stamp for camera, stamp, _ in recording.frames if camera == "cam0"
    )
    assert {len(p.polygon.points) for p in points} <= {0, 3}
    # The stored frames are the offline detector's (float32 points on the wire).
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    offline = detect_recording(frames, scenario.rig).observations
    stored = collector.session.buffer.observations()
    assert len(stored.frames) >= 0.9 * len(offline.frames)
    for uv in stored.uv:
        seen = np.isfinite(uv)
        distance = np.nan_to_num(np.abs(offline.uv[:, seen] - uv[seen]), nan=np.inf).max(axis=1)
        assert distance.min() < 1e-3
