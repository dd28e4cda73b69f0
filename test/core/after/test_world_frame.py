"""The world frame from the wand laid on a known floor: normal and origin against the truth."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from rigs import in_truth_frame, rms, scenario_data

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.after.world_frame import fit_floor
from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.scenarios import Scenario, image_placements

STILL_FRAMES = 15  # each lay of the wand held still for half a second at 30 fps


def _floor(scenario: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A floor through the waved volume's centre, facing the cameras: (point, normal, x, y) in camera 0's frame."""
    axes = np.array([camera.pose.rotation[2] for camera in scenario.cameras])  # optical axes, reference frame
    normal = -axes.mean(axis=0)
    normal /= np.linalg.norm(normal)
    x = np.cross(normal, [0.0, 1.0, 0.0]) if abs(normal[1]) < 0.9 else np.cross(normal, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    return scenario.volume.mean(axis=0), normal, x, np.cross(normal, x)


def _laid(scenario: Scenario, noise: float, rng: np.random.Generator, directions: int = 2):  # type: ignore[no-untyped-def]
    """The wand laid along x, then along y (beside it), each held still: its observations and the truth."""
    point, normal, x, y = _floor(scenario)
    lays = [(point - 0.5 * scenario.wand.L * x, x), (point + 150.0 * x - 0.5 * scenario.wand.L * y, y)][:directions]
    a = np.repeat([lay[0] for lay in lays], STILL_FRAMES, axis=0)
    direction = np.repeat([lay[1] for lay in lays], STILL_FRAMES, axis=0)
    data = image_placements(scenario, a, direction, np.tile(normal, (a.shape[0], 1)), noise, rng)
    return data.observations.uv, lays[0][0], normal, x


def _floor_errors(name: str, calibrated: bool) -> dict[str, list[float]]:
    """Per seed: normal and x errors (deg), origin error (mm) and the normal's z-score."""
    errors: dict[str, list[float]] = {"normal": [], "x": [], "origin": [], "z": []}
    for seed in range(4):
        scenario, data, _ = scenario_data(name, seed, noise=1.0)
        if calibrated:
            models, poses = in_truth_frame(calibrate(scenario.rig, data.observations), scenario)
        else:
            models, poses = [c.model for c in scenario.cameras], [c.pose for c in scenario.cameras]
        uv, origin, normal, x = _laid(scenario, 1.0, np.random.default_rng(100 + seed))
        points = triangulate_placements(tuple(models), tuple(poses), uv)
        world = fit_floor(points, np.array([pose.center for pose in poses]))
        rotation, translation = world.world_from_reference.rotation, world.world_from_reference.translation
        errors["normal"].append(float(np.degrees(np.arccos(np.clip(rotation[2] @ normal, -1, 1)))))
        errors["x"].append(float(np.degrees(np.arccos(np.clip(rotation[0] @ x, -1, 1)))))
        errors["origin"].append(float(np.linalg.norm(-rotation.T @ translation - origin)))
        errors["z"].append(errors["normal"][-1] / world.normal_std_deg)
    return errors


@pytest.mark.parametrize("name", ["paper3", "mixed3"])
def test_the_floor_fit_is_within_0_2_deg_and_2_mm_at_1_px(name: str) -> None:
    # With the true cameras: what the floor fit itself adds (30 still frames of two lays, 1 px).
    errors = _floor_errors(name, calibrated=False)
    assert rms(errors["normal"]) < 0.2 and rms(errors["origin"]) < 2.0, errors
    assert rms(errors["x"]) < 0.5 and rms(errors["z"]) < 3.0  # the reported uncertainty is about right


@pytest.mark.parametrize(("name", "normal_deg", "origin_mm"), [("paper3", 0.5, 8.0), ("mixed3", 0.7, 30.0)])
def test_with_calibrated_cameras_the_floor_carries_the_calibration_errors(
    name: str, normal_deg: float, origin_mm: float
) -> None:
    # Measured 0.30 / 0.44 deg and 3.9 / 19.6 mm (RMS over 4 seeds, 300 placements at 1 px): the
    # calibration's own rotation and scale errors, not the floor's, dominate (see the test above).
    errors = _floor_errors(name, calibrated=True)
    assert rms(errors["normal"]) < normal_deg and rms(errors["origin"]) < origin_mm, errors


def test_cameras_in_the_world_sit_above_the_floor() -> None:
    scenario, data, _ = scenario_data("paper3", 0, noise=1.0)
    result = calibrate(scenario.rig, data.observations)
    models, poses = in_truth_frame(result, scenario)
    uv, *_ = _laid(scenario, 1.0, np.random.default_rng(7))
    world = fit_floor(triangulate_placements(tuple(models), tuple(poses), uv), np.array([p.center for p in poses]))
    for pose in poses:
        assert world.camera_in_world(pose).center[2] > 100.0  # z up: every camera above the floor


def test_one_direction_or_too_few_placements_are_refused() -> None:
    scenario, data, _ = scenario_data("paper3", 0, noise=1.0)
    result = calibrate(scenario.rig, data.observations)
    models, poses = in_truth_frame(result, scenario)
    centres = np.array([p.center for p in poses])
    uv, _, _, _ = _laid(scenario, 1.0, np.random.default_rng(8), directions=1)
    points = triangulate_placements(tuple(models), tuple(poses), uv)
    with pytest.raises(DegenerateDataError, match="in one direction only"):
        fit_floor(points, centres)
    with pytest.raises(InsufficientDataError, match="at least 2 placements"):
        fit_floor(points[:1], centres)


def test_floor_frames_of_a_recording_set_the_world_of_the_result_file(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    from wand_calib_ros.cli import main
    from wand_calib_ros.core.model.rig import WandObservations
    from wand_calib_ros.io.observations_csv import write_observations
    from wand_calib_ros.io.rig_yaml import save_rig

    scenario, data, _ = scenario_data("paper3", 1, noise=1.0)
    uv, _, _, _ = _laid(scenario, 1.0, np.random.default_rng(3))
    waved = data.observations
    frames = np.r_[waved.frames, 10_000 + np.arange(uv.shape[0])]
    recording = WandObservations(frames, waved.camera_names, np.concatenate([waved.uv, uv]))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    write_observations(recording, tmp_path / "observations.csv")
    argv = ["--cameras", str(tmp_path / "cameras.yaml"), "--observations", str(tmp_path / "observations.csv")]
    last = 10_000 + uv.shape[0] - 1
    assert main(["-q", "calibrate", *argv, "--output", str(tmp_path / "r.yaml"), "--floor", f"10000-{last}"]) == 0
    assert "world frame from the floor (30 placements)" in capsys.readouterr().out
    world = yaml.safe_load((tmp_path / "r.yaml").read_text())["world"]
    assert world["frame"] == "floor" and world["floor"]["placements"] == 30
    assert all(np.linalg.norm(np.array(c["translation"])) > 100 for c in world["cameras"].values())
    centre_z = [-(np.array(c["rotation"]).T @ np.array(c["translation"]))[2] for c in world["cameras"].values()]
    assert min(centre_z) > 100.0  # every camera above the floor
    (tmp_path / "floor_frames.txt").write_text("".join(f"{f}\n" for f in range(10_000, last + 1)))  # the collector's
    assert (
        main(
            [
                "-q",
                "calibrate",
                *argv,
                "--output",
                str(tmp_path / "f.yaml"),
                "--floor",
                str(tmp_path / "floor_frames.txt"),
            ]
        )
        == 0
    )
    assert yaml.safe_load((tmp_path / "f.yaml").read_text())["world"] == world
    floor = ["--floor", f"10000-{last}", "--floor-origin", "centre"]
    assert main(["-q", "calibrate", *argv, "--output", str(tmp_path / "c.yaml"), *floor]) == 0
    centred = yaml.safe_load((tmp_path / "c.yaml").read_text())["world"]
    shift = np.array(world["translation"]) - np.array(centred["translation"])  # origin moved L/2 along x
    assert np.allclose(shift, [scenario.wand.L / 2, 0.0, 0.0], atol=1.0)
    assert main(["-q", "calibrate", *argv, "--output", str(tmp_path / "n.yaml")]) == 0
    assert yaml.safe_load((tmp_path / "n.yaml").read_text())["world"]["frame"] == "reference_camera"
    assert main(["-q", "calibrate", *argv, "--output", str(tmp_path / "x.yaml"), "--floor", "90000-90010"]) == 2


def test_an_l_frame_in_cameras_yaml_sets_the_world_of_calibrate(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from dataclasses import replace

    from rigs import L_FRAME

    from wand_calib_ros.cli import main
    from wand_calib_ros.core.model.rig import WandObservations
    from wand_calib_ros.io.observations_csv import write_observations
    from wand_calib_ros.io.rig_yaml import save_rig
    from wand_calib_ros.sim.floor import floor_tool, shuffled

    base, data, _ = scenario_data("paper3", 2, noise=1.0)
    point, normal, x, _ = _floor(base)
    scenario = replace(base, floor=np.stack([point, normal, x]))
    rng = np.random.default_rng(4)
    truth = floor_tool(scenario, L_FRAME, 1.0, rng, first_frame=10_000)
    tool = WandObservations(truth.observations.frames, truth.observations.camera_names, shuffled(truth, rng))
    waved = data.observations
    recording = WandObservations(
        np.r_[waved.frames, tool.frames], waved.camera_names, np.concatenate([waved.uv, tool.uv])
    )
    save_rig(replace(scenario.rig, floor_tool=tuple(tuple(p) for p in L_FRAME.tolist())), tmp_path / "cameras.yaml")
    write_observations(recording, tmp_path / "observations.csv")
    argv = ["-q", "calibrate", "--cameras", str(tmp_path / "cameras.yaml"), "--observations"]
    argv += [str(tmp_path / "observations.csv"), "--output", str(tmp_path / "r.yaml"), "--floor", "10000-10014"]
    assert main(argv) == 0
    world = yaml.safe_load((tmp_path / "r.yaml").read_text())["world"]
    rotation, translation = np.array(world["rotation"]), np.array(world["translation"])
    true = truth.world_from_reference
    origin = float(np.linalg.norm(-rotation.T @ translation - true.inverse().translation))
    tilt = float(np.degrees(np.arccos(np.clip(rotation[2] @ true.rotation[2], -1.0, 1.0))))
    floor = world["floor"]
    assert floor["placements"] == 15 and floor["origin_std_mm"] > 0 and floor["normal_std_deg"] > 0
    assert origin < 5 * floor["origin_std_mm"] and tilt < 5 * floor["normal_std_deg"], (origin, tilt, floor)
