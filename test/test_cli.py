"""The wand-calib command: end to end, and one clear line for every bad input."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from wand_calib_ros.cli import main
from wand_calib_ros.io.observations_csv import read_observations, write_observations


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("paper")
    assert main(["-q", "simulate", "paper", "--seed", "3", "--noise", "0.5", "--out", str(out)]) == 0
    return out


def _calibrate(sim: Path, out: Path, *extra: str) -> int:
    return main(
        [
            "-q",
            "calibrate",
            "--cameras",
            str(sim / "cameras.yaml"),
            "--observations",
            str(sim / "observations.csv"),
            "--output",
            str(out / "result.yaml"),
            *extra,
        ]
    )


def test_simulate_then_calibrate_recovers_the_truth(simulated: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    code = _calibrate(
        simulated, tmp_path, "--camera-info-dir", str(tmp_path / "info"), "--truth", str(simulated / "truth.yaml")
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "equidistant" in printed and "held-out wand length error" in printed
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    truth = yaml.safe_load((simulated / "truth.yaml").read_text())
    for name in ("cam0", "cam1"):
        fx = result["cameras"][name]["opencv_equidistant"]["camera_matrix"][0][0]
        fx_true = truth["cameras"][name]["opencv_equidistant"]["camera_matrix"][0][0]
        assert abs(fx - fx_true) < 3.0
        pp = np.array(result["cameras"][name]["principal_point"])
        assert np.linalg.norm(pp - truth["cameras"][name]["principal_point"]) < 5.0
    assert np.allclose(result["cameras"]["cam1"]["translation"], truth["cameras"]["cam1"]["translation"], atol=10.0)
    assert (tmp_path / "info" / "cam1.yaml").exists()


def _expect_one_line_error(capsys, code: int, *needles: str) -> None:  # type: ignore[no-untyped-def]
    captured = capsys.readouterr()
    assert code == 2
    lines = [line for line in captured.err.splitlines() if line.startswith("wand-calib: error:")]
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err
    for needle in needles:
        assert needle in lines[0]


def test_missing_columns(simulated: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "obs.csv").write_text("frame,camera,u,v\n0,cam0,1,2\n")
    shutil.copy(simulated / "cameras.yaml", tmp_path)
    code = main(
        [
            "-q",
            "calibrate",
            "--cameras",
            str(tmp_path / "cameras.yaml"),
            "--observations",
            str(tmp_path / "obs.csv"),
            "--output",
            str(tmp_path / "r.yaml"),
        ]
    )
    _expect_one_line_error(capsys, code, "obs.csv", "row 1", "missing column(s) point")


def test_nan_in_observations(simulated: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    lines = (simulated / "observations.csv").read_text().splitlines()
    lines[7] = ",".join([*lines[7].split(",")[:3], "nan", "12.0"])
    (tmp_path / "observations.csv").write_text("\n".join(lines) + "\n")
    shutil.copy(simulated / "cameras.yaml", tmp_path)
    code = _calibrate(tmp_path, tmp_path)
    _expect_one_line_error(capsys, code, "row 8", "must be finite")


def test_unknown_camera_name(simulated: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    text = (simulated / "observations.csv").read_text().replace(",cam1,", ",camX,", 1)
    (tmp_path / "observations.csv").write_text(text)
    shutil.copy(simulated / "cameras.yaml", tmp_path)
    code = _calibrate(tmp_path, tmp_path)
    _expect_one_line_error(capsys, code, "unknown camera 'camX'", "row")


def test_too_few_placements(simulated: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    obs = read_observations(simulated / "observations.csv")
    write_observations(obs.select_frames(np.arange(obs.frames.size) < 8), tmp_path / "observations.csv")
    shutil.copy(simulated / "cameras.yaml", tmp_path)
    code = _calibrate(tmp_path, tmp_path)
    _expect_one_line_error(capsys, code, "only 8 placements", "cam0", "cam1")


def test_non_positive_wand_length(simulated: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    text = (simulated / "cameras.yaml").read_text().replace("L2: 200.0", "L2: 0.0")
    (tmp_path / "cameras.yaml").write_text(text)
    shutil.copy(simulated / "observations.csv", tmp_path)
    code = _calibrate(tmp_path, tmp_path)
    _expect_one_line_error(capsys, code, "cameras.yaml", "wand lengths must be positive")


def test_all_placements_degenerate(simulated: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    obs = read_observations(simulated / "observations.csv")
    still = obs.uv[:1].repeat(60, axis=0) + np.random.default_rng(0).normal(scale=0.3, size=(60, *obs.uv.shape[1:]))
    from wand_calib_ros.core.model.rig import WandObservations

    write_observations(WandObservations(np.arange(60), obs.camera_names, still), tmp_path / "observations.csv")
    shutil.copy(simulated / "cameras.yaml", tmp_path)
    code = _calibrate(tmp_path, tmp_path)
    _expect_one_line_error(capsys, code, "hardly moved", "cam0")


def test_missing_input_file(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    code = _calibrate(tmp_path, tmp_path)
    _expect_one_line_error(capsys, code, "cameras.yaml", "cannot read")


def test_console_script_runs_as_a_separate_process(simulated: Path, tmp_path: Path) -> None:
    completed = subprocess.run(
        [
            sys.executable,
            "-m",
            "wand_calib_ros.cli",
            "calibrate",
            "--cameras",
            str(simulated / "cameras.yaml"),
            "--observations",
            str(tmp_path / "missing.csv"),
            "--output",
            str(tmp_path / "r.yaml"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.returncode == 2
    assert completed.stderr.strip().splitlines()[-1].startswith("wand-calib: error:")
    assert "Traceback" not in completed.stderr


def test_multi_camera_rig_with_outliers_end_to_end(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    sim = tmp_path / "ring"
    assert main(["-q", "simulate", "ring6", "--seed", "2", "--outliers", "0.03", "--out", str(sim)]) == 0
    assert _calibrate(sim, tmp_path, "--truth", str(sim / "truth.yaml")) == 0
    printed = capsys.readouterr().out
    assert "calibrated 6 cameras" in printed and "rejected as outliers" in printed
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    assert len(result["cameras"]) == 6
    assert sum(c["rejected_views"] for c in result["cameras"].values()) > 0
    truth = yaml.safe_load((sim / "truth.yaml").read_text())
    assert truth["outlier_fraction"] == 0.03


def test_max_placements_subsamples(simulated: Path, tmp_path: Path) -> None:
    assert _calibrate(simulated, tmp_path, "--max-placements", "120") == 0
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    assert result["metrics"]["placements_used"] <= 120


def test_render_detect_calibrate_from_a_bag(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "rec"
    assert main(["-q", "render", "paper", "--frames", "150", "--seed", "2", "--out", str(out)]) == 0
    assert (
        main(
            ["-q", "detect", str(out / "bag"), "--cameras", str(out / "cameras.yaml"), "--output", str(out / "obs.csv")]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "cam0: 150 images" in printed
    detected = read_observations(out / "obs.csv", ("cam0", "cam1"))
    drawn = read_observations(out / "drawn.csv", ("cam0", "cam1"))
    rows = np.searchsorted(drawn.frames, detected.frames)  # frame ids number the time slots
    both = detected.complete & drawn.complete[rows]
    errors = np.linalg.norm(detected.uv - drawn.uv[rows], axis=-1)[both]
    assert (errors > 3).mean() <= 0.005, np.sort(errors)[-10:]  # labels
    assert np.sqrt(np.mean(errors[errors <= 3] ** 2) / 2) < 0.15  # centres
    code = main(
        [
            "-q",
            "calibrate",
            "--cameras",
            str(out / "cameras.yaml"),
            "--observations",
            str(out / "obs.csv"),
            "--output",
            str(tmp_path / "result.yaml"),
        ]
    )
    assert code == 0
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    truth = yaml.safe_load((out / "truth.yaml").read_text())
    for name in ("cam0", "cam1"):
        pp = np.array(result["cameras"][name]["principal_point"])
        assert np.linalg.norm(pp - truth["cameras"][name]["principal_point"]) < 1.0  # 0.04 px detection noise


def test_detect_on_a_bag_without_the_topics_is_one_clear_line(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "rec"
    assert main(["-q", "render", "paper", "--frames", "5", "--out", str(out)]) == 0
    code = main(
        [
            "-q",
            "detect",
            str(out / "bag"),
            "--cameras",
            str(out / "cameras.yaml"),
            "--output",
            str(out / "obs.csv"),
            "--topic",
            "/{camera}/color",
        ]
    )
    _expect_one_line_error(capsys, code, "none of the image topics", "/cam0/image_raw")


def test_detect_writes_debug_overlays(tmp_path: Path) -> None:
    out = tmp_path / "rec"
    assert main(["-q", "render", "paper", "--frames", "10", "--reflections", "0.5", "--out", str(out)]) == 0
    debug = tmp_path / "debug"
    assert (
        main(
            [
                "-q",
                "detect",
                str(out / "bag"),
                "--cameras",
                str(out / "cameras.yaml"),
                "--output",
                str(out / "obs.csv"),
                "--debug-dir",
                str(debug),
                "--debug-every",
                "5",
            ]
        )
        == 0
    )
    pictures = sorted(debug.glob("*.png"))
    assert len(pictures) == 4  # 10 images per camera, every 5th
    assert pictures[0].read_bytes()[:4] == b"\x89PNG"


def test_a_free_running_take_is_simulated_and_its_timing_calibrated(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    sim = tmp_path / "take"
    arguments = ["simulate", "paper3", "--take", "10", "--free-running", "--readout-ms", "20", "--noise", "0.25"]
    assert main(["-q", *arguments, "--seed", "4", "--out", str(sim)]) == 0
    assert read_observations(sim / "observations.csv").stamps is not None
    truth = yaml.safe_load((sim / "truth.yaml").read_text())["cameras"]
    assert all(entry["rolling_shutter_readout_s"] == 0.02 for entry in truth.values())
    capsys.readouterr()
    assert _calibrate(sim, tmp_path, "--truth", str(sim / "truth.yaml")) == 0
    out = capsys.readouterr().out
    assert "time offset" in out and "readout" in out
    errors = [float(part.split()[-2]) for part in out.split(",") if "time offset error" in part]
    assert len(errors) == 3 and max(abs(e) for e in errors) < 1.0  # ms
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    assert result["timing"]["time_offsets"] == "estimated"
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_code:  # argparse: a usage line and exit 2
        _calibrate(sim, tmp_path, "--time-offsets", "bogus")
    assert exit_code.value.code == 2 and "--time-offsets: invalid choice" in capsys.readouterr().err


def test_estimating_offsets_of_independent_placements_is_one_clear_line(
    simulated: Path, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    assert _calibrate(simulated, tmp_path, "--time-offsets", "estimate") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "time offsets cannot be estimated" in err[0]


def test_calibrate_with_the_intrinsics_given_in_cameras_yaml(simulated: Path, tmp_path: Path) -> None:
    truth = yaml.safe_load((simulated / "truth.yaml").read_text())
    rig = yaml.safe_load((simulated / "cameras.yaml").read_text())
    for camera in rig["cameras"]:  # a board calibration of each camera: OpenCV fisheye K and D
        opencv = truth["cameras"][camera["name"]]["opencv_equidistant"]
        camera["intrinsics"] = {"K": opencv["camera_matrix"], "D": opencv["distortion"]}
    sim = tmp_path / "sim"
    sim.mkdir()
    (sim / "cameras.yaml").write_text(yaml.safe_dump(rig))
    (sim / "observations.csv").write_bytes((simulated / "observations.csv").read_bytes())
    assert _calibrate(sim, tmp_path) == 0
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    for name in ("cam0", "cam1"):
        camera = result["cameras"][name]
        assert camera["intrinsics"] == "given" and camera["initial_projection"] == "given"
        given = truth["cameras"][name]["opencv_equidistant"]
        assert np.allclose(camera["opencv_equidistant"]["camera_matrix"], given["camera_matrix"], rtol=1e-12)
        assert np.allclose(camera["opencv_equidistant"]["distortion"], given["distortion"], rtol=1e-9, atol=1e-15)
        assert not {"k1", "u0", "v0"} & set(camera["std"])
    assert np.allclose(result["cameras"]["cam1"]["translation"], truth["cameras"]["cam1"]["translation"], atol=10.0)


def test_a_five_marker_wand_from_simulate_to_result(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    sim = tmp_path / "five"
    assert main(["-q", "simulate", "paper3", "--seed", "2", "--wand-mm", "0,120,250,400,600", "--out", str(sim)]) == 0
    assert yaml.safe_load((sim / "cameras.yaml").read_text())["wand"] == {"points_mm": [0, 120, 250, 400, 600]}
    assert {row.split(",")[2] for row in (sim / "observations.csv").read_text().splitlines()[1:]} == set("ABCDE")
    assert _calibrate(sim, tmp_path, "--truth", str(sim / "truth.yaml")) == 0
    assert "wand |AE| " in capsys.readouterr().out
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    assert result["wand"] == {"points_mm": [0, 120, 250, 400, 600]}
    assert result["metrics"]["wand_length_rms_mm"] < 10.0


def test_a_two_marker_wand_from_simulate_to_result(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    sim = tmp_path / "two"
    assert main(["-q", "simulate", "paper", "--seed", "2", "--wand-mm", "0,600", "--out", str(sim)]) == 0
    assert _calibrate(sim, tmp_path) == 0
    assert "wand |AB| " in capsys.readouterr().out
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    assert result["wand"] == {"points_mm": [0, 600]} and result["metrics"]["wand_length_rms_mm"] < 10.0
    assert main(["-q", "simulate", "paper", "--wand-mm", "0,600,500", "--out", str(sim)]) == 2
    assert "marker positions must start at 0 mm and increase" in capsys.readouterr().err


def _rendered_wand_take(tmp_path: Path, wand: str, labels: tuple[str, ...]) -> tuple:  # type: ignore[type-arg]
    """A 200-frame paper3 take of another wand rendered and detected: (detected, drawn rows of it, frames
    both show whole, the calibrate command's arguments, the truth)."""
    out = tmp_path / "rec"
    assert main(["-q", "render", "paper3", "--frames", "200", "--seed", "2", "--wand-mm", wand, "--out", str(out)]) == 0
    cameras = ["--cameras", str(out / "cameras.yaml")]
    assert main(["-q", "detect", str(out / "bag"), *cameras, "--output", str(out / "obs.csv")]) == 0
    names = ("cam0", "cam1", "cam2")
    detected = read_observations(out / "obs.csv", names, labels=labels)
    drawn = read_observations(out / "drawn.csv", names, labels=labels)
    rows = np.searchsorted(drawn.frames, detected.frames)
    both = detected.complete & drawn.complete[rows]
    argv = [*cameras, "--observations", str(out / "obs.csv"), "--output", str(tmp_path / "result.yaml")]
    return detected, drawn.uv[rows], both, argv, yaml.safe_load((out / "truth.yaml").read_text())


def _calibrated_near_the_truth(tmp_path: Path, argv: list[str], truth: dict) -> None:  # type: ignore[type-arg]
    assert main(["-q", "calibrate", *argv]) == 0
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    for name in ("cam0", "cam1", "cam2"):
        pp = np.array(result["cameras"][name]["principal_point"])
        assert np.linalg.norm(pp - truth["cameras"][name]["principal_point"]) < 1.0
    assert result["metrics"]["wand_length_rms_mm"] < 1.0


def test_a_two_led_wand_from_a_rendered_bag_to_the_calibration(tmp_path: Path) -> None:
    detected, drawn, both, argv, truth = _rendered_wand_take(tmp_path, "0,600", ("A", "B"))
    # the two LEDs as found: each view matches the drawn ones in one order or the other
    straight = np.linalg.norm(detected.uv - drawn, axis=-1).max(axis=-1)
    crossed = np.linalg.norm(detected.uv[:, :, ::-1] - drawn, axis=-1).max(axis=-1)
    assert both.sum() > 400 and np.all(np.minimum(straight, crossed)[both] < 0.5)
    _calibrated_near_the_truth(tmp_path, argv, truth)


def test_a_five_led_wand_from_a_rendered_bag_to_the_calibration(tmp_path: Path) -> None:
    detected, drawn, both, argv, truth = _rendered_wand_take(tmp_path, "0,120,250,400,600", tuple("ABCDE"))
    errors = np.linalg.norm(detected.uv - drawn, axis=-1).max(axis=-1)[both]  # labels in order
    assert both.sum() > 300 and (errors > 0.5).mean() <= 0.005, np.sort(errors)[-5:]
    _calibrated_near_the_truth(tmp_path, argv, truth)


def test_a_room_bag_sent_as_jpeg_is_detected_from_the_rig_files_topics_with_its_masks(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "room"
    render = ["-q", "render", "mixed", "--room", "colour_jpeg", "--frames", "90", "--seed", "4", "--out", str(out)]
    assert main(render) == 0
    # image_transport's compressed topics only: the rig file names the raw topic, detect finds <topic>/compressed
    rig = yaml.safe_load((out / "cameras.yaml").read_text())
    for camera in rig["cameras"]:
        camera["image_topic"] = f"/{camera['name']}/image_raw"
    rig["cameras"][0]["mask"] = {"rectangles": [[0, 0, 20, 20]]}
    (out / "cameras.yaml").write_text(yaml.safe_dump(rig))
    detect = ["-q", "detect", str(out / "bag"), "--cameras", str(out / "cameras.yaml"), "--output", str(out / "o.csv")]
    assert main(detect) == 0
    printed = capsys.readouterr().out
    assert "cam0: 90 images (/cam0/image_raw/compressed)" in printed
    summary = yaml.safe_load((out / "o.detection.yaml").read_text())["cameras"]
    assert summary["cam0"]["images"] == 90 and summary["cam0"]["views"] > 30
    assert summary["cam0"]["mask"] == "o.masks/cam0.png" and (out / "o.masks" / "cam0.png").exists()
    assert summary["cam0"]["masked_fraction"] > 20 * 20 / (658 * 492)  # the rig file's rectangle at least
    detected = read_observations(out / "o.csv", ("cam0", "cam1"))
    drawn = read_observations(out / "drawn.csv", ("cam0", "cam1"))
    assert detected.stamps is not None and drawn.stamps is not None
    for c in range(2):  # every clearly visible view drawn was found, at its drawn pixels
        shown = np.isfinite(drawn.stamps[:, c])
        found = {round(s, 6): uv for s, uv in zip(detected.stamps[:, c], detected.uv[:, c], strict=True)}
        hits = [found.get(round(s, 6)) for s in drawn.stamps[shown, c]]
        close = [h is not None and np.all(np.isfinite(h)) and np.abs(h - d).max() < 1.0
                 for h, d in zip(hits, drawn.uv[shown, c], strict=True)]  # fmt: skip
        assert np.mean(close) >= 0.9, (c, np.mean(close))
    # the report shows what each camera saw
    calibrate_argv = ["-q", "calibrate", "--cameras", str(out / "cameras.yaml"), "--observations", str(out / "o.csv")]
    assert main([*calibrate_argv, "--output", str(out / "result.yaml")]) == 0
    report = ["-q", "report", "--result", str(out / "result.yaml"), "--cameras", str(out / "cameras.yaml")]
    assert main([*report, "--observations", str(out / "o.csv"), "--out", str(out / "report")]) == 0
    page = (out / "report" / "index.html").read_text()
    assert "What each camera saw" in page and "cam0 mask" in page


def test_a_mask_taken_from_a_stretch_of_a_bag(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "room"
    assert main(["-q", "render", "paper", "--room", "lamps_window", "--frames", "20", "--out", str(out)]) == 0
    masks = tmp_path / "masks"
    argv = ["-q", "mask", str(out / "bag"), "--cameras", str(out / "cameras.yaml"), "--out", str(masks)]
    assert main([*argv, "--seconds", "0.3"]) == 0
    printed = capsys.readouterr().out
    assert "mask: ../masks/cam0.png" in printed
    for name in ("cam0", "cam1"):  # the paper's two fisheyes
        picture = cv2.imread(str(masks / f"{name}.png"), cv2.IMREAD_GRAYSCALE)
        assert picture is not None and picture.shape == (480, 640) and picture.max() == 255
    assert main([*argv, "--start", "100"]) == 2
    assert "no image between 100 and 101 s" in capsys.readouterr().err


def test_a_full_disk_is_one_line_exit_2_and_leaves_no_result(
    simulated: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:  # type: ignore[no-untyped-def]
    import os
    import tempfile

    def full_disk(*args: object, **kwargs: object) -> tuple[int, str]:  # every staged output on a full device
        return os.open("/dev/full", os.O_WRONLY), str(tmp_path / "staged.tmp")

    monkeypatch.setattr(tempfile, "mkstemp", full_disk)
    output = tmp_path / "result.yaml"
    argv = ["calibrate", "--cameras", str(simulated / "cameras.yaml"), "--observations"]
    infos = tmp_path / "camera_info"
    argv += [str(simulated / "observations.csv"), "--camera-info-dir", str(infos), "--output", str(output)]
    assert main(["-q", *argv]) == 2
    assert capsys.readouterr().err.strip() == f"wand-calib: error: cannot write {output}: No space left on device"
    assert not output.exists() and not infos.exists()  # nothing left behind, not even the folder


def test_outputs_are_written_through_links_with_the_umask_and_to_a_pipe_directly(
    simulated: Path, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    import os
    import stat

    elsewhere = tmp_path / "kept" / "result.yaml"
    elsewhere.parent.mkdir()
    elsewhere.write_text("old\n")
    link = tmp_path / "result.yaml"
    link.symlink_to(elsewhere)
    argv = ["-q", "calibrate", "--cameras", str(simulated / "cameras.yaml")]
    argv += ["--observations", str(simulated / "observations.csv")]
    before = os.umask(0o022)
    try:
        assert main([*argv, "--output", str(link), "--camera-info-dir", str(tmp_path / "info")]) == 0
    finally:
        os.umask(before)
    assert link.is_symlink() and "reference_camera" in elsewhere.read_text()  # the target replaced, the link kept
    assert stat.S_IMODE(elsewhere.stat().st_mode) == 0o644  # (kept: the file was 0644 under this umask)
    assert stat.S_IMODE(next((tmp_path / "info").iterdir()).stat().st_mode) == 0o644  # new: the umask's
    import threading

    read, write = os.pipe()
    chunks: list[bytes] = []

    def drain() -> None:  # (the pipe's reader, as the next command of a shell pipeline)
        while chunk := os.read(read, 1 << 16):
            chunks.append(chunk)

    reader = threading.Thread(target=drain)
    reader.start()
    try:
        capsys.readouterr()
        assert main([*argv, "--output", f"/proc/self/fd/{write}"]) == 0  # what --output /dev/stdout is in a pipe
    finally:
        os.close(write)
        reader.join(10)
        os.close(read)
    assert b"reference_camera:" in b"".join(chunks)  # the YAML, whole, in the pipe
    captured = capsys.readouterr()
    assert "calibrated" not in captured.out and "calibrated" in captured.err  # the summary kept out of it


def test_a_library_write_that_fails_names_the_commands_output(
    simulated: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:  # type: ignore[no-untyped-def]
    import errno

    from wand_calib_ros.commands import report

    def no_space(args: object) -> int:  # as matplotlib's savefig on a full disk: an OSError without a file name
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(report, "run", no_space)
    out = tmp_path / "report"
    argv = ["report", "--result", "r.yaml", "--cameras", "c.yaml", "--observations", "o.csv", "--out", str(out)]
    assert main(argv) == 2
    assert capsys.readouterr().err.strip() == f"wand-calib: error: cannot write {out}: No space left on device"


def test_a_distortion_free_plumb_bob_start_says_its_principal_point_is_weak(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    # cam1 given a plumb_bob start without distortion (fixed: false): its tangential terms trade against the
    # principal point, which these views fix to several px only. The result says so, with a std that holds.
    rig = tmp_path / "rig"
    assert main(["-q", "simulate", "conventional", "--plumb-bob", "--seed", "2", "--out", str(rig)]) == 0
    truth = yaml.safe_load((rig / "truth.yaml").read_text())["cameras"]["cam1"]
    document = yaml.safe_load((rig / "cameras.yaml").read_text())
    start = {"K": truth["opencv"]["camera_matrix"], "D": [0.0] * 5, "distortion_model": "plumb_bob", "fixed": False}
    document["cameras"][1]["intrinsics"] = start
    (rig / "start.yaml").write_text(yaml.safe_dump(document))
    argv = ["-q", "calibrate", "--cameras", str(rig / "start.yaml"), "--observations", str(rig / "observations.csv")]
    assert main([*argv, "--output", str(tmp_path / "result.yaml")]) == 0
    assert "warning: cam1: its principal point is uncertain by +-" in capsys.readouterr().out
    camera = yaml.safe_load((tmp_path / "result.yaml").read_text())["cameras"]["cam1"]
    error = np.subtract(camera["principal_point"], truth["principal_point"])
    std = np.array([camera["std"]["u0"], camera["std"]["v0"]])
    assert np.all(np.abs(error) < 3 * std) and np.hypot(*std) > 5.0


def _xypts(path: Path, observations_csv: Path, names: tuple[str, ...], height: int) -> None:
    """A DLTdv 7 points file (bottom-left origin, 1-based pixels) of an observations CSV."""
    obs = read_observations(observations_csv, names)
    columns = [f"pt{p + 1}_cam{c + 1}_{a}" for c in range(len(names)) for p in range(3) for a in "XY"]
    lines = [",".join(columns)]
    for frame in obs.uv:
        cells = []
        for c in range(len(names)):
            for p in range(3):
                u, v = frame[c, p]
                cells += ["NaN", "NaN"] if not np.isfinite(u) else [f"{u + 1:.4f}", f"{height - v:.4f}"]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")


def test_every_command_writes_through_links_with_the_umask_and_refuses_or_fails_in_one_line(
    simulated: Path, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    import os
    import stat

    cameras, observations = str(simulated / "cameras.yaml"), str(simulated / "observations.csv")
    bag = tmp_path / "rec"
    assert main(["-q", "render", "paper", "--frames", "45", "--seed", "3", "--out", str(bag)]) == 0
    _xypts(tmp_path / "take_xypts.csv", simulated / "observations.csv", ("cam0", "cam1"), 480)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    def linked(name: str) -> Path:
        """An output that is a link to a file elsewhere (which exists, mode 0640)."""
        (elsewhere / name).write_text("old\n")
        (elsewhere / name).chmod(0o640)
        (tmp_path / name).symlink_to(elsewhere / name)
        return tmp_path / name

    result = tmp_path / "result.yaml"
    runs = {
        "calibrate": ["calibrate", "--cameras", cameras, "--observations", observations, "--output"],
        "detect": ["detect", str(bag / "bag"), "--cameras", str(bag / "cameras.yaml"), "--output"],
        "import": [
            "import",
            "--format",
            "xypts",
            "--origin",
            "bottom-left",
            "--points",
            str(tmp_path / "take_xypts.csv"),
            "--cameras",
            cameras,
            "--out",
        ],
    }
    before = os.umask(0o022)
    try:
        for command, argv in runs.items():
            output = linked(f"{command}.out")
            assert main(["-q", *argv, str(output)]) == 0, command
            assert output.is_symlink() and (elsewhere / output.name).read_text() != "old\n", command  # through it
            assert stat.S_IMODE((elsewhere / output.name).stat().st_mode) == 0o640, command  # its mode kept
            capsys.readouterr()
            assert main(["-q", *argv, "/dev/full"]) == 2, command  # a device: written directly, never replaced
            assert (
                capsys.readouterr().err.strip() == "wand-calib: error: cannot write /dev/full: No space left on device"
            )
            assert stat.S_ISCHR(Path("/dev/full").stat().st_mode)
        assert main(["-q", *runs["calibrate"], str(result), "--camera-info-dir", str(tmp_path / "info")]) == 0
        exported, report = tmp_path / "exported", tmp_path / "report"
        assert main(["-q", "export", "--result", str(result), "--format", "opencv", "--out", str(exported)]) == 0
        report_argv = ["report", "--result", str(result), "--cameras", cameras, "--observations", observations]
        assert main(["-q", *report_argv, "--out", str(report)]) == 0
        made = [result, *(tmp_path / "info").iterdir(), *exported.iterdir(), *report.iterdir()]
        made += [tmp_path / "detect.detection.yaml"] if (tmp_path / "detect.detection.yaml").exists() else []
        assert len(made) >= 8 and {stat.S_IMODE(p.stat().st_mode) for p in made} == {0o644}  # new: the umask's
    finally:
        os.umask(before)


def test_help_and_argument_errors_answer_before_any_heavy_import() -> None:
    """``wand-calib --help``, a command's ``--help`` and an argument error import no solver, image, bag, plot or
    YAML library (each command imports what it uses when it runs): a fresh interpreter's modules after each."""
    import subprocess
    import sys

    probe = (
        "import sys\n"
        "from wand_calib_ros.cli import main\n"
        "for argv in (['--help'], ['calibrate', '--help'], ['import', '--help'], ['calibrate', '--cameras']):\n"
        "    try:\n"
        "        main(argv)\n"
        "    except SystemExit:\n"
        "        pass\n"
        "heavy = {'scipy', 'cv2', 'rosbags', 'matplotlib', 'yaml', 'pandas', 'h5py', 'PIL'}\n"
        "print(sorted({name.split('.')[0] for name in sys.modules} & heavy))\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.strip().splitlines()[-1] == "[]"


def test_a_camera_whose_clock_is_seconds_ahead_is_lined_up_and_said(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from dataclasses import replace

    from wand_calib_ros.io.rig_yaml import save_rig
    from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
    from wand_calib_ros.sim.scenarios import SCENARIOS

    scenario = SCENARIOS["paper3"]()
    options = TakeOptions()
    clocks = options.clocks(3, np.random.default_rng(2))
    clocks = (clocks[0], replace(clocks[1], latency_s=clocks[1].latency_s + 2.3), clocks[2])  # cam1 2.3 s ahead
    takes = film(scenario, take_trajectory(scenario, options, np.random.default_rng(1)), clocks, 20.0,
                 np.random.default_rng(3))  # fmt: skip
    sim = tmp_path / "take"
    sim.mkdir()
    save_rig(scenario.rig, sim / "cameras.yaml")
    write_observations(
        observe(scenario.rig.camera_names, takes, 0.25, np.random.default_rng(4)), sim / "observations.csv"
    )
    assert _calibrate(sim, tmp_path) == 0
    out = capsys.readouterr().out
    assert out.count("found from the wand's motion") == 1 and "clock: cam1's clock is 2.30" in out
    result = yaml.safe_load((tmp_path / "result.yaml").read_text())
    assert result["timing"]["clocks"] == [line.split("clock: ")[1] for line in out.splitlines() if "clock: " in line]
    offsets = {name: entry["time_offset_s"] for name, entry in result["cameras"].items()}
    truth = {f"cam{c}": clock.latency_s for c, clock in enumerate(clocks)}
    for name, offset in offsets.items():  # the whole offset: the seconds and the sub-frame part
        assert abs(offset - (truth[name] - truth[result["reference_camera"]])) < 0.001
