"""The collector node in-process: rendered images in, /calibrate, CameraInfo and result.yaml out."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import TransformStamped  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.io.rig_yaml import save_rig  # noqa: E402
from wand_calib_ros.nodes.collector import CollectorNode  # noqa: E402
from wand_calib_ros.sim.render import RenderOptions, render_recording  # noqa: E402
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario  # noqa: E402


def _image(stamp_ns: int, frame_id: str, pixels: np.ndarray) -> Image:
    message = Image()
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    message.header.frame_id = frame_id
    message.height, message.width = pixels.shape
    message.encoding, message.step = "mono8", pixels.shape[1]
    message.data = pixels.tobytes()
    return message


def test_collect_calibrate_and_publish(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 150, 30.0, RenderOptions(), np.random.default_rng(0))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    context = Context()
    rclpy.init(context=context, domain_id=int(np.random.default_rng().integers(60, 200)))
    executor = MultiThreadedExecutor(context=context)
    collector = CollectorNode(
        context=context,
        parameter_overrides=[
            Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
            Parameter("output_dir", value=str(tmp_path / "out")),
            Parameter("min_placements", value=50),
            Parameter("image_qos", value="reliable"),
        ],
    )
    helper = Node("test_helper", context=context)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    publishers = {
        c.spec.name: helper.create_publisher(Image, f"/{c.spec.name}/image_raw", reliable) for c in scenario.cameras
    }
    infos: list[CameraInfo] = []
    transforms: list[TransformStamped] = []
    helper.create_subscription(CameraInfo, "wand_calib/cam1/camera_info", infos.append, latched)
    helper.create_subscription(TransformStamped, "wand_calib/cam1/extrinsics", transforms.append, latched)
    executor.add_node(collector)
    executor.add_node(helper)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        time.sleep(0.5)
        for camera, stamp, pixels in recording.frames:
            publishers[camera].publish(_image(stamp, camera, pixels))
            time.sleep(0.01)
        stats = collector.buffer.stats
        deadline = time.monotonic() + 20
        while stats.accepted + stats.still + stats.full + stats.empty < 140 and time.monotonic() < deadline:
            time.sleep(0.1)
        # every frame arrived (frames whose A/C labels no camera could settle yet count as empty)
        assert stats.accepted + stats.still + stats.full + stats.empty >= 140 and stats.accepted >= 50
        client = helper.create_client(Trigger, "calibrate")
        assert client.wait_for_service(timeout_sec=5)
        response = client.call(Trigger.Request())
        assert response.success, response.message
        assert "result.yaml" in response.message
        deadline = time.monotonic() + 5
        while not (infos and transforms) and time.monotonic() < deadline:
            time.sleep(0.05)
        centre = scenario.cameras[1].pose.center / 1000.0  # camera 1 in camera 0's frame, metres
        moved = transforms[-1].transform.translation
        assert transforms[-1].header.frame_id == "cam0" and transforms[-1].child_frame_id == "cam1"
        assert np.linalg.norm(np.array([moved.x, moved.y, moved.z]) - centre) < 0.01
        assert infos and infos[-1].distortion_model == "equidistant"
        truth = scenario.cameras[1].model
        assert abs(infos[-1].k[0] - truth.focal_px[0]) < 0.5
        assert abs(infos[-1].k[2] - truth.principal_point[0]) < 1.0
        result = yaml.safe_load((tmp_path / "out" / "result.yaml").read_text())
        assert set(result["cameras"]) == {"cam0", "cam1"}
        assert (tmp_path / "out" / "observations.csv").read_text().startswith("frame,camera,point,u,v")
    finally:
        executor.shutdown()
        collector.destroy_node()
        helper.destroy_node()
        rclpy.shutdown(context=context)
        spinner.join(timeout=5)
    assert not spinner.is_alive()
