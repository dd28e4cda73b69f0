"""/set_floor live: the wand laid still on the floor twice, then /calibrate publishes the cameras in the world
(extrinsics, /tf_static and the RViz markers)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import LATCHED, Ros, points_rig, wait_until

from wand_calib_ros.collection.floor import FLOOR_FILE, read_floor_frames
from wand_calib_ros.sim.floor import floor_tool
from wand_calib_ros.sim.scenarios import image_placements, paper_three_camera_scenario, simulate

rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import TransformStamped  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

try:  # tf2_msgs comes with ROS, not with the PyPI wheels
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

HOLD_S = 1.0
L_FRAME = np.array([[0.0, 0.0, 0.0], [500.0, 0.0, 0.0], [0.0, 300.0, 0.0]])


def test_set_floor_twice_then_calibrate_publishes_the_cameras_in_the_world(ros: Ros, tmp_path: Path) -> None:
    scenario = paper_three_camera_scenario()
    transforms = ros.collect(TransformStamped, "wand_calib/cam1/extrinsics", LATCHED)
    tf_static = ros.collect(TFMessage, "/tf_static", LATCHED) if TFMessage is not None else None
    markers = ros.collect(MarkerArray, "wand_calib/markers", LATCHED)
    play = points_rig(ros, scenario, tmp_path, {"floor_hold_s": HOLD_S}).play

    floor_service = ros.helper.create_client(Trigger, "set_floor")
    assert floor_service.wait_for_service(timeout_sec=5)
    play(simulate(scenario, 0.5, np.random.default_rng(0)).observations.uv)  # the wave
    rng = np.random.default_rng(1)
    centre = scenario.volume.mean(axis=0)
    normal = -np.mean([c.pose.rotation[2] for c in scenario.cameras], axis=0)
    normal /= np.linalg.norm(normal)
    x = np.cross(normal, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    for lay, direction in enumerate((x, np.cross(normal, x))):
        answer = floor_service.call(Trigger.Request(), timeout_sec=5)
        assert answer.success and f"floor lay {lay + 1}" in answer.message
        a = np.tile(centre - 0.5 * scenario.wand.L * direction, (15, 1))
        still = image_placements(scenario, a, np.tile(direction, (15, 1)), np.tile(normal, (15, 1)), 0.5, rng)
        play(still.observations.uv)
        time.sleep(HOLD_S + 0.2)  # the window closes: later frames are waved frames again
    floor = read_floor_frames(tmp_path / "out" / FLOOR_FILE)
    assert len(floor) == 30  # every still frame kept (the still filter would keep one per lay)

    client = ros.helper.create_client(Trigger, "calibrate")
    answer = client.call(Trigger.Request(), timeout_sec=120)
    assert answer.success, answer.message
    world = yaml.safe_load((tmp_path / "out" / "result.yaml").read_text())["world"]
    assert world["frame"] == "floor" and world["floor"]["placements"] == 30
    assert wait_until(lambda: bool(transforms), 5)
    assert transforms[-1].header.frame_id == "world" and transforms[-1].child_frame_id == "cam1"
    assert transforms[-1].transform.translation.z > 0.1  # cam1 above the floor (metres)
    if tf_static is not None:  # tf2_msgs is in every ROS install, not in the PyPI wheels
        assert wait_until(lambda: bool(tf_static), 5)
        published = {t.child_frame_id: t for t in tf_static[-1].transforms}
        assert sorted(published) == ["cam0", "cam1", "cam2"]
        assert {t.header.frame_id for t in published.values()} == {"world"}
        assert published["cam1"].transform == transforms[-1].transform
    assert wait_until(lambda: bool(markers), 5)
    _check_markers(markers[-1], world["cameras"])


def test_an_l_frame_on_the_floor_then_calibrate_puts_the_cameras_in_its_world(ros: Ros, tmp_path: Path) -> None:
    # The tool's markers arrive in any order per view (as a detector finds three blobs that are no wand).
    base = paper_three_camera_scenario()
    normal = -np.mean([c.pose.rotation[2] for c in base.cameras], axis=0)
    normal /= np.linalg.norm(normal)
    x = np.cross(normal, [0.0, 1.0, 0.0])
    scenario = replace(base, floor=np.stack([base.volume.mean(axis=0), normal, x / np.linalg.norm(x)]))
    rig = replace(scenario.rig, floor_tool=tuple(tuple(p) for p in L_FRAME.tolist()))
    play = points_rig(ros, scenario, tmp_path, {"floor_hold_s": HOLD_S}, rig=rig).play
    floor_service = ros.helper.create_client(Trigger, "set_floor")
    assert floor_service.wait_for_service(timeout_sec=5)
    play(simulate(scenario, 0.5, np.random.default_rng(0)).observations.uv)
    answer = floor_service.call(Trigger.Request(), timeout_sec=5)
    assert answer.success
    rng = np.random.default_rng(1)
    truth = floor_tool(scenario, L_FRAME, 0.5, rng)
    uv = truth.observations.uv.copy()
    for view in uv.reshape(-1, *uv.shape[2:]):
        view[:] = view[rng.permutation(len(view))]
    play(uv)
    time.sleep(HOLD_S + 0.2)
    assert len(read_floor_frames(tmp_path / "out" / FLOOR_FILE)) == 15
    answer = ros.helper.create_client(Trigger, "calibrate").call(Trigger.Request(), timeout_sec=120)
    assert answer.success, answer.message
    world = yaml.safe_load((tmp_path / "out" / "result.yaml").read_text())["world"]
    rotation, translation = np.array(world["rotation"]), np.array(world["translation"])
    true = truth.world_from_reference
    # Within 5 sigma of the offline statistics (paper3 at 0.5 px: about 1 mm and 0.1 deg).
    assert np.linalg.norm(-rotation.T @ translation - true.inverse().translation) < 5.0
    assert np.degrees(np.arccos(np.clip(rotation[2] @ true.rotation[2], -1.0, 1.0))) < 0.5


def _check_markers(array: MarkerArray, cameras: dict) -> None:  # type: ignore[type-arg]
    """Every frustum's pose is its camera's in result.yaml's world (X_cam = R X_world + T, mm)."""
    by = {(m.ns, m.id): m for m in array.markers if m.action == Marker.ADD}
    for c, name in enumerate(sorted(cameras)):  # the rig's order: cam0, cam1, cam2
        rotation, translation = np.array(cameras[name]["rotation"]), np.array(cameras[name]["translation"])
        frustum = by[("frustums", c)]
        assert frustum.header.frame_id == "world" and by[("names", c)].text == name
        p, q = frustum.pose.position, frustum.pose.orientation
        assert np.allclose([p.x, p.y, p.z], -rotation.T @ translation / 1000.0, atol=1e-9)
        turned = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        assert np.allclose(turned, rotation.T, atol=1e-9)
        apex = frustum.points[0]
        assert (apex.x, apex.y, apex.z) == (0.0, 0.0, 0.0) and len(frustum.points) == 16
        ray = np.array([frustum.points[1].x, frustum.points[1].y, frustum.points[1].z])
        assert ray[2] > 0.0  # toward the top-left corner, in front of the camera
    wand = np.array([[v.x, v.y, v.z] for v in by[("wand", 0)].points])
    volume = np.array([[v.x, v.y, v.z] for v in by[("volume", 0)].points])
    assert len(wand) >= 100 and len(volume) >= 12 and len(volume) % 3 == 0
    assert np.all(wand >= volume.min(axis=0) - 1e-9) and np.all(wand <= volume.max(axis=0) + 1e-9)


