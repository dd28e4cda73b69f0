"""A room's images live: JPEG on image_transport's compressed topics, detected by the collector as offline, with
what each camera sees in /diagnostics, beside the buffer and drawn on its detections topic."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import Ros, wait_until

from wand_calib_ros.collection.recording import detect_recording
from wand_calib_ros.io.bags import ImageFrame
from wand_calib_ros.io.images import decode_compressed
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.room_layout import ROOM_SCENES
from wand_calib_ros.sim.room_take import room_take
from wand_calib_ros.sim.scenarios import mixed_pair_scenario

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import CompressedImage, Image  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.nodes.collector import CollectorNode  # noqa: E402
from wand_calib_ros.nodes.messages import time_message  # noqa: E402


def test_a_room_sent_as_jpeg_is_detected_live_as_offline(ros: Ros, tmp_path: Path) -> None:
    scenario = mixed_pair_scenario()
    # The colour JPEG room overexposed: its LEDs saturate, as a camera left on a long exposure
    room = ROOM_SCENES["colour_jpeg"]()
    room = replace(room, sensor=replace(room.sensor, exposure_ms=30.0))
    recording = room_take(scenario, room, 4.0, np.random.default_rng(2))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    collector = ros.add(
        CollectorNode(
            context=ros.context,
            parameter_overrides=[
                Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
                Parameter("output_dir", value=str(tmp_path / "out")),
                Parameter("image_qos", value="reliable"),
                Parameter("with_calibrator", value=False),
                Parameter("running_estimate", value=False),
                Parameter("min_motion_px", value=0.0),
            ],
        )
    )
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    drawn = ros.collect(Image, "wand_calib/cam0/detections", 1)
    names = scenario.rig.camera_names
    publishers = {n: ros.helper.create_publisher(CompressedImage, f"/{n}/image_raw/compressed", 50) for n in names}
    # image_transport: auto listens to the raw topic, and to the compressed one once only that is published
    assert wait_until(lambda: all(collector.images[n].transport == "compressed" for n in names), 10)
    assert wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 10)
    for camera, stamp, payload, fmt in recording.frames:
        message = CompressedImage(format=fmt, data=payload)
        message.header.stamp, message.header.frame_id = time_message(stamp), camera
        publishers[camera].publish(message)
        time.sleep(0.004)
    assert wait_until(lambda: sum(collector.session.received.values()) == len(recording.frames), 20)
    collector.flush()

    # The stored views are the offline detector's (the same stream, decoded alike).
    frames = []
    for camera, stamp, payload, fmt in recording.frames:
        assert isinstance(payload, bytes)
        image, encoding = decode_compressed(payload, fmt)
        frames.append(ImageFrame(camera, stamp, image, encoding))
    offline = detect_recording(frames, scenario.rig).observations
    stored = collector.session.buffer.observations()
    assert stored.complete.shape == offline.complete.shape
    assert np.array_equal(stored.complete, offline.complete)  # in the same frames: none lost on the way
    assert offline.stamps is not None and stored.stamps is not None
    assert offline.saturated is not None and stored.saturated is not None
    for c in range(len(names)):
        views = {round(s, 6): uv for s, uv in zip(offline.stamps[:, c], offline.uv[:, c], strict=True)}
        flags = {round(s, 6): f for s, f in zip(offline.stamps[:, c], offline.saturated[:, c], strict=True)}
        mine = np.isfinite(stored.stamps[:, c]) & stored.complete[:, c]
        for stamp, uv, flag in zip(stored.stamps[mine, c], stored.uv[mine, c], stored.saturated[mine, c], strict=True):
            assert np.abs(views[round(stamp, 6)] - uv).max() < 1e-3  # float32 on the way: same pixels
            assert np.array_equal(flags[round(stamp, 6)], flag)  # and the same saturated spots
    assert stored.saturated[stored.complete].mean() > 0.5  # 30 ms: most LEDs saturate, and the buffer says so

    # What each camera sees: in /diagnostics, beside the buffer, drawn on its detections topic.
    assert wait_until(lambda: bool(drawn) and bool(diagnostics), 5)
    assert drawn[-1].encoding == "bgr8" and (drawn[-1].width, drawn[-1].height) == scenario.cameras[0].spec.image_size
    assert wait_until(lambda: any("static_lights" in {kv.key for kv in s.values} for s in diagnostics[-1].status), 5)
    cam0 = next(s for s in diagnostics[-1].status if s.name.endswith(": cam0"))
    values = {kv.key: kv.value for kv in cam0.values}
    assert int(values["static_lights"]) >= 1 and float(values["saturated"]) > 0.5  # 30 ms: most LEDs saturate
    assert "shorten the exposure" in cam0.message
    summary = tmp_path / "out" / "observations.detection.yaml"
    assert wait_until(summary.exists, 12)
    assert yaml.safe_load(summary.read_text())["cameras"]["cam0"]["images"] > 0

    client = ros.helper.create_client(Trigger, "take_mask")
    assert client.wait_for_service(timeout_sec=5)
    response = client.call(Trigger.Request(), timeout_sec=10)
    assert response.success and "keep the wand out of sight" in response.message
    assert all(stream.taking_mask for stream in collector.session.streams.values())
