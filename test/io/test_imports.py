"""Other tools' files (Argus, DLTdv, easyWand, caliscope, pyOpenLPT, aniposelib) as each tool writes them, imported."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tool_files
import yaml

from wand_calib_ros.cli import main
from wand_calib_ros.core.model.rig import WandObservations, WandSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.anipose import read_anipose
from wand_calib_ros.io.imports.xypts import read_xypts
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.scenarios import SCENARIOS, paper_three_camera_scenario, simulate

TWO = WandSpec((0.0, 600.0))


def test_an_argus_point_file_imports_exactly_and_calibrates(tmp_path: Path) -> None:
    scenario = replace(paper_three_camera_scenario(), wand=TWO)
    data = simulate(scenario, 0.5, np.random.default_rng(3))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    heights = [spec.image_size[1] for spec in scenario.rig.cameras]
    tool_files.argus_clicker_points(tmp_path / "wand-xypts.csv", data.observations.uv, heights, ("wandA", "wandB"))
    out = tmp_path / "observations.csv"
    argv = ["--points", str(tmp_path / "wand-xypts.csv"), "--cameras", str(tmp_path / "cameras.yaml")]
    assert main(["-q", "import", "--format", "xypts", *argv, "--out", str(out)]) == 0
    read = read_observations(out, scenario.rig.camera_names, labels=TWO.labels)
    seen = np.any(np.isfinite(data.observations.uv), axis=(1, 2, 3))
    assert np.allclose(read.uv, data.observations.uv[seen], atol=2e-6, equal_nan=True)
    assert main(["-q", "calibrate", "--cameras", str(tmp_path / "cameras.yaml"), "--observations", str(out),
                 "--output", str(tmp_path / "result.yaml")]) == 0  # fmt: skip


def test_a_sparse_two_marker_take_with_empty_cells_keeps_its_frames_and_calibrates_with_board_intrinsics(
    tmp_path: Path,
) -> None:
    # A digitised take as a user has it: the plumb_bob intrinsics of a board calibration, most frames
    # showing the wand to few cameras, views of one marker, labels swapped per view, empty cells where
    # a marker was not seen and rows where no camera saw anything.
    scenario = SCENARIOS["sparse4"]()
    data = simulate(scenario, 0.3, np.random.default_rng(4))
    uv = data.observations.uv.copy()
    swap = np.random.default_rng(5).random(uv.shape[:2]) < 0.5
    uv[swap] = uv[swap][:, ::-1]
    assert (~np.isfinite(uv).any(axis=(1, 2, 3))).sum() > 5  # rows of empty cells
    cameras = tuple(
        replace(spec, intrinsics=c.model) for spec, c in zip(scenario.rig.cameras, scenario.cameras, strict=True)
    )
    save_rig(replace(scenario.rig, cameras=cameras), tmp_path / "cameras.yaml")
    tool_files.dltdv_points(
        tmp_path / "xypts.csv", uv, [spec.image_size[1] for spec in scenario.rig.cameras], version=7
    )
    (tmp_path / "xypts.csv").write_text((tmp_path / "xypts.csv").read_text().replace("NaN", ""))  # empty cells
    out = tmp_path / "observations.csv"
    argv = ["--points", str(tmp_path / "xypts.csv"), "--cameras", str(tmp_path / "cameras.yaml"), "--out", str(out)]
    assert main(["-q", "import", "--format", "xypts", "--origin", "bottom-left", *argv]) == 0
    read = read_observations(out, scenario.rig.camera_names, labels=scenario.wand.labels)
    seen = np.flatnonzero(np.isfinite(uv).any(axis=(1, 2, 3)))
    assert np.array_equal(read.frames, seen)  # frame id = row index, empty rows counted
    assert np.allclose(read.uv, uv[seen], atol=2e-6, equal_nan=True)
    result = tmp_path / "result.yaml"
    assert main(["-q", "calibrate", "--cameras", str(tmp_path / "cameras.yaml"), "--observations", str(out),
                 "--output", str(result)]) == 0  # fmt: skip
    metrics = yaml.safe_load(result.read_text())["metrics"]
    assert metrics["wand_length_std_mm"] / metrics["wand_length_mean_mm"] < 0.01


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("pt1_cam1_x,pt1_cam1_y\n1,2\n", "1 cameras in the file, 3 in the rig description"),
        ("pt0_cam0_x,pt0_cam0_y\n1,2\n", "column 1 is 'pt0_cam0_x': markers and cameras count from 1"),
        ("frame,pt1_cam1_x\n", "column 1 is 'frame', not pt<P>_cam<C>_x (DLTdv, Argus) or <track>_cam_<N>_x"),
        ("Track 1_cam_0_x,Track 1_cam_0_y\n", "column 1 is 'Track 1_cam_0_x': Argus's cameras count from 1"),
        (None, "'high' is not a number (write NaN where a marker was not seen)"),
        (None, "marker 2 in camera 3 has x or y only"),
    ],
)
def test_a_point_file_that_cannot_be_read_names_the_problem(tmp_path: Path, text: str | None, message: str) -> None:
    scenario = replace(paper_three_camera_scenario(), wand=TWO)
    path = tmp_path / "wand-xypts.csv"
    if text is None:
        header = [f"pt{p}_cam{c}_{a}" for p in (1, 2) for c in (1, 2, 3) for a in "XY"]  # DLTdv's capitals
        row = ["10"] * 12
        row[header.index("pt1_cam2_X")] = "high" if "high" in message else "10"
        if "only" in message:
            row[header.index("pt2_cam3_Y")] = "NaN"
        text = ",".join(header) + "\n" + ",".join(row) + "\n"
    path.write_text(text)
    with pytest.raises(FormatError, match=message.replace("(", r"\(").replace(")", r"\)")):
        read_xypts(path, scenario.rig)


def test_anipose_calibration_as_aniposelib_writes_it_is_read_exactly(tmp_path: Path) -> None:
    cameras = pytest.importorskip("aniposelib.cameras")
    fisheye_k = np.array([[356.9, 0.0, 307.1], [0.0, 356.9, 249.6], [0.0, 0.0, 1.0]])
    pinhole_k = np.array([[768.4, 0.0, 322.2], [0.0, 768.4, 251.3], [0.0, 0.0, 1.0]])
    group = cameras.CameraGroup(
        [
            cameras.FisheyeCamera(fisheye_k, np.array([0.27, 0.06, 0.04, -0.04]), (640, 480), name="cam0"),
            cameras.Camera(pinhole_k, np.array([-0.066, 0.01, -0.0018, 0.0022, 0.0]), (658, 492), name="cam1"),
        ]
    )
    group.dump(str(tmp_path / "calibration.toml"))
    fisheye, pinhole = read_anipose(tmp_path / "calibration.toml")
    assert (fisheye.name, fisheye.distortion_model, fisheye.image_size) == ("cam0", "equidistant", (640, 480))
    assert np.array_equal(fisheye.camera_matrix, fisheye_k) and fisheye.distortion == (0.27, 0.06, 0.04, -0.04)
    assert (pinhole.name, pinhole.distortion_model, pinhole.image_size) == ("cam1", "plumb_bob", (658, 492))
    assert np.array_equal(pinhole.camera_matrix, pinhole_k) and pinhole.distortion == (
        -0.066,
        0.01,
        -0.0018,
        0.0022,
        0.0,
    )


def test_anipose_intrinsics_become_the_rigs_given_intrinsics_and_are_held(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    sim = tmp_path / "sim"
    assert main(["-q", "simulate", "mixed", "--seed", "2", "--out", str(sim)]) == 0
    argv = ["-q", "calibrate", "--cameras", str(sim / "cameras.yaml"), "--observations", str(sim / "observations.csv")]
    assert main([*argv, "--output", str(tmp_path / "first.yaml")]) == 0
    # anipose's file as this package exports it (aniposelib reads it: test_export), then back as given intrinsics
    assert (
        main(
            [
                "-q",
                "export",
                "--result",
                str(tmp_path / "first.yaml"),
                "--format",
                "anipose",
                "--out",
                str(tmp_path / "ani"),
            ]
        )
        == 0
    )
    toml = tmp_path / "ani" / "calibration.toml"
    imported = tmp_path / "given.yaml"
    base = ["import", "--format", "anipose", "--points", str(toml), "--cameras", str(sim / "cameras.yaml")]
    assert main([*base, "--out", str(imported)]) == 0
    assert (
        "imported the intrinsics of 2 cameras by name, held fixed: cam0 -> cam0 (equidistant)"
        in capsys.readouterr().out
    )
    given = ["-q", "calibrate", "--cameras", str(imported), "--observations", str(sim / "observations.csv")]
    assert main([*given, "--output", str(tmp_path / "second.yaml")]) == 0
    first = yaml.safe_load((tmp_path / "first.yaml").read_text())["cameras"]
    second = yaml.safe_load((tmp_path / "second.yaml").read_text())["cameras"]
    for name in ("cam0", "cam1"):
        assert second[name]["intrinsics"] == "given"
        assert np.allclose(second[name]["opencv"]["camera_matrix"], first[name]["opencv"]["camera_matrix"], rtol=1e-12)
    # a file for other image sizes, or without a key, is one line naming the camera or the table
    text = toml.read_text()
    (tmp_path / "sized.toml").write_text(text.replace("size = [658, 492]", "size = [1316, 984]", 1))
    assert (
        main([*base[:3], "--points", str(tmp_path / "sized.toml"), *base[5:], "--out", str(tmp_path / "x.yaml")]) == 2
    )
    assert "camera 'cam0' is 1316x984, the rig's 'cam0' 658x492" in capsys.readouterr().err  # (both are 658x492)
    (tmp_path / "broken.toml").write_text(text.replace("matrix = ", "matrix_ = ", 1))
    assert (
        main([*base[:3], "--points", str(tmp_path / "broken.toml"), *base[5:], "--out", str(tmp_path / "x.yaml")]) == 2
    )
    assert "broken.toml: [cam_00] lacks matrix" in capsys.readouterr().err


# --- the other tools' files, written as each tool writes them --------------------------------------------------


def _given_rig(scenario):  # type: ignore[no-untyped-def]
    """The scenario's rig with its true intrinsics given (held)."""
    cameras = tuple(replace(s, intrinsics=c.model) for s, c in zip(scenario.rig.cameras, scenario.cameras, strict=True))
    return replace(scenario.rig, cameras=cameras)


