"""Live: a rendered take replayed through the collector in real time shows a running estimate within seconds
(preliminary topics only) and, with auto_calibrate, ends in the final calibration without a service call."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from conftest import LATCHED, Ros, wait_until

from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.result_yaml import read_result
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_three_camera_scenario

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from wand_calib_ros.core.pipeline import calibrate  # noqa: E402
from wand_calib_ros.nodes.calibrator import CalibratorNode  # noqa: E402
from wand_calib_ros.nodes.collector import CollectorNode  # noqa: E402
from wand_calib_ros.nodes.messages import array_to_image  # noqa: E402

FPS = 30.0


def test_a_running_estimate_appears_while_waving_and_auto_calibrate_ends_the_session(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_three_camera_scenario()
    names = scenario.rig.camera_names
    recording = render_recording(scenario, 450, FPS, RenderOptions(), np.random.default_rng(7))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    common = [
        Parameter("cameras_file", value=str(tmp_path / "cameras.yaml")),
        Parameter("output_dir", value=str(tmp_path / "out")),
    ]
    settings = {"image_qos": "reliable", "estimate_period_s": 2.0, "auto_calibrate": True}
    collector = ros.add(
        CollectorNode(
            context=ros.context, parameter_overrides=[*common, *(Parameter(k, value=v) for k, v in settings.items())]
        )
    )
    calibrator = ros.add(
        CalibratorNode(
            context=ros.context,
            parameter_overrides=[*common, Parameter("write_report", value=False)],
            before_calibrate=collector.flush,
            after_calibrate=collector.session.after_calibrate,
        )
    )
    collector.session.calibrate_now = calibrator.calibrate_now  # as build() wires them in one process
    preliminary = ros.collect(CameraInfo, "wand_calib/preliminary/cam1/camera_info", LATCHED)
    preliminary_markers = ros.collect(MarkerArray, "wand_calib/preliminary/markers", LATCHED)
    final = ros.collect(CameraInfo, "wand_calib/cam1/camera_info", LATCHED)
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics")
    publishers = {n: ros.helper.create_publisher(Image, f"/{n}/image_raw", 50) for n in names}
    assert wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 10)

    started = time.monotonic()
    first_estimate = None
    complete_sent = 0  # frames whose three images were sent
    connected = None  # when the rig could first be calibrated: 30 frames with the wand
    for i, (camera, stamp, pixels) in enumerate(recording.frames):  # in real time, 30 frames per second
        publishers[camera].publish(array_to_image(pixels, stamp, camera))
        if (i + 1) % len(names) == 0:
            complete_sent += 1
            if connected is None and complete_sent == 30:
                connected = time.monotonic()
            if first_estimate is None and preliminary:
                first_estimate = time.monotonic()
            time.sleep(max(0.0, started + complete_sent / FPS - time.monotonic()))
    assert wait_until(lambda: sum(collector.session.received.values()) == len(recording.frames), 20)  # none dropped
    assert wait_until(lambda: bool(final), 60), [s.message for s in diagnostics[-1].status]
    if first_estimate is None:
        first_estimate = time.monotonic()
    assert connected is not None and first_estimate - connected < 10.0, first_estimate - connected
    took = time.monotonic() - started
    print(f"first estimate {first_estimate - connected:.1f} s after 30 frames; final after {took:.1f} s")
    labels = [m.text for m in preliminary_markers[-1].markers if m.ns == "names"] if preliminary_markers else []
    assert labels == [f"{n} (preliminary)" for n in names]
    assert len(final) == 1  # the final topic carries the final calibration only

    seen = [{kv.key: kv.value for kv in s.values} for d in diagnostics for s in d.status if s.hardware_id == "cam1"]
    estimated = [v for v in seen if "estimate_focal_std_percent" in v]
    assert estimated and {"estimate_rms_px", "estimate_principal_std_px", "estimate_improving"} <= set(estimated[-1])
    assert wait_until(lambda: _rig_values(diagnostics[-1]).get("auto_calibrate") == "calibrated", 5)

    # The same result as /calibrate on the same buffer: the frames the auto-calibration read.
    stored = read_observations(tmp_path / "out" / "observations.csv", names, image_sizes=scenario.rig.image_sizes)
    used = stored.frames <= calibrator._calibrated_through
    same = WandObservations(
        stored.frames[used], names, stored.uv[used], None if stored.stamps is None else stored.stamps[used]
    )
    again = calibrate(scenario.rig, same, calibrator.options)
    _, written = read_result(tmp_path / "out" / "result.yaml")
    for name in names:
        assert np.allclose(
            written[name].model.intrinsic_vector(), again.camera(name).model.intrinsic_vector(), atol=1e-9
        )
        assert np.allclose(written[name].pose.translation, again.camera(name).pose.translation, atol=1e-9)
    truth = scenario.cameras[1].model
    assert abs(final[-1].k[0] - truth.focal_px[0]) < 1.0 and abs(final[-1].k[2] - truth.principal_point[0]) < 1.0


def _rig_values(array: DiagnosticArray) -> dict[str, str]:
    return {kv.key: kv.value for s in array.status if s.hardware_id == "rig" for kv in s.values}
