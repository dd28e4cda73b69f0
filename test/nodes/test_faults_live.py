"""A rig that misbehaves, through the real collector: stamps that jump, a camera that falls silent or sends
images it cannot use, images dropped on the way, a bag replayed after /reset. Nothing collected is lost, each
fault is said (once per cause) and shown in /diagnostics while it lasts, and the rig recovers by itself."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from conftest import Ros, calibrates_as_kept, wait_until

from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, paper_three_camera_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PolygonStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402
from wand_calib_ros.nodes.collector import POINTS_QOS, CollectorNode  # noqa: E402
from wand_calib_ros.nodes.messages import array_to_image, points_message, time_message  # noqa: E402

EPOCH = 1_700_000_000 * 10**9
PERIOD = 33_333_333

#: A stamp per (frame, camera), or None: the camera sends nothing for that frame.
Stamps = Callable[[int, int], int | None]


def _collector(ros: Ros, tmp_path: Path, rig: Any, **parameters: Any) -> CollectorNode:
    save_rig(rig, tmp_path / "cameras.yaml")
    values = {
        "cameras_file": str(tmp_path / "cameras.yaml"),
        "output_dir": str(tmp_path / "out"),
        "require_coverage": False,
        "input": "points",
        "with_calibrator": False,
        "running_estimate": False,
        "min_motion_px": 0.0,
        **parameters,
    }
    node = CollectorNode(context=ros.context, parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
    return ros.add(node)  # type: ignore[return-value]


def _play(ros: Ros, collector: CollectorNode, uv: np.ndarray, stamps: Stamps, pace_s: float = 0.002) -> None:
    """Publish (F, C, 3, 2) views as detector points, camera by camera within a frame, stamped by ``stamps``."""
    names = collector.rig.camera_names
    publishers = {n: ros.helper.create_publisher(PolygonStamped, f"/{n}/wand_points", POINTS_QOS) for n in names}
    assert wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 10)
    before = sum(collector.received.values())
    sent = 0
    for k, frame in enumerate(uv):
        for c, name in enumerate(names):
            stamp = stamps(k, c)
            if stamp is None:
                continue
            points = frame[c] if np.all(np.isfinite(frame[c])) else None
            publishers[name].publish(points_message(points, Header(stamp=time_message(stamp), frame_id=name)))
            sent += 1
        time.sleep(pace_s)
    assert wait_until(lambda: sum(collector.received.values()) - before == sent, 20)
    collector.flush()


def _views(collector: CollectorNode) -> int:
    return int(collector.buffer.observations().complete.sum())


def _latest(diagnostics: list[DiagnosticArray], camera: str) -> Any:
    for array in reversed(diagnostics):
        for entry in array.status:
            if entry.name.endswith(f": {camera}"):
                return entry
    return None


def _value(entry: Any, key: str) -> str:
    return "" if entry is None else next(v.value for v in entry.values if v.key == key)


def _steady(k: int, c: int) -> int:
    return EPOCH + k * PERIOD


FAULTS: dict[str, tuple[Stamps, str]] = {
    # cam1's driver restarted on a clock 60 s behind
    "restarted driver": (lambda k, c: _steady(k, c) - (60 * 10**9 if c == 1 and k >= 100 else 0), "60.0 s back"),
    # cam1's stamps leapt 3 h ahead (the others must not lose their views)
    "stamps 3 h ahead": (lambda k, c: _steady(k, c) + (3 * 3600 * 10**9 if c == 1 and k >= 100 else 0), "3.0 h ahead"),
    # the host's clock stepped back 30 s under every camera
    "clock step": (lambda k, c: _steady(k, c) - (30 * 10**9 if k >= 100 else 0), "30.0 s back"),
    # cam1's driver does not stamp
    "unstamped": (lambda k, c: 0 if c == 1 else _steady(k, c), "stamped 0"),
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_stamps_that_jump_start_a_segment_and_lose_nothing(
    ros: Ros, tmp_path: Path, fault: str, capfd: pytest.CaptureFixture[str]
) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(7), n=240).observations.uv
    collector = _collector(ros, tmp_path, scenario.rig)
    stamps, said = FAULTS[fault]
    if fault == "unstamped":  # stamped by their arrival: sent at the camera's own pace
        uv = uv[:90]
    _play(ros, collector, uv, stamps, pace_s=PERIOD / 1e9 if fault == "unstamped" else 0.002)
    complete = int(np.all(np.isfinite(uv), axis=(2, 3)).all(axis=1).sum())
    stored = collector.buffer.observations()
    assert int(stored.complete.all(axis=1).sum()) == complete  # every frame all cameras saw, whole
    assert _views(collector) == int(np.all(np.isfinite(uv), axis=(2, 3)).sum())  # and every single view
    assert stored.stamps is not None and np.all(np.diff(stored.stamps[np.isfinite(stored.stamps[:, 0]), 0]) > 0)
    log = capfd.readouterr().err
    assert said in log and log.count("new segment") <= 3  # said once per jump (the clock step: per camera)
    calibrates_as_kept(ros, tmp_path, collector)


def test_a_restarted_driver_is_calibrated_as_the_kept_frames_are(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(8), n=240).observations.uv
    collector = _collector(ros, tmp_path, scenario.rig)
    _play(ros, collector, uv, FAULTS["restarted driver"][0])
    calibrates_as_kept(ros, tmp_path, collector)
    placements = yaml.safe_load((tmp_path / "out" / "result.yaml").read_text())["metrics"]["placements_used"]
    assert placements == int(np.all(np.isfinite(uv), axis=(2, 3)).all(axis=1).sum())  # every one after the jump too


def test_a_silent_camera_is_said_while_silent_and_resumes(
    ros: Ros, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(9), n=300).observations.uv
    collector = _collector(ros, tmp_path, scenario.rig)
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    silent = range(100, 200)  # cam1 sends nothing for 100 frames, 3.3 s of stamps and of time

    def stamps(k: int, c: int) -> int | None:
        return None if c == 1 and k in silent else _steady(k, c)

    _play(ros, collector, uv[:100], stamps, pace_s=0.002)
    _play(ros, collector, uv[100:200], lambda k, c: stamps(k + 100, c), pace_s=PERIOD / 1e9)
    assert wait_until(lambda: "no image for" in getattr(_latest(diagnostics, "cam1"), "message", ""), 5)
    during = _latest(diagnostics, "cam1")
    assert during.level == b"\x01" or during.level == 1  # WARN
    rig = next(e for e in reversed(diagnostics[-1].status) if e.name.endswith(": rig"))
    assert "cam1: no image for" in rig.message
    _play(ros, collector, uv[200:], lambda k, c: stamps(k + 200, c))
    assert wait_until(lambda: "no image for" not in _latest(diagnostics, "cam1").message, 5)
    log = capfd.readouterr().err
    assert log.count("cam1: no image for") == 1 and "cam1: images again after 3." in log
    seen = np.all(np.isfinite(uv), axis=(2, 3))
    seen[100:200, 1] = False
    assert _views(collector) == int(seen.sum())  # the others' views while it was silent, its own after
    calibrates_as_kept(ros, tmp_path, collector)


def test_dropped_images_are_counted_and_said(ros: Ros, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(10), n=300).observations.uv
    collector = _collector(ros, tmp_path, scenario.rig)
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    lost = set(range(60, 84)) | set(range(200, 224))  # 48 images of cam2 at 120 Hz never arrive

    def stamps(k: int, c: int) -> int | None:
        return None if c == 2 and k in lost else EPOCH + k * 8_333_333

    _play(ros, collector, uv, stamps)
    assert wait_until(lambda: _value(_latest(diagnostics, "cam2"), "dropped") == "48", 5)
    assert _value(_latest(diagnostics, "cam0"), "dropped") == "0"
    assert "cam2: 48 images missing in its stamps" in capfd.readouterr().err


def test_the_same_bag_replayed_after_reset_is_stored_again(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(11), n=200).observations.uv
    collector = _collector(ros, tmp_path, scenario.rig)
    _play(ros, collector, uv, _steady)
    first = _views(collector)
    client = ros.helper.create_client(Trigger, "reset")
    assert client.wait_for_service(timeout_sec=5)
    assert client.call(Trigger.Request(), timeout_sec=10).success
    assert _views(collector) == 0
    _play(ros, collector, uv, _steady)  # its stamps start over
    assert _views(collector) == first == int(np.all(np.isfinite(uv), axis=(2, 3)).sum())
    calibrates_as_kept(ros, tmp_path, collector)


def test_images_it_cannot_use_are_said_and_the_good_ones_between_are_kept(
    ros: Ros, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 90, 30.0, RenderOptions(), np.random.default_rng(12))
    collector = _collector(ros, tmp_path, scenario.rig, input="images", image_qos="reliable")
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    publishers = {n: ros.helper.create_publisher(Image, f"/{n}/image_raw", 50) for n in scenario.rig.camera_names}
    assert wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 10)

    def spoiled(k: int, pixels: np.ndarray, stamp: int, camera: str) -> Image:
        if k % 3 == 1 and 30 <= k < 60:  # every third image of cam1 in the middle third is unusable
            kind = (k // 3) % 3
            if kind == 0:
                return array_to_image(np.ascontiguousarray(pixels[::2, ::2]), stamp, camera)  # 320x240
            if kind == 1:
                message = array_to_image(pixels, stamp, camera)
                message.encoding, message.step = "32FC1", pixels.shape[1] * 4
                message.data = pixels.astype(np.float32).tobytes()
                return message
            message = array_to_image(pixels, stamp, camera)
            message.data = bytes(message.data)[: len(message.data) // 2]  # truncated
            return message
        return array_to_image(pixels, stamp, camera)

    count = dict.fromkeys(scenario.rig.camera_names, 0)
    for camera, stamp, pixels in recording.frames:
        k = count[camera]
        count[camera] += 1
        message = spoiled(k, pixels, stamp, camera) if camera == "cam1" else array_to_image(pixels, stamp, camera)
        publishers[camera].publish(message)
        time.sleep(0.005)
    assert wait_until(lambda: sum(collector.received.values()) == len(recording.frames), 20)
    assert wait_until(lambda: "320x240" in getattr(_latest(diagnostics, "cam1"), "message", ""), 5)
    entry = _latest(diagnostics, "cam1")
    assert "32FC1" in entry.message and "truncated" in entry.message
    stats = collector.streams["cam1"].stats.rejected
    assert (stats["wrong_size"], stats["encoding"], stats["bad_image"]) == (3, 4, 3)  # images 31, 34, ... 58
    log = capfd.readouterr().err
    assert log.count("cam1: its images are 320x240, the rig file says 640x480") == 1
    collector.flush()
    stored = collector.buffer.observations()
    assert stored.stamps is not None
    kept = {round(s, 6) for s in stored.stamps[np.isfinite(stored.stamps[:, 1]), 1]}
    good = [stamp for k, (camera, stamp, _) in enumerate(recording.frames) if camera == "cam1"]
    usable = [s for k, s in enumerate(good) if not (k % 3 == 1 and 30 <= k < 60)]
    assert len([s for s in usable if round(s / 1e9, 6) in kept]) >= len(usable) - 6  # the first: still, unseen


def test_a_calibration_whose_take_was_reset_meanwhile_is_set_aside(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(13), n=200).observations.uv
    collector = _collector(ros, tmp_path, scenario.rig)
    _play(ros, collector, uv, _steady)
    calibrated: list[Any] = []
    reset = ros.helper.create_client(Trigger, "reset")
    asked: list[int] = []

    def take_then_reset() -> int:  # a /reset arrives while the solve runs (before its end is checked)
        if asked:
            assert reset.call(Trigger.Request(), timeout_sec=10).success
        asked.append(collector.take)
        return asked[-1]

    overrides = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
        Parameter("require_coverage", value=False),
        Parameter("time_offsets", value="fixed"),
    ]
    ros.add(
        CalibratorNode(
            context=ros.context,
            parameter_overrides=overrides,
            before_calibrate=collector.flush,
            after_calibrate=calibrated.append,
            take=take_then_reset,
        )
    )
    client = ros.helper.create_client(Trigger, "calibrate")
    assert client.wait_for_service(timeout_sec=5) and reset.wait_for_service(timeout_sec=5)
    response = client.call(Trigger.Request(), timeout_sec=120)
    assert response is not None and not response.success
    assert "/reset cleared the take this calibration was solving" in response.message
    out = tmp_path / "out"
    assert not (out / "result.yaml").exists() and not (out / "camera_info").exists() and calibrated == []
    aside = [p for p in out.iterdir() if p.name.startswith("reset.") and p.is_dir()]
    assert len(aside) == 1 and (aside[0] / "result.yaml").exists() and (aside[0] / "camera_info" / "cam0.yaml").exists()


def test_two_rigs_in_their_own_namespaces_store_their_own_views(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    collectors = {}
    for rig in ("rigA", "rigB"):
        values = {
            "cameras_file": str(tmp_path / "cameras.yaml"),
            "output_dir": str(tmp_path / rig),
            "input": "points",
            "with_calibrator": False,
            "running_estimate": False,
            "min_motion_px": 0.0,
        }
        node = CollectorNode(
            context=ros.context,
            namespace=f"/{rig}",
            parameter_overrides=[Parameter(k, value=v) for k, v in values.items()],
        )
        collectors[rig] = ros.add(node)
    uv = {
        rig: simulate(scenario, 0.5, np.random.default_rng(seed), n=60).observations.uv
        for seed, rig in enumerate(collectors)
    }
    publishers = {
        (rig, n): ros.helper.create_publisher(PolygonStamped, f"/{rig}/{n}/wand_points", POINTS_QOS)
        for rig in collectors
        for n in scenario.rig.camera_names
    }
    assert wait_until(lambda: all(p.get_subscription_count() == 1 for p in publishers.values()), 10)
    for k in range(60):
        for rig in collectors:
            for c, name in enumerate(scenario.rig.camera_names):
                points = uv[rig][k, c] if np.all(np.isfinite(uv[rig][k, c])) else None
                header = Header(stamp=time_message(_steady(k, c)), frame_id=name)
                publishers[(rig, name)].publish(points_message(points, header))
        time.sleep(0.002)
    for rig, collector in collectors.items():
        assert wait_until(lambda c=collector: sum(c.received.values()) == 60 * 2, 10)
        collector.flush()
        stored = collector.buffer.observations()
        seen = np.all(np.isfinite(uv[rig]), axis=(2, 3))
        ours = uv[rig][seen.all(axis=1)]
        assert np.allclose(stored.uv[stored.complete.all(axis=1)], ours, atol=1e-3)  # its own only (float32 points)