def _projects_as(rig_file: Path, scenario) -> None:  # type: ignore[no-untyped-def]
    """The rig file's given intrinsics (held) project as the truth's, to 1e-9 px."""
    from wand_calib_ros.core.model.camera_model import project
    from wand_calib_ros.io.rig_yaml import load_rig

    points = np.random.default_rng(0).uniform([-2000, -1000, 5000], [2000, 1000, 11000], (50, 3))
    for spec, camera in zip(load_rig(rig_file).cameras, scenario.cameras, strict=True):
        assert spec.intrinsics is not None and spec.intrinsics_fixed
        in_camera = camera.pose.apply(points)
        assert np.allclose(project(spec.intrinsics, in_camera), project(camera.model, in_camera), atol=1e-9)


def _calibrates_as_given_directly(tmp_path: Path, rig_file: Path, observations: Path, direct_rig, direct) -> None:  # type: ignore[no-untyped-def]
    """The imported files calibrate (the command) as the same data given in memory: the import loses nothing."""
    from wand_calib_ros.core.pipeline import calibrate
    from wand_calib_ros.io.result_yaml import read_result

    assert main(["-q", "calibrate", "--cameras", str(rig_file), "--observations", str(observations), "--output",
                 str(tmp_path / "result.yaml")]) == 0  # fmt: skip
    result = calibrate(direct_rig, direct)
    for name, camera in read_result(tmp_path / "result.yaml")[1].items():
        assert np.allclose(camera.pose.rotation, result.camera(name).pose.rotation, atol=1e-6)
        assert np.allclose(camera.pose.translation, result.camera(name).pose.translation, atol=1e-3)


