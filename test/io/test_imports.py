"""Other tools' wand point files: an easyWand / Argus / DLTdv ``xypts.csv`` of a two-marker wand."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from wand_calib_ros.cli import main
from wand_calib_ros.core.model.rig import WandSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.imports.anipose import read_anipose
from wand_calib_ros.io.imports.xypts import read_xypts
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.scenarios import SCENARIOS, paper_three_camera_scenario, simulate

TWO = WandSpec((0.0, 600.0))


def _write_xypts(path: Path, uv: np.ndarray, heights: list[int], unseen: str = "NaN") -> None:
    """A point file as Argus writes its paired points: pt1 of every camera, then pt2; y up from the bottom;
    ``unseen`` in the cells of markers not seen (DLTdv leaves them empty)."""
    _, n_cameras, n_points, _ = uv.shape
    header = [f"pt{p + 1}_cam{c + 1}_{axis}" for p in range(n_points) for c in range(n_cameras) for axis in "xy"]
    lines = [",".join(header)]
    for frame in uv:
        cells = []
        for p in range(n_points):
            for c in range(n_cameras):
                x, y = frame[c, p]
                cells += [unseen, unseen] if not np.isfinite(x) else [f"{x:.6f}", f"{heights[c] - y:.6f}"]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")


def test_an_argus_point_file_imports_exactly_and_calibrates(tmp_path: Path) -> None:
    scenario = replace(paper_three_camera_scenario(), wand=TWO)
    data = simulate(scenario, 0.5, np.random.default_rng(3))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    heights = [spec.image_size[1] for spec in scenario.rig.cameras]
    _write_xypts(tmp_path / "wand-xypts.csv", data.observations.uv, heights)
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
    _write_xypts(tmp_path / "xypts.csv", uv, [spec.image_size[1] for spec in scenario.rig.cameras], unseen="")
    out = tmp_path / "observations.csv"
    argv = ["--points", str(tmp_path / "xypts.csv"), "--cameras", str(tmp_path / "cameras.yaml"), "--out", str(out)]
    assert main(["-q", "import", "--format", "xypts", *argv]) == 0
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
        ("frame,pt1_cam1_x\n", "column 1 is 'frame', not pt<P>_cam<C>_x or _y"),
        (None, "'high' is not a number (write NaN where a marker was not seen)"),
        (None, "pt2_cam3 has x or y only"),
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


def _write_argus_profile(path: Path, scenario) -> None:  # type: ignore[no-untyped-def]
    """A camera profile as Argus writes its ``-clicker-profile.txt`` (pandas, spaces, no header): camera
    number, f, width and height as twice the principal point, cx, cy, aspect ratio, r2, r4, t1, t2, r6."""
    from wand_calib_ros.core.model.camera_model import to_opencv

    lines = []
    for number, camera in enumerate(scenario.cameras, start=1):
        opencv = to_opencv(camera.model)
        (fx, _, cx), (_, fy, cy), _ = opencv.camera_matrix
        values = [fx, 2 * cx, 2 * cy, cx, cy, fy / fx, *opencv.distortion]
        lines.append(" ".join([str(number), *(repr(float(v)) for v in values)]))
    path.write_text("\n".join(lines) + "\n")


def test_an_argus_camera_profile_and_its_points_in_one_command_calibrate_as_the_truths_intrinsics(
    tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    from wand_calib_ros.core.model.camera_model import project
    from wand_calib_ros.core.pipeline import calibrate
    from wand_calib_ros.io.result_yaml import read_result
    from wand_calib_ros.io.rig_yaml import load_rig

    scenario = SCENARIOS["action2"]()
    data = simulate(scenario, 1.0, np.random.default_rng(11))
    save_rig(scenario.rig, tmp_path / "cameras.yaml")
    _write_argus_profile(tmp_path / "profile.txt", scenario)
    _write_xypts(tmp_path / "wand-xypts.csv", data.observations.uv, [s.image_size[1] for s in scenario.rig.cameras])
    argv = ["import", "--format", "xypts", "--points", str(tmp_path / "wand-xypts.csv"), "--cameras",
            str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "obs.csv"), "--intrinsics",
            str(tmp_path / "profile.txt"), "--rig-out", str(tmp_path / "given.yaml")]  # fmt: skip
    assert main(argv) == 0
    assert "cam1 -> cam0 (plumb_bob), cam2 -> cam1 (plumb_bob)" in capsys.readouterr().out  # in order
    alone = ["import", "--format", "argus-profile", "--points", str(tmp_path / "profile.txt"), "--cameras",
             str(tmp_path / "cameras.yaml"), "--out", str(tmp_path / "alone.yaml")]  # fmt: skip
    assert main(alone) == 0  # the intrinsics alone: the same rig file
    assert (tmp_path / "alone.yaml").read_text() == (tmp_path / "given.yaml").read_text()
    given = load_rig(tmp_path / "given.yaml")
    points = np.random.default_rng(0).uniform([-2000, -1000, 5000], [2000, 1000, 11000], (50, 3))
    for spec, camera in zip(given.cameras, scenario.cameras, strict=True):
        assert spec.intrinsics is not None and spec.intrinsics_fixed
        in_camera = camera.pose.apply(points)
        assert np.allclose(project(spec.intrinsics, in_camera), project(camera.model, in_camera), atol=1e-9)
    assert main(["-q", "calibrate", "--cameras", str(tmp_path / "given.yaml"), "--observations",
                 str(tmp_path / "obs.csv"), "--output", str(tmp_path / "result.yaml")]) == 0  # fmt: skip
    imported = read_result(tmp_path / "result.yaml")[1]["cam1"].pose
    direct = calibrate(_given_rig(scenario), data.observations).camera("cam1").pose
    assert np.allclose(imported.rotation, direct.rotation, atol=1e-6)  # the import loses nothing
    assert np.allclose(imported.translation, direct.translation, atol=1e-3)


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


def _wand_points_table(uv: np.ndarray) -> np.ndarray:
    """(F, 4C) easyWand's wand points: the first marker's x, y in every camera, then the second's."""
    return uv.transpose(0, 2, 1, 3).reshape(len(uv), -1)


