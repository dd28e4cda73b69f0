"""The HTML report renders with every figure, for simulated and real data."""

from __future__ import annotations

from pathlib import Path

import pytest

from wand_calib_ros.cli import main
from wand_calib_ros.report.figures import FIGURES

DATA = Path(__file__).resolve().parents[1] / "data" / "ewand"


def _check(out: Path, *, timing: bool, session: bool = False) -> str:
    """The page has every figure (the timing one only where the result has a timing to show, the running
    estimate only for a live session)."""
    page = (out / "index.html").read_text()
    expected = [n for n in FIGURES if (timing or n != "timing") and (session or n != "running_estimate")]
    assert page.count('src="data:image/png;base64,') == len(expected)
    for name in expected:
        assert (out / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
    assert "Parameters" in page and "Warnings" in page
    return page


@pytest.mark.parametrize("scenario", ["paper", "ring6"])
def test_report_for_simulated_rigs(tmp_path: Path, scenario: str) -> None:
    sim = tmp_path / "sim"
    assert main(["-q", "simulate", scenario, "--seed", "1", "--out", str(sim)]) == 0
    files = ["--cameras", str(sim / "cameras.yaml"), "--observations", str(sim / "observations.csv")]
    assert main(["-q", "calibrate", *files, "--output", str(tmp_path / "result.yaml")]) == 0
    assert main(["-q", "report", "--result", str(tmp_path / "result.yaml"), *files, "--out", str(tmp_path / "r")]) == 0
    page = _check(tmp_path / "r", timing=False)  # independent placements: no timing
    assert "cam1" in page


def test_report_of_a_sparse_two_marker_take_with_plumb_bob_intrinsics_given(tmp_path: Path) -> None:
    sim = tmp_path / "sim"
    assert main(["-q", "simulate", "sparse4", "--seed", "3", "--known-intrinsics", "--out", str(sim)]) == 0
    files = ["--cameras", str(sim / "cameras.yaml"), "--observations", str(sim / "observations.csv")]
    assert main(["-q", "calibrate", *files, "--output", str(tmp_path / "result.yaml")]) == 0
    assert main(["-q", "report", "--result", str(tmp_path / "result.yaml"), *files, "--out", str(tmp_path / "r")]) == 0
    assert "cam3" in _check(tmp_path / "r", timing=False)


def test_report_for_ewand(tmp_path: Path) -> None:
    files = ["--cameras", str(DATA / "cameras.yaml"), "--observations", str(DATA / "observations.csv")]
    assert main(["-q", "calibrate", *files, "--output", str(tmp_path / "result.yaml")]) == 0
    assert main(["-q", "report", "--result", str(tmp_path / "result.yaml"), *files, "--out", str(tmp_path / "r")]) == 0
    page = _check(tmp_path / "r", timing=True)  # cam0's estimated offset, before and after
    assert "<h2>timing</h2>" in page


def test_report_of_a_free_running_take_shows_its_timing(tmp_path: Path) -> None:
    sim = tmp_path / "sim"
    assert (
        main(["-q", "simulate", "paper3", "--take", "10", "--free-running", "--noise", "0.3", "--out", str(sim)]) == 0
    )
    files = ["--cameras", str(sim / "cameras.yaml"), "--observations", str(sim / "observations.csv")]
    assert main(["-q", "calibrate", *files, "--output", str(tmp_path / "result.yaml")]) == 0
    assert main(["-q", "report", "--result", str(tmp_path / "result.yaml"), *files, "--out", str(tmp_path / "r")]) == 0
    _check(tmp_path / "r", timing=True)


def test_report_on_a_result_of_another_rig_is_a_clear_error(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    sim = tmp_path / "sim"
    assert main(["-q", "simulate", "paper3", "--seed", "1", "--out", str(sim)]) == 0
    files = ["--cameras", str(DATA / "cameras.yaml"), "--observations", str(DATA / "observations.csv")]
    code = main(["-q", "report", "--result", str(sim / "truth.yaml"), *files, "--out", str(tmp_path / "r")])
    assert code == 2
    assert "no result for camera(s) cam3" in capsys.readouterr().err


def test_the_figures_stay_readable_with_outliers_and_wide_lenses(tmp_path: Path) -> None:
    """Looked at as a user would: reference curves clipped to the image, outliers marked instead of
    drawn as huge arrows, histograms of the points used with the rejected ones counted, colour scales
    labelled, rotations in degrees."""
    import numpy as np
    import yaml

    from wand_calib_ros.io.observations_csv import read_observations
    from wand_calib_ros.io.rig_yaml import load_rig
    from wand_calib_ros.report import figures
    from wand_calib_ros.report.analysis import prepare
    from wand_calib_ros.report.html import write_report

    sim = tmp_path / "sim"
    assert main(["-q", "simulate", "paper", "--seed", "1", "--outliers", "0.03", "--out", str(sim)]) == 0
    files = ["--cameras", str(sim / "cameras.yaml"), "--observations", str(sim / "observations.csv")]
    assert main(["-q", "calibrate", *files, "--output", str(tmp_path / "result.yaml")]) == 0
    rig = load_rig(sim / "cameras.yaml")
    data = prepare(rig, read_observations(sim / "observations.csv", rig.camera_names), tmp_path / "result.yaml")
    assert all(camera.rejected.any() and camera.rejected.mean() < 0.2 for camera in data.cameras)

    curves = figures.distortion_curves(data)
    for axis, spec in zip(curves.axes[: len(rig.cameras)], rig.cameras, strict=True):
        corner = 0.5 * np.hypot(*spec.image_size)
        assert axis.get_ylim()[0] >= 0 and axis.get_ylim()[1] <= 1.2 * 1.5 * corner  # not -100,000 px
    vectors = figures.residual_vectors(data)
    for axis, camera in zip(vectors.axes, data.cameras, strict=False):
        (arrows,) = axis.collections
        assert len(arrows.get_offsets()) == int((~camera.rejected).sum())  # rejected views: marks, not arrows
        (marks,) = axis.get_lines()
        assert len(marks.get_xdata()) == int(camera.rejected.sum())
    histograms = figures.residual_histograms(data)
    assert all("points of rejected views not shown" in axis.get_title() for axis in histograms.axes[:2])
    heat = figures.coverage(data)
    assert sum(axis.get_label() == "<colorbar>" for axis in heat.axes) == len(rig.cameras)

    page = write_report(rig, read_observations(sim / "observations.csv", rig.camera_names), tmp_path / "result.yaml",
                        tmp_path / "r").read_text()  # fmt: skip
    assert "<th>rx (deg)</th>" in page and "<th>RMS per coordinate (px)</th>" in page
    rotvec = np.degrees(data.poses[1].rotvec)
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    assert f"{rotvec[0]:.5g}" in page and result["cameras"]["cam1"]["std"]["rx"] > 0


def test_report_of_a_live_session_shows_its_running_estimate_and_events(tmp_path: Path) -> None:
    import numpy as np

    from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
    from wand_calib_ros.io.observations_csv import read_observations
    from wand_calib_ros.io.rig_yaml import load_rig
    from wand_calib_ros.io.session_csv import ESTIMATES_FILE, EVENTS_FILE, append_estimate, append_event
    from wand_calib_ros.report.html import write_report

    sim, out = tmp_path / "sim", tmp_path / "out"
    assert main(["-q", "simulate", "paper3", "--seed", "2", "--out", str(sim)]) == 0
    files = ["--cameras", str(sim / "cameras.yaml"), "--observations", str(sim / "observations.csv")]
    assert main(["-q", "calibrate", *files, "--output", str(out / "result.yaml")]) == 0
    rig = load_rig(sim / "cameras.yaml")
    observations = read_observations(sim / "observations.csv", rig.camera_names)
    for second, frames in enumerate((60, 120, 240)):  # three rounds, as the collector appends them
        result = calibrate(rig, observations.select_frames(np.arange(frames)), CalibrationOptions())
        append_estimate(out / ESTIMATES_FILE, 1000.0 + 3 * second, frames, result)
    append_event(out / EVENTS_FILE, 1010.0, "calibrated", "", "RMS ...")
    append_event(out / EVENTS_FILE, 1030.0, "moved", "cam1", "cam1 moved: residual 1.8 px, was 1.0")
    write_report(rig, observations, out / "result.yaml", out / "report")
    page = _check(out / "report", timing=False, session=True)
    assert "<h2>running estimate</h2>" in page and "Session events" in page
    assert "cam1 moved: residual 1.8 px, was 1.0" in page
    assert "<h2>Quality: " in page


def test_each_camera_is_reported_in_its_own_model_with_plain_metric_names(tmp_path: Path) -> None:
    import yaml

    rig = tmp_path / "rig"
    assert main(["-q", "simulate", "mixed", "--plumb-bob", "--seed", "1", "--out", str(rig)]) == 0
    document = yaml.safe_load((rig / "cameras.yaml").read_text())
    document["cameras"][1]["camera_model"] = "plumb_bob"  # the conventional camera, in OpenCV's pinhole model
    (rig / "cameras.yaml").write_text(yaml.safe_dump(document))
    argv = ["-q", "calibrate", "--cameras", str(rig / "cameras.yaml"), "--observations", str(rig / "observations.csv")]
    assert main([*argv, "--output", str(tmp_path / "result.yaml")]) == 0
    report = ["-q", "report", "--result", str(tmp_path / "result.yaml"), "--cameras", str(rig / "cameras.yaml")]
    assert main([*report, "--observations", str(rig / "observations.csv"), "--out", str(tmp_path / "r")]) == 0
    page = (tmp_path / "r" / "index.html").read_text()
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())["cameras"]
    models = {name: camera["opencv"]["distortion_model"] for name, camera in result.items()}
    assert sorted(models.values()) == ["equidistant", "plumb_bob"]
    pinhole = next(name for name, model in models.items() if model == "plumb_bob")
    fisheye = next(name for name, model in models.items() if model == "equidistant")
    p1 = result[pinhole]["opencv"]["distortion"][2]
    assert f"p1 {p1:.4g}" in page and "<th>fx (px)</th>" in page and "<th>k1 (mm)</th>" not in page
    assert f"{fisheye}: exactly OpenCV fisheye (cv2.fisheye) / ROS equidistant" in page
    assert f"{pinhole}: exactly OpenCV pinhole (cv2.projectPoints, 5 coefficients) / ROS plumb_bob" in page
    assert "free_parameters" not in page and "parameters estimated (cameras and wand placements)" in page