def test_argus_clicker_points_with_its_profiles_import_in_its_pixel_frame_and_calibrate_as_given_directly(
    tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    # Argus's Clicker: a track per marker, columns sorted by name, bottom left, y up, pixel edges at whole
    # numbers; its profiles in the same frame (the principal point 7 px off the middle row, p1 not zero: a
    # profile taken in another frame would show).
    scenario = SCENARIOS["action2"]()
    data = simulate(scenario, 1.0, np.random.default_rng(11))
    heights = [s.image_size[1] for s in scenario.rig.cameras]
    models = [camera.model for camera in scenario.cameras]
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    tool_files.argus_clicker_points(tmp_path / "take-xypts.csv", data.observations.uv, heights, ("Track 1", "Track 2"))
    assert (tmp_path / "take-xypts.csv").read_text().startswith("Track 1_cam_1_x,Track 1_cam_1_y,Track 1_cam_2_x,")
    tool_files.argus_clicker_profile(tmp_path / "take-clicker-profile.txt", models)
    tool_files.argus_sba_profile(tmp_path / "take-sba-profile.txt", models, np.random.default_rng(1))
    argv = ["import", "--format", "xypts", "--points", str(tmp_path / "take-xypts.csv"), "--cameras",
            str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv"), "--intrinsics",
            str(tmp_path / "take-clicker-profile.txt"), "--rig-out", str(tmp_path / "given.yaml")]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "cam1 -> cam0 (plumb_bob), cam2 -> cam1 (plumb_bob)" in out  # in order
    assert "Argus Clicker's points (<track>_cam_<N>_x): origin bottom-left (as the file says), the first pixel's " \
        "centre at (0.5, 0.5)" in out  # fmt: skip
    # exactly the points a hand conversion gives: u = x - 0.5, v = height - 0.5 - y
    written = np.genfromtxt(tmp_path / "take-xypts.csv", delimiter=",", skip_header=1).reshape(-1, 2, 2, 2)
    by_hand = np.stack([written[..., 0] - 0.5, 1519.5 - written[..., 1]], axis=-1).transpose(0, 2, 1, 3)  # track-major
    imported = read_observations(tmp_path / "obs.csv", scenario.rig.camera_names, labels=scenario.wand.labels)
    seen = np.any(np.isfinite(by_hand), axis=(1, 2, 3))
    assert np.allclose(imported.uv, by_hand[seen], atol=1e-6, equal_nan=True)
    assert np.allclose(imported.uv, data.observations.uv[seen], atol=1e-6, equal_nan=True)
    _projects_as(tmp_path / "given.yaml", scenario)
    for name in ("take-clicker-profile.txt", "take-sba-profile.txt"):  # the intrinsics alone: the same rig file
        alone = ["import", "--format", "argus-profile", "--points", str(tmp_path / name), "--cameras",
                 str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "alone.yaml")]  # fmt: skip
        assert main(alone) == 0
        assert (tmp_path / "alone.yaml").read_text() == (tmp_path / "given.yaml").read_text(), name
    _calibrates_as_given_directly(tmp_path, tmp_path / "given.yaml", tmp_path / "obs.csv", _given_rig(scenario),
                                  data.observations)  # fmt: skip


