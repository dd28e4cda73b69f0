"""Other tools' wand point files: an easyWand / Argus / DLTdv ``xypts.csv`` of a two-marker wand."""

from __future__ import annotations

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
