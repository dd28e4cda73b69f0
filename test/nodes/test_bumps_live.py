"""After /calibrate, the collector watches the rig: a camera moved is named on /diagnostics and in the log,
and /refine re-estimates it from the frames after the move."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import LATCHED, Ros, points_rig, wait_until

from wand_calib_ros.core.judge.metrics import rereference
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.sim.scenarios import paper_three_camera_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402


def test_a_moved_camera_is_named_and_refined_and_an_untouched_one_is_not(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_three_camera_scenario()
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    markers = ros.collect(MarkerArray, "wand_calib/markers", LATCHED)
    play = points_rig(ros, scenario, tmp_path, {}, watch=True).play

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

    def cam1_off_mm() -> float:  # cam1's centre from the truth (moved), in cam0's frame, mm
        _, geometry = read_result(tmp_path / "out" / "result.yaml")
        poses = rereference({n: g.pose for n, g in geometry.items()}, "cam0")
        return float(np.linalg.norm(poses["cam1"].center - moved.compose(cameras[0].pose.inverse()).center))

    assert cam1_off_mm() > 15.0  # the calibration's cam1 is where it was
    refine = ros.helper.create_client(Trigger, "refine")
    started = time.perf_counter()
    answer = refine.call(Trigger.Request(), timeout_sec=60)
    took = time.perf_counter() - started
    assert answer.success, answer.message
    assert "re-estimated cam1 from the 1" in answer.message, answer.message  # about the 150 frames after
    assert cam1_off_mm() < 3.0, (cam1_off_mm(), answer.message)
    assert wait_until(lambda: len(markers) == 2, 5)  # the markers follow the repaired result
    _, geometry = read_result(tmp_path / "out" / "result.yaml")
    frustum = next(m for m in markers[-1].markers if (m.ns, m.id) == ("frustums", 1))
    centre = frustum.pose.position
    assert frustum.header.frame_id == "cam0"
    assert np.allclose([centre.x, centre.y, centre.z], geometry["cam1"].pose.center / 1000.0, atol=1e-9)
    print(f"/refine answered in {took:.2f} s: {answer.message}")
    play(simulate(replace(scenario, cameras=tuple(cameras)), 1.0, np.random.default_rng(4), n=150).observations.uv)
    time.sleep(2.5)  # the watch now judges against the repaired calibration
    assert not flagged(), flagged()
    again = refine.call(Trigger.Request(), timeout_sec=60)
    assert again.success and again.message.startswith("no camera moved"), again.message