@pytest.mark.parametrize(
    ("writer", "origin"),
    [("dltdv 8", "top-left"), ("dltdv 7", "bottom-left"), ("argus", "top-left"), ("argus flip", "bottom-left")],
)
def test_dltdv_and_argus_paired_points_import_exactly_from_the_origin_given(
    writer: str, origin: str, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    scenario = replace(paper_three_camera_scenario(), wand=TWO)
    uv = simulate(scenario, 0.5, np.random.default_rng(3)).observations.uv
    heights = [spec.image_size[1] for spec in scenario.rig.cameras]
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    if writer.startswith("dltdv"):
        tool_files.dltdv_points(tmp_path / "xypts.csv", uv, heights, version=int(writer[-1]))
    else:
        tool_files.argus_paired_points(tmp_path / "xypts.csv", uv, heights, flip_y=writer.endswith("flip"))
    base = ["import", "--format", "xypts", "--points", str(tmp_path / "xypts.csv"), "--cameras",
            str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv")]  # fmt: skip
    assert main(base) == 2  # the file does not say its origin: asked for
    err = capsys.readouterr().err.strip()
    assert "do not say their pixel origin: give --origin top-left" in err and "\n" not in err
    assert main(["-q", *base, "--origin", origin]) == 0
    written = np.genfromtxt(tmp_path / "xypts.csv", delimiter=",", skip_header=1).reshape(-1, 2, 3, 2)
    base_x = 1.0 if writer.startswith("dltdv") else 0.0
    h = np.array(heights, dtype=float)[None, None, :]
    v = written[..., 1] - base_x if origin == "top-left" else h - written[..., 1]  # DLTdv 7 and Argus's flip: h - y
    by_hand = np.stack([written[..., 0] - base_x, v], axis=-1).transpose(0, 2, 1, 3)
    imported = read_observations(tmp_path / "obs.csv", scenario.rig.camera_names, labels=TWO.labels)
    seen = np.any(np.isfinite(by_hand), axis=(1, 2, 3))
    assert np.allclose(imported.uv, by_hand[seen], atol=1e-6, equal_nan=True)
    assert np.allclose(imported.uv, uv[seen], atol=1e-6, equal_nan=True)
    direct = WandObservations(np.flatnonzero(seen), scenario.rig.camera_names, uv[seen])
    _calibrates_as_given_directly(tmp_path, tmp_path / "cameras.yaml", tmp_path / "obs.csv", scenario.rig, direct)


def test_the_origin_a_point_file_does_not_say_is_decided_from_the_fit_with_board_intrinsics(
    tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    # DLTdv files of either version with a board calibration's intrinsics (OpenCV's frame): the wrong origin
    # mirrors the points but not the lens, and the calibration with the intrinsics held refuses it.
    scenario = SCENARIOS["conventional"](pinhole=True)
    uv = simulate(scenario, 0.5, np.random.default_rng(5)).observations.uv
    heights = [spec.image_size[1] for spec in scenario.rig.cameras]
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    (tmp_path / "camera_array.toml").write_text(_camera_array_toml(scenario))
    for version, origin in ((8, "top-left"), (7, "bottom-left")):
        tool_files.dltdv_points(tmp_path / "xypts.csv", uv, heights, version=version)
        argv = ["import", "--format", "xypts", "--points", str(tmp_path / "xypts.csv"), "--cameras",
                str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv"), "--intrinsics",
                str(tmp_path / "camera_array.toml"), "--rig-out", str(tmp_path / "given.yaml")]  # fmt: skip
        assert main(argv) == 0
        out = capsys.readouterr().out
        assert f"do not say their origin: {origin} calibrates with camera_array.toml held" in out
        imported = read_observations(tmp_path / "obs.csv", scenario.rig.camera_names, labels=scenario.wand.labels)
        seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
        assert np.allclose(imported.uv, uv[seen], atol=1e-6, equal_nan=True)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("1 900 1920 1080 959.5 539.5 1 -0.25 0.06 0 0", "profile.txt, row 1: 11 values; a camera profile row has 12"),
        ("1 4 1920 1440 0.99 -0.01 0.01 718.4 977.1 -847.7 0 0.0003 0 0 2.3", "omnidirectional (CMei / ocam)"),
        ("0 900 1920 1080 959.5 539.5 1 -0.25 0.06 0 0 0", "row 1: the camera number is '0'; cameras count from 1"),
        ("1 900 1920 1080 959.5 539.5 1 -0.25 x 0 0 0", "row 1: 'x' is not a number"),
    ],
)
def test_a_camera_profile_that_cannot_be_read_names_the_row(line: str, message: str, tmp_path: Path) -> None:
    from wand_calib_ros.io.imports.camera_profile import read_camera_profile

    (tmp_path / "profile.txt").write_text(line + "\n")
    with pytest.raises(FormatError, match=re.escape(message)):
        read_camera_profile(tmp_path / "profile.txt")


def test_easywand_data_files_import_their_points_and_intrinsics_and_calibrate_as_given_directly(
    tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    from wand_calib_ros.io.imports.easywand import read_easywand

    scenario = SCENARIOS["action2"]()  # plumb_bob lenses, p1 not zero, the principal point off the middle row
    data = simulate(scenario, 1.0, np.random.default_rng(6))
    uv = data.observations.uv
    heights = [s.image_size[1] for s in scenario.rig.cameras]
    models = [camera.model for camera in scenario.cameras]
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
    # easyWand 5 holding its profile: its points and principal points DLTdv's (1-based), the origin not written
    for lower_left in (False, True):
        xy = tool_files.matlab_xy(uv, heights, lower_left=lower_left)
        tool_files.easywand5(tmp_path / "take_easyWandData.mat", xy, models, lower_left=lower_left)
        five = read_easywand(tmp_path / "take_easyWandData.mat", scenario.rig)
        assert five.pixels.origin is None and five.intrinsics is not None
        assert np.array_equal(five.frames, np.flatnonzero(seen))
        assert np.allclose(five.xy, xy[seen], atol=1e-9, equal_nan=True)
        origin = ["--origin", "bottom-left"] if lower_left else []
        argv = ["import", "--format", "easywand", "--points", str(tmp_path / "take_easyWandData.mat"), "--cameras",
                str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv"), "--rig-out",
                str(tmp_path / "given.yaml"), *origin]  # fmt: skip
        assert main(argv) == 0  # one command: the points and the profile easyWand held
        out = capsys.readouterr().out
        if not lower_left:
            assert "either origin fits alike, one the other's mirror image, so took top-left" in out
        imported = read_observations(tmp_path / "obs.csv", scenario.rig.camera_names, labels=scenario.wand.labels)
        assert np.allclose(imported.uv, uv[seen], atol=1e-6, equal_nan=True)  # 1-based, flipped where so
        _projects_as(tmp_path / "given.yaml", scenario)
    _calibrates_as_given_directly(tmp_path, tmp_path / "given.yaml", tmp_path / "obs.csv", _given_rig(scenario),
                                  data.observations)  # fmt: skip
    # easyWand 6: MATLAB 7.3, its origin flag, rows of the points file in ID, its intrinsics a struct array
    rows = np.flatnonzero(seen)
    for lower_left in (False, True):
        xy = tool_files.matlab_xy(uv[seen], heights, lower_left=lower_left)
        tool_files.easywand6(tmp_path / "take_easyWand6Data.mat", xy, rows, models, lower_left=lower_left)
        six = read_easywand(tmp_path / "take_easyWand6Data.mat", scenario.rig)
        assert six.pixels.origin == ("bottom-left" if lower_left else "top-left")
        assert np.array_equal(six.frames, rows)
        argv = ["import", "--format", "easywand", "--points", str(tmp_path / "take_easyWand6Data.mat"), "--cameras",
                str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv"), "--rig-out",
                str(tmp_path / "given.yaml")]  # fmt: skip
        assert main(argv) == 0
        assert "as the file says" in capsys.readouterr().out
        imported = read_observations(tmp_path / "obs.csv", scenario.rig.camera_names, labels=scenario.wand.labels)
        assert np.array_equal(imported.frames, rows)
        assert np.allclose(imported.uv, uv[seen], atol=1e-6, equal_nan=True)
        _projects_as(tmp_path / "given.yaml", scenario)
    # without --rig-out the points alone, and the intrinsics are named
    argv = ["import", "--format", "easywand", "--points", str(tmp_path / "take_easyWand6Data.mat"), "--cameras",
            str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv")]  # fmt: skip
    assert main(argv) == 0
    assert "carries the cameras' intrinsics: --rig-out FILE writes them into a rig file" in capsys.readouterr().out
    # a file for other cameras is one line naming what differs
    from scipy.io import savemat

    savemat(tmp_path / "four.mat", {"easyWandData": {"wandPts": np.zeros((3, 16))}})
    with pytest.raises(FormatError, match="its wand points have 16 columns; 2 markers in 2 cameras take 8"):
        read_easywand(tmp_path / "four.mat", scenario.rig)


def _camera_array_toml(scenario) -> str:  # type: ignore[no-untyped-def]
    """caliscope's camera_array.toml as its CameraArray.to_toml writes it ([cameras.N], Rodrigues rotations)."""
    import cv2

    from wand_calib_ros.core.model.camera_model import to_opencv

    def row(values) -> str:  # type: ignore[no-untyped-def]
        return "[" + ", ".join(repr(float(v)) for v in values) + "]"

    parts = []
    for cam_id, camera in enumerate(scenario.cameras):
        opencv = to_opencv(camera.model)
        matrix = "[" + ", ".join(row(r) for r in opencv.camera_matrix) + "]"
        rotation = row(cv2.Rodrigues(camera.pose.rotation)[0][:, 0])
        parts.append(
            f"[cameras.{cam_id}]\ncam_id = {cam_id}\nsize = [{', '.join(map(str, camera.spec.image_size))}]\n"
            f"rotation_count = 0\nerror = 0.31\nmatrix = {matrix}\ndistortions = {row(opencv.distortion)}\n"
            f"translation = {row(camera.pose.translation / 1000.0)}\nrotation = {rotation}\nexposure = -6\n"
            "grid_count = 30\nfisheye = false\n"
        )
    return "\n".join(parts)


def _caliscope_points(uv: np.ndarray, camera: str = "cam_id", point: str = "keypoint_id") -> str:
    """caliscope's point table (pandas to_csv, index=False): a row per seen point, obj_loc left empty."""
    lines = [f"sync_index,{camera},object_id,{point},img_loc_x,img_loc_y,obj_loc_x,obj_loc_y,obj_loc_z"]
    for f, c, p in zip(*np.nonzero(np.isfinite(uv[..., 0])), strict=True):
        lines.append(f"{f},{c},0,{p},{float(uv[f, c, p, 0])!r},{float(uv[f, c, p, 1])!r},,,")
    return "\n".join(lines) + "\n"


def test_a_caliscope_session_imports_in_one_command_and_calibrates_with_its_intrinsics(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from wand_calib_ros.io.imports.caliscope import read_caliscope_points
    from wand_calib_ros.io.rig_yaml import load_rig

    scenario = SCENARIOS["conventional"](pinhole=True)  # plumb_bob lenses, the three-LED wand (keypoints 0, 1, 2)
    data = simulate(scenario, 0.5, np.random.default_rng(8))
    uv = data.observations.uv
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    (tmp_path / "camera_array.toml").write_text(_camera_array_toml(scenario))
    (tmp_path / "xy_WAND.csv").write_text(_caliscope_points(uv))
    argv = ["import", "--format", "caliscope", "--points", str(tmp_path / "xy_WAND.csv"), "--cameras",
            str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv"), "--intrinsics",
            str(tmp_path / "camera_array.toml"), "--rig-out", str(tmp_path / "given.yaml"), "--as-start"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "(camera ids 0 -> cam0, 1 -> cam1)" in out and "as a start: cam_0 -> cam0 (plumb_bob)" in out
    read = read_observations(tmp_path / "obs.csv", scenario.rig.camera_names, labels=scenario.wand.labels)
    seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
    assert np.allclose(read.uv, uv[seen], atol=2e-6, equal_nan=True)
    given = load_rig(tmp_path / "given.yaml")
    for spec, camera in zip(given.cameras, scenario.cameras, strict=True):
        assert spec.intrinsics is not None and not spec.intrinsics_fixed
        assert np.allclose(spec.intrinsics.principal_point, camera.model.principal_point, atol=1e-9)
        assert np.isclose(spec.intrinsics.k[0], camera.model.k[0], rtol=1e-12)
    direct = WandObservations(np.flatnonzero(seen), scenario.rig.camera_names, uv[seen])
    _calibrates_as_given_directly(tmp_path, tmp_path / "given.yaml", tmp_path / "obs.csv", given, direct)
    # caliscope's older column names
    (tmp_path / "old.csv").write_text(_caliscope_points(uv, camera="port", point="point_id"))
    old = read_caliscope_points(tmp_path / "old.csv", scenario.rig).observations
    assert np.allclose(old.uv, uv[seen], atol=1e-12, equal_nan=True)


def test_pyopenlpt_wand_points_import_without_the_rows_its_filter_set_aside(tmp_path: Path) -> None:
    from wand_calib_ros.io.imports.openlpt import read_openlpt_points

    scenario = replace(paper_three_camera_scenario(), wand=WandSpec((0.0, 10.0)))
    data = simulate(scenario, 0.3, np.random.default_rng(9))
    uv = data.observations.uv
    lines = ["frame,cam_id,pt_idx,x,y,radius,status"]
    for f, c, p in zip(*np.nonzero(np.isfinite(uv[..., 0])), strict=True):
        lines.append(f"{f},{c},{p},{uv[f, c, p, 0]:.4f},{uv[f, c, p, 1]:.4f},14.9,Raw")
        if (f + c) % 7 == 0:  # a blob its filter judged too small, somewhere else in the image
            lines.append(f"{f},{c},{p},{(uv[f, c, p, 0] + 97.0) % 640:.4f},{uv[f, c, p, 1]:.4f},2.1,Filtered_Small")
    (tmp_path / "wand_points.csv").write_text("\n".join(lines) + "\n")
    table = read_openlpt_points(tmp_path / "wand_points.csv", scenario.rig)
    seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
    assert table.skipped == sum(1 for line in lines if line.endswith("Filtered_Small"))
    assert np.array_equal(table.observations.frames, np.flatnonzero(seen))
    assert np.allclose(table.observations.uv, uv[seen], atol=5e-5, equal_nan=True)  # its 4 decimals
    (tmp_path / "three.csv").write_text("\n".join(lines[:1] + [line for line in lines[1:] if ",2," not in line[:8]]))
    with pytest.raises(FormatError, match=r"three.csv: 2 cameras \(0, 1\) in the table, 3 in the rig description"):
        read_openlpt_points(tmp_path / "three.csv", scenario.rig)


def test_pyopenlpt_export_wand_data_imports_the_filtered_pairs_its_calibration_uses_and_calibrates_as_given(
    tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    scenario = replace(paper_three_camera_scenario(), wand=TWO)  # small ball A, large ball B
    data = simulate(scenario, 0.3, np.random.default_rng(9))
    uv = data.observations.uv.copy()
    uv[np.random.default_rng(1).random(uv.shape[:2]) < 0.05, 1] = np.nan  # the large ball not found: one ball
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    raw_rows, single = tool_files.openlpt_wand_data(tmp_path / "wand_points.csv", uv, np.random.default_rng(2))
    assert single > 0 and (tmp_path / "wand_points.csv").read_text().startswith("Frame,Camera,Status,PointIdx,X,Y")
    argv = ["import", "--format", "openlpt", "--points", str(tmp_path / "wand_points.csv"), "--cameras",
            str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv")]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"{raw_rows} rows its own calibration does not use left out, {single} views with one marker left out" in out
    # by hand: the filtered rows as written (3 decimals), a view with one ball left out
    by_hand = np.round(uv, 3)
    by_hand[np.isfinite(uv[..., 0]).sum(axis=2) == 1] = np.nan
    kept = np.any(np.isfinite(by_hand), axis=(1, 2, 3))
    imported = read_observations(tmp_path / "obs.csv", scenario.rig.camera_names, labels=TWO.labels)
    assert np.array_equal(imported.frames, np.flatnonzero(kept))
    assert np.allclose(imported.uv, by_hand[kept], atol=1e-6, equal_nan=True)
    direct = WandObservations(np.flatnonzero(kept), scenario.rig.camera_names, by_hand[kept])
    _calibrates_as_given_directly(tmp_path, tmp_path / "cameras.yaml", tmp_path / "obs.csv", scenario.rig, direct)


def test_import_options_and_tables_that_cannot_be_used_are_one_line(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    scenario = SCENARIOS["conventional"](pinhole=True)
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    uv = simulate(scenario, 0.5, np.random.default_rng(2), n=20).observations.uv
    (tmp_path / "xy.csv").write_text(_caliscope_points(uv))
    base = ["import", "--format", "caliscope", "--points", str(tmp_path / "xy.csv"), "--cameras",
            str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv")]  # fmt: skip
    assert main([*base, "--intrinsics", str(tmp_path / "camera_array.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("--intrinsics and --rig-out go together: the rig file is written with those intrinsics")
    assert "\n" not in err and not (tmp_path / "obs.csv").exists()
    (tmp_path / "xy.csv").write_text(_caliscope_points(uv).replace("img_loc_x", "x_loc"))
    assert main(base) == 2
    assert "xy.csv, row 1: no column img_loc_x in the header (sync_index, cam_id" in capsys.readouterr().err
    (tmp_path / "camera_array.toml").write_text(_camera_array_toml(scenario).replace("matrix = ", "# matrix = ", 1))
    (tmp_path / "xy.csv").write_text(_caliscope_points(uv))
    argv = [*base, "--intrinsics", str(tmp_path / "camera_array.toml"), "--rig-out", str(tmp_path / "given.yaml")]
    assert main(argv) == 2
    assert "camera_array.toml: [cameras.0] has no matrix: caliscope has not calibrated its intrinsics" in (
        capsys.readouterr().err
    )
    assert not (tmp_path / "obs.csv").exists() and not (tmp_path / "given.yaml").exists()  # all read before writing
