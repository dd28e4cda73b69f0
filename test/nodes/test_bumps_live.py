"""After /calibrate, the collector watches the rig: a camera moved is named on /diagnostics and in the log."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import Ros, wait_until

from wand_calib_ros.core.geometry import Pose
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.scenarios import paper_three_camera_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PolygonStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402
from wand_calib_ros.nodes.collector import POINTS_QOS, CollectorNode  # noqa: E402
from wand_calib_ros.nodes.messages import points_message  # noqa: E402


def test_a_camera_moved_after_calibrate_is_named_and_an_untouched_one_is_not(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_three_camera_scenario()
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    common = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("require_coverage", value=False),
    ]
    collector = ros.add(
        CollectorNode(
            context=ros.context,
            parameter_overrides=[
                *common,
                Parameter("input", value="points"),
                Parameter("with_calibrator", value=False),
            ],
        )
    )
    ros.add(
        CalibratorNode(
            context=ros.context,
            parameter_overrides=[*common, Parameter("write_report", value=False)],
            before_calibrate=collector.flush,
            after_calibrate=collector.after_calibrate,
        )
    )
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    publishers = {
        n: ros.helper.create_publisher(PolygonStamped, f"/{n}/wand_points", POINTS_QOS)
        for n in scenario.rig.camera_names
    }
    assert wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 10)
    sent = [0]

    def play(uv: np.ndarray) -> None:
        for frame in uv:
            sent[0] += 1
            stamp = Time(sec=1000 + sent[0] // 30, nanosec=int(sent[0] % 30 * 1e9 / 30))
            for c, name in enumerate(scenario.rig.camera_names):
                points = frame[c] if np.all(np.isfinite(frame[c])) else None
                publishers[name].publish(points_message(points, Header(stamp=stamp, frame_id=name)))
            time.sleep(0.002)
        assert wait_until(lambda: min(collector.received.values()) == sent[0], 20)

    def flagged() -> dict[str, str]:
        latest = diagnostics[-1] if diagnostics else None
        return {
            s.hardware_id: s.message for s in (latest.status if latest else []) if s.level == DiagnosticStatus.ERROR
        }

    play(simulate(scenario, 1.0, np.random.default_rng(1)).observations.uv)
    answer = ros.helper.create_client(Trigger, "calibrate").call(Trigger.Request(), timeout_sec=120)
    assert answer.success, answer.message
    play(simulate(scenario, 1.0, np.random.default_rng(2), n=150).observations.uv)  # untouched
    time.sleep(2.5)  # two feedback rounds judge it
    assert not flagged(), flagged()
    cameras = list(scenario.cameras)
    moved = Pose(cameras[1].pose.rotation, cameras[1].pose.translation + np.array([20.0, 0.0, 0.0]))
    cameras[1] = replace(cameras[1], pose=moved)
    play(simulate(replace(scenario, cameras=tuple(cameras)), 1.0, np.random.default_rng(3), n=150).observations.uv)
    assert wait_until(lambda: "cam1" in flagged(), 10), [d.status[1].message for d in diagnostics[-3:]]
    assert flagged()["cam1"].startswith("cam1 moved")
