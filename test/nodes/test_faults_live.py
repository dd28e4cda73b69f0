"""A rig through the real nodes: a /reset while a calibration runs sets that calibration aside, and two rigs in
their own namespaces store their own views. The streams' faults (stamps that jump, a silent camera, unusable
and dropped images, a bag replayed after /reset) are the collection session's: ``test/collection/test_session.py``."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Ros, wait_until

from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import PolygonStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402
from wand_calib_ros.nodes.collector import POINTS_QOS, CollectorNode  # noqa: E402
from wand_calib_ros.nodes.messages import points_message, time_message  # noqa: E402

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
    before = sum(collector.session.received.values())
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
    assert wait_until(lambda: sum(collector.session.received.values()) - before == sent, 20)
    collector.flush()


def _steady(k: int, c: int) -> int:
    return EPOCH + k * PERIOD


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
        asked.append(collector.session.take)
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
        assert wait_until(lambda c=collector: sum(c.session.received.values()) == 60 * 2, 10)
        collector.flush()
        stored = collector.session.buffer.observations()
        seen = np.all(np.isfinite(uv[rig]), axis=(2, 3))
        ours = uv[rig][seen.all(axis=1)]
        assert np.allclose(stored.uv[stored.complete.all(axis=1)], ours, atol=1e-3)  # its own only (float32 points)