def test_tf_static_holds_every_camera_but_none_as_its_own_parent() -> None:
    from rigs import scenario_data

    from wand_calib_ros.core.pipeline import calibrate
    from wand_calib_ros.nodes.messages import extrinsics_message, static_transforms

    scenario, data, _ = scenario_data("paper3", 0, noise=0.5)
    result = calibrate(scenario.rig, data.observations)
    transforms = static_transforms(result, Time(), frame_ids={"cam0": "left"})
    names = {"cam0": "left", "cam1": "cam1", "cam2": "cam2"}
    reference = names[result.reference_camera]
    assert sorted(t.child_frame_id for t in transforms) == sorted(set(names.values()) - {reference})
    assert {t.header.frame_id for t in transforms} == {reference}
    for t in transforms:
        camera = next(c for c, f in names.items() if f == t.child_frame_id)
        assert t == extrinsics_message(result, camera, Time(), frame_ids={"cam0": "left"})


def test_published_frames_follow_the_rig_files_frame_ids() -> None:
    from rigs import scenario_data

    from wand_calib_ros.core.pipeline import calibrate
    from wand_calib_ros.nodes.messages import camera_info_message, extrinsics_message

    scenario, data, _ = scenario_data("paper", 0, noise=0.5)
    result = calibrate(scenario.rig, data.observations)
    frames = {"cam0": "left_optical", "cam1": "right_optical"}
    other = "cam1" if result.reference_camera == "cam0" else "cam0"
    transform = extrinsics_message(result, other, Time(), frame_ids=frames)
    assert (transform.header.frame_id, transform.child_frame_id) == (frames[result.reference_camera], frames[other])
    assert camera_info_message(result, "cam1", Time(), frames["cam1"]).header.frame_id == "right_optical"
