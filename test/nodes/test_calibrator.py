"""The calibrator alone on a persisted buffer, and committing results to camera drivers."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import LATCHED, Ros, wait_until

from wand_calib_ros.collection.report_drawer import ReportDrawer, ReportRequest, draw_report
from wand_calib_ros.io.observations_csv import write_observations
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import CameraInfo  # noqa: E402
from sensor_msgs.srv import SetCameraInfo  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402


def test_calibrator_alone_commits_to_the_drivers(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(3))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    (tmp_path / "out").mkdir()
    write_observations(data.observations, tmp_path / "out" / "observations.csv")
    ros.add(
        CalibratorNode(
            context=ros.context,
            parameter_overrides=[
                Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
                Parameter("output_dir", value=str(tmp_path / "out")),
                Parameter("commit_to_drivers", value=True),
                Parameter("driver_timeout_s", value=1.0),
                Parameter("write_report", value=False),
                Parameter("min_theta_fraction", value=0.5),
            ],
        )
    )
    committed: dict[str, CameraInfo] = {}

    def driver(name: str):  # a camera driver's camera_info_manager service
        def handle(request: SetCameraInfo.Request, response: SetCameraInfo.Response) -> SetCameraInfo.Response:
            committed[name] = request.camera_info
            response.success, response.status_message = True, "stored"
            return response

        return handle

    ros.helper.create_service(SetCameraInfo, "/cam0/set_camera_info", driver("cam0"))
    published = ros.collect(CameraInfo, "wand_calib/cam0/camera_info", LATCHED)
    client = ros.helper.create_client(Trigger, "calibrate")
    assert client.wait_for_service(timeout_sec=5)
    partial = client.call(Trigger.Request(), timeout_sec=120)
    assert not partial.success
    assert "committing to the drivers failed: cam1: no service /cam1/set_camera_info" in partial.message
    assert (tmp_path / "out" / "result.yaml").exists()  # the calibration itself is kept

    ros.helper.create_service(SetCameraInfo, "/cam1/set_camera_info", driver("cam1"))
    full = client.call(Trigger.Request(), timeout_sec=120)
    assert full.success and "committed to cam0, cam1" in full.message, full.message
    assert wait_until(lambda: bool(published), 5)
    assert committed["cam0"].distortion_model == "equidistant"
    assert list(committed["cam0"].k) == list(published[-1].k) and list(committed["cam0"].d) == list(published[-1].d)
    truth = scenario.cameras[1].model
    assert abs(committed["cam1"].k[0] - truth.focal_px[0]) < 1.0


def _calibrator_on_a_take(ros: Ros, tmp_path: Path, seed: int) -> tuple[CalibratorNode, Path]:
    """A calibrator on its defaults (write_report as a user has it: on) whose output folder holds a take of the
    paper's rig (seed ``seed``): the node, spinning, and that folder."""
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(seed))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    out = tmp_path / "out"
    out.mkdir()
    write_observations(data.observations, out / "observations.csv")
    node = CalibratorNode(
        context=ros.context,
        parameter_overrides=[
            Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
            Parameter("output_dir", value=str(out)),
            Parameter("min_theta_fraction", value=0.5),
        ],
    )
    ros.add(node)
    return node, out


def test_calibrate_answers_before_its_report_and_again_while_it_is_drawn(ros: Ros, tmp_path: Path) -> None:
    node, out = _calibrator_on_a_take(ros, tmp_path, 5)
    assert node.reports is not None
    release, sources = threading.Event(), []

    def held(request: ReportRequest) -> None:  # the real report, once the test lets it through
        assert release.wait(60)
        sources.append(request.source)
        draw_report(request)

    node.reports = ReportDrawer(node._said_report, draw=held)
    client = ros.helper.create_client(Trigger, "calibrate")
    assert client.wait_for_service(timeout_sec=5)
    page = out / "report" / "index.html"
    first = client.call(Trigger.Request(), timeout_sec=120)
    assert first.success and first.message.endswith(f"; report to follow in {page}"), first.message
    assert not page.exists()  # answered before its report
    second = client.call(Trigger.Request(), timeout_sec=120)  # while the first's report is drawn
    assert second.success and second.message.endswith(f"; report to follow in {page}"), second.message
    release.set()
    assert node.reports.wait(60) and page.exists()
    assert sources == ["/calibrate", "/calibrate"]  # each calibration's report, the newest last
    assert "cam1" in page.read_text()


def test_a_stop_waits_a_few_seconds_for_the_report_being_drawn(ros: Ros, tmp_path: Path) -> None:
    node, out = _calibrator_on_a_take(ros, tmp_path, 6)
    started = threading.Event()

    def slow(request: ReportRequest) -> None:  # a report that takes a second longer than usual
        started.set()
        time.sleep(1.0)
        draw_report(request)

    node.reports = ReportDrawer(node._said_report, draw=slow)
    assert node.calibrate_now("auto_calibrate")
    assert started.wait(120)
    node.close()  # Ctrl-C just after the calibration
    assert (out / "report" / "index.html").exists() and not node.working