def test_easywand5_and_easywand6_data_files_import_exactly(tmp_path: Path) -> None:
    import h5py
    from scipy.io import savemat

    from wand_calib_ros.io.imports.easywand import read_easywand

    scenario = replace(paper_three_camera_scenario(), wand=TWO)
    data = simulate(scenario, 0.5, np.random.default_rng(6))
    uv = data.observations.uv
    heights = np.array([s.image_size[1] for s in scenario.rig.cameras], dtype=float)
    widths = np.array([s.image_size[0] for s in scenario.rig.cameras], dtype=float)
    # easyWand 5: a MATLAB 5.0 struct, DLTdv's bottom-left pixels
    lower_left = uv.copy()
    lower_left[..., 1] = heights[None, :, None] - uv[..., 1]
    fields = {"wandPts": _wand_points_table(lower_left), "imageWidth": widths, "imageHeight": heights, "nCams": 3.0}
    savemat(tmp_path / "take_easyWandData.mat", {"easyWandData": fields})
    five = read_easywand(tmp_path / "take_easyWandData.mat", scenario.rig)
    seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
    assert np.array_equal(five.frames, np.flatnonzero(seen))
    assert np.allclose(five.uv, uv[seen], atol=1e-9, equal_nan=True)
    # easyWand 6: MATLAB 7.3 (HDF5, arrays column-major), rows of the points file in ID, top-left pixels
    rows = np.flatnonzero(seen)
    path = tmp_path / "take_easyWand6Data.mat"
    with h5py.File(path, "w", userblock_size=512) as mat:
        wand = mat.create_group("ew6Save/data/wandPts")
        for group in (mat["ew6Save"], mat["ew6Save/data"], wand):
            group.attrs["MATLAB_class"] = np.bytes_("struct")
        wand.create_dataset("data", data=_wand_points_table(uv[seen]).T).attrs["MATLAB_class"] = np.bytes_("double")
        wand.create_dataset("ID", data=(rows + 1.0)[None, :]).attrs["MATLAB_class"] = np.bytes_("double")
        flag = mat["ew6Save/data"].create_dataset("imageOriginLowerLeft", data=np.zeros((1, 1)))
        flag.attrs["MATLAB_class"] = np.bytes_("double")
    with path.open("r+b") as stream:  # MATLAB's text header in the user block
        stream.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Dec  4 12:00:00 2026 HDF5 schema 1.00 .")
    six = read_easywand(path, scenario.rig)
    assert np.array_equal(six.frames, rows)
    assert np.allclose(six.uv, uv[seen], atol=1e-9, equal_nan=True)
    # a file for other cameras is one line naming what differs
    savemat(tmp_path / "four.mat", {"easyWandData": {**fields, "wandPts": np.zeros((3, 16))}})
    with pytest.raises(FormatError, match="its wand points have 16 columns; 2 markers in 3 cameras take 12"):
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
    assert main(["-q", "calibrate", "--cameras", str(tmp_path / "given.yaml"), "--observations",
                 str(tmp_path / "obs.csv"), "--output", str(tmp_path / "result.yaml")]) == 0  # fmt: skip
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
