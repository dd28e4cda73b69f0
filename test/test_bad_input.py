"""The bad-input catalogue of the command line: every case ends with exit code 2 and one line.

Each case spoils one input of a good simulated run (or gives one bad option) and asserts the exit
code, that stderr is a single ``wand-calib: error:`` line naming what is wrong (file, row, camera,
option), that no input file changed and that no output was written. Buffer cases (torn writes,
resets) are in ``test/collection/test_recovery.py``; node parameter cases in ``test/nodes``.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml

from wand_calib_ros.cli import main

Spoil = Callable[[Path], list[str]]  # given a folder holding a good run's files, the argv of a bad run

PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(256))


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("good")
    assert main(["-q", "simulate", "paper", "--seed", "3", "--noise", "0.5", "--out", str(folder)]) == 0
    result = ["-q", "calibrate", "--cameras", str(folder / "cameras.yaml"), "--observations"]
    assert main([*result, str(folder / "observations.csv"), "--output", str(folder / "result.yaml")]) == 0
    return folder


def _calibrate(
    folder: Path, *extra: str, cameras: str = "cameras.yaml", observations: str = "observations.csv"
) -> list[str]:
    return [
        "calibrate",
        "--cameras",
        str(folder / cameras),
        "--observations",
        str(folder / observations),
        "--output",
        str(folder / "out" / "result.yaml"),
        *extra,
    ]


def _rewrite(folder: Path, name: str, edit: Callable[[str], str]) -> Path:
    """A spoilt copy of ``name`` as ``bad-<name>``."""
    path = folder / f"bad-{name}"
    path.write_text(edit((folder / name).read_text()))
    return path


def _observations(edit: Callable[[str], str], *extra: str) -> Spoil:
    def spoil(folder: Path) -> list[str]:
        _rewrite(folder, "observations.csv", edit)
        return _calibrate(folder, *extra, observations="bad-observations.csv")

    return spoil


def _cameras(edit: Callable[[str], str]) -> Spoil:
    def spoil(folder: Path) -> list[str]:
        _rewrite(folder, "cameras.yaml", edit)
        return _calibrate(folder, cameras="bad-cameras.yaml")

    return spoil


def _bytes(name: str, content: bytes) -> Spoil:
    def spoil(folder: Path) -> list[str]:
        (folder / f"bad-{name}").write_bytes(content)
        if name == "cameras.yaml":
            return _calibrate(folder, cameras="bad-cameras.yaml")
        return _calibrate(folder, observations="bad-observations.csv")

    return spoil


def _row(n: int, edit: Callable[[list[str]], list[str]]) -> Callable[[str], str]:
    """Edit the cells of line ``n`` (1 = header) of a CSV text."""

    def change(text: str) -> str:
        lines = text.splitlines()
        lines[n - 1] = ",".join(edit(lines[n - 1].split(",")))
        return "\n".join(lines) + "\n"

    return change


def _cell(n: int, column: int, value: str) -> Callable[[str], str]:
    return _row(n, lambda cells: [*cells[:column], value, *cells[column + 1 :]])


def _with_stamps(edit: Callable[[list[str], int], str] | None = None) -> Callable[[str], str]:
    """Add a stamp column (30 fps, both cameras at the frame's time); ``edit(cells, line)`` may change one."""

    def change(text: str) -> str:
        lines = text.splitlines()
        out = [lines[0] + ",stamp"]
        for k, line in enumerate(lines[1:], start=2):
            cells = line.split(",")
            stamp = f"{1.7e9 + int(cells[0]) / 30.0:.6f}"
            out.append(line + "," + (edit(cells, k) if edit is not None else stamp))
        return "\n".join(out) + "\n"

    return change


def _stamp_at(line: int, value: str) -> Callable[[str], str]:
    return _with_stamps(lambda cells, k: value if k == line else f"{1.7e9 + int(cells[0]) / 30.0:.6f}")


def _yaml_replace(old: str, new: str, count: int = 1) -> Callable[[str], str]:
    def change(text: str) -> str:
        assert old in text, old
        return text.replace(old, new, count)

    return change


def _argv(*argv: str) -> Spoil:
    return lambda folder: [a.format(folder=folder) for a in argv]


def _output_in_a_file(folder: Path) -> list[str]:
    (folder / "plain").write_text("a file\n")
    argv = _calibrate(folder)
    argv[argv.index("--output") + 1] = str(folder / "plain" / "result.yaml")
    return argv


def _output_is_a_folder(folder: Path) -> list[str]:
    argv = _calibrate(folder)
    argv[argv.index("--output") + 1] = str(folder)
    return argv


def _camera_info_in_a_file(folder: Path) -> list[str]:
    (folder / "plain").write_text("a file\n")
    return _calibrate(folder, "--camera-info-dir", str(folder / "plain"))


def _report(result: Callable[[Path], Path]) -> Spoil:
    def spoil(folder: Path) -> list[str]:
        return [
            "report",
            "--result",
            str(result(folder)),
            "--observations",
            str(folder / "observations.csv"),
            "--cameras",
            str(folder / "cameras.yaml"),
            "--out",
            str(folder / "out" / "report"),
        ]

    return spoil


def _detect(topic: str) -> Spoil:
    def spoil(folder: Path) -> list[str]:
        output = str(folder / "out" / "o.csv")
        return [
            "detect",
            str(folder / "no-bag"),
            "--cameras",
            str(folder / "cameras.yaml"),
            "--topic",
            topic,
            "--output",
            output,
        ]

    return spoil


def _binary_result(folder: Path) -> Path:
    (folder / "bad-result.yaml").write_bytes(PNG)
    return folder / "bad-result.yaml"


def _other_cameras_result(folder: Path) -> Path:
    return _rewrite(folder, "result.yaml", lambda text: text.replace("cam1", "camX"))


def _floor(write: Callable[[Path], str]) -> Spoil:
    """A calibration with ``--floor`` what ``write(folder)`` gives (a text, or a file it wrote)."""
    return lambda folder: _calibrate(folder, "--floor", write(folder))


def _floor_file(content: bytes) -> Callable[[Path], str]:
    def write(folder: Path) -> str:
        (folder / "floor.txt").write_bytes(content)
        return str(folder / "floor.txt")

    return write


def _given_intrinsics(edit: Callable[[dict], dict]) -> Spoil:  # type: ignore[type-arg]
    """cam1 given the true intrinsics of truth.yaml (K, D as OpenCV fisheye), as ``edit`` spoils them."""

    def spoil(folder: Path) -> list[str]:
        truth = yaml.safe_load((folder / "truth.yaml").read_text())["cameras"]["cam1"]["opencv"]
        given = {"K": truth["camera_matrix"], "D": truth["distortion"], "distortion_model": "equidistant"}
        document = yaml.safe_load((folder / "cameras.yaml").read_text())
        document["cameras"][1]["intrinsics"] = edit(given)
        (folder / "bad-cameras.yaml").write_text(yaml.safe_dump(document))
        return _calibrate(folder, cameras="bad-cameras.yaml")

    return spoil


def _plumb_bob_given(p1: float, p2: float) -> Spoil:
    """A conventional rig of plumb_bob lenses, cam1 given its true K and D but for tangential terms p1, p2."""

    def spoil(folder: Path) -> list[str]:
        rig = folder / "plumb_bob"
        assert main(["-q", "simulate", "conventional", "--plumb-bob", "--seed", "2", "--out", str(rig)]) == 0
        truth = yaml.safe_load((rig / "truth.yaml").read_text())["cameras"]["cam1"]["opencv"]
        D = [*truth["distortion"][:2], p1, p2, *truth["distortion"][4:]]
        document = yaml.safe_load((rig / "cameras.yaml").read_text())
        document["cameras"][1]["intrinsics"] = {"K": truth["camera_matrix"], "D": D, "distortion_model": "plumb_bob"}
        (rig / "bad-cameras.yaml").write_text(yaml.safe_dump(document))
        return _calibrate(rig, cameras="bad-cameras.yaml")

    return spoil


def _scaled_focal(given: dict) -> dict:  # type: ignore[type-arg]
    k = np.array(given["K"], dtype=float)
    k[0, 0] *= 1.25
    k[1, 1] *= 1.25
    return {**given, "K": k.tolist()}


def _camera_info(text: str) -> Spoil:
    """cam0's intrinsics from a camera_info file of ``text``."""

    def spoil(folder: Path) -> list[str]:
        (folder / "cam0-info.yaml").write_text(text)
        _rewrite(
            folder,
            "cameras.yaml",
            _yaml_replace("max_view_angle_deg: 92.5", "max_view_angle_deg: 92.5\n  intrinsics: cam0-info.yaml"),
        )
        return _calibrate(folder, cameras="bad-cameras.yaml")

    return spoil


INFO = (
    "image_width: 640\nimage_height: 480\n"
    "camera_matrix: {rows: 3, cols: 3, data: [356, 0, 310, 0, 356, 250, 0, 0, 1]}\n"
    "distortion_model: equidistant\ndistortion_coefficients: {rows: 1, cols: 4, data: [0, 0, 0, 0]}\n"
)


def _result_command(command: str, result: Callable[[Path], Path]) -> Spoil:
    """``export`` (opencv) or ``refine`` with a spoilt result."""

    def spoil(folder: Path) -> list[str]:
        path = str(result(folder))
        if command == "export":
            return ["export", "--result", path, "--format", "opencv", "--out", str(folder / "out" / "export")]
        return ["refine", "--cameras", str(folder / "cameras.yaml"), "--result", path, "--observations",
                str(folder / "observations.csv"), "--output", str(folder / "out" / "refined.yaml")]  # fmt: skip

    return spoil


def _result_text(edit: Callable[[str], str]) -> Callable[[Path], Path]:
    return lambda folder: _rewrite(folder, "result.yaml", edit)


def _result_document(edit: Callable[[dict], None]) -> Callable[[Path], Path]:  # type: ignore[type-arg]
    def write(folder: Path) -> Path:
        document = yaml.safe_load((folder / "result.yaml").read_text())
        edit(document)
        (folder / "bad-result.yaml").write_text(yaml.safe_dump(document))
        return folder / "bad-result.yaml"

    return write


def _refine_views(keep: Callable[[list[str]], bool]) -> Spoil:
    """``refine`` on the rows of observations.csv that ``keep`` keeps (new views of the calibrated rig)."""

    def spoil(folder: Path) -> list[str]:
        lines = (folder / "observations.csv").read_text().splitlines()
        rows = [lines[0], *(line for line in lines[1:] if keep(line.split(",")))]
        (folder / "bad-observations.csv").write_text("\n".join(rows) + "\n")
        result, views = str(folder / "result.yaml"), str(folder / "bad-observations.csv")
        return ["refine", "--cameras", str(folder / "cameras.yaml"), "--result", result, "--observations", views,
                "--output", str(folder / "out" / "r.yaml")]  # fmt: skip

    return spoil


def _other_rig(folder: Path) -> list[str]:
    """``report`` of this rig's result on another simulated rig (the same camera names and image sizes)."""
    other = folder / "other"
    assert main(["-q", "simulate", "paper", "--seed", "8", "--true-focal", "2.3", "--out", str(other)]) == 0
    return ["report", "--result", str(folder / "result.yaml"), "--observations", str(other / "observations.csv"),
            "--cameras", str(other / "cameras.yaml"), "--out", str(folder / "out" / "report")]  # fmt: skip


def _drop_metrics(document: dict) -> None:  # type: ignore[type-arg]
    del document["metrics"]


def _scale_rotation(document: dict) -> None:  # type: ignore[type-arg]
    document["cameras"]["cam1"]["rotation"][0] = [2 * v for v in document["cameras"]["cam1"]["rotation"][0]]


def _nan_rotation(document: dict) -> None:  # type: ignore[type-arg]
    document["cameras"]["cam1"]["rotation"][0][0] = float("nan")


def _no_cameras(document: dict) -> None:  # type: ignore[type-arg]
    document["cameras"] = {}


def _unknown_reference(document: dict) -> None:  # type: ignore[type-arg]
    document["reference_camera"] = "cam9"


CASES: dict[str, tuple[Spoil, str]] = {
    # cameras.yaml
    "cameras missing": (lambda f: _calibrate(f, cameras="none.yaml"), "none.yaml: cannot read: No such file"),
    "cameras binary": (_bytes("cameras.yaml", PNG), "bad-cameras.yaml: not UTF-8 text"),
    "cameras not YAML": (_cameras(lambda t: "wand: [1, 2\ncameras: {"), "bad-cameras.yaml: not valid YAML"),
    "cameras empty": (_cameras(lambda t: ""), "bad-cameras.yaml"),
    "cameras a list": (_cameras(lambda t: "- 1\n- 2\n"), "bad-cameras.yaml"),
    "wand length negative": (_cameras(_yaml_replace("L1: 400.0", "L1: -400.0")), "L1"),
    "wand length text": (_cameras(_yaml_replace("L1: 400.0", "L1: long")), "L1"),
    "wand missing": (_cameras(_yaml_replace("wand: {L1: 400.0, L2: 200.0}\n", "")), "wand"),
    "camera without image_size": (_cameras(_yaml_replace("  image_size: [640, 480]\n", "")), "image_size"),
    "image_size of one number": (_cameras(_yaml_replace("image_size: [640, 480]", "image_size: [640]")), "image_size"),
    "focal zero": (_cameras(_yaml_replace("nominal_focal_mm: 1.8", "nominal_focal_mm: 0")), "nominal_focal_mm"),
    "pixel size negative": (
        _cameras(_yaml_replace("pixel_size_um: [5.6, 5.6]", "pixel_size_um: [-5.6, 5.6]")),
        "pixel_size_um",
    ),
    "duplicate camera name": (_cameras(_yaml_replace("name: cam1", "name: cam0")), "cam0"),
    "one camera only": (_cameras(lambda t: t[: t.index("- name: cam1")]), "unknown camera 'cam1'; the rig has cam0"),
    "floor tool on one line": (
        _cameras(lambda t: t + "floor: {points_mm: [[0, 0, 0], [500, 0, 0], [250, 0, 0]]}\n"),
        "floor points_mm lie on one line",
    ),
    "floor tool of more markers than the wand": (
        _cameras(lambda t: t + "floor: {points_mm: [[0, 0, 0], [500, 0, 0], [0, 300, 0], [500, 300, 0]]}\n"),
        "floor points_mm has 4 markers",
    ),
    "floor tool not points": (_cameras(lambda t: t + "floor: {points_mm: [0, 500]}\n"), "floor points_mm must be"),
    "floor tool unknown key": (_cameras(lambda t: t + "floor: {points: [[0, 0, 0]]}\n"), "'floor' must be a mapping"),
    # observations CSV
    "observations missing": (lambda f: _calibrate(f, observations="none.csv"), "none.csv: cannot read: No such file"),
    "observations binary": (_bytes("observations.csv", PNG), "bad-observations.csv: not UTF-8 text"),
    "observations empty": (_bytes("observations.csv", b""), "bad-observations.csv: empty file"),
    "header only": (_observations(lambda t: t.splitlines()[0] + "\n"), "no observations after the header"),
    "column missing": (_observations(_row(1, lambda c: c[:4])), "row 1: missing column(s) v"),
    "row too short": (_observations(_row(5, lambda c: c[:3])), "row 5: expected at least 5 columns"),
    "frame not an integer": (_observations(_cell(4, 0, "1.5")), "row 4: frame must be an integer"),
    "frame beyond 64 bits": (
        _observations(_cell(4, 0, "100000000000000000000")),
        "row 4: frame 100000000000000000000 is out of range (a frame id is a 64-bit integer)",
    ),
    "point D": (_observations(_cell(3, 2, "D")), "row 3: point must be A, B or C"),
    "decimal comma": (_observations(_cell(6, 3, "12,5")), "row 6: 6 cells where the header has 5 (a decimal comma?"),
    "v text": (_observations(_cell(6, 4, "high")), "row 6: u, v must be numbers"),
    "u NaN": (_observations(_cell(7, 3, "nan")), "row 7: camera 'cam1' frame 0 point C: u, v must be finite"),
    "v infinite": (_observations(_cell(7, 4, "inf")), "row 7"),
    "unknown camera": (_observations(_cell(8, 1, "cam7")), "row 8: unknown camera 'cam7'"),
    "point twice": (_observations(_row(3, lambda c: [c[0], c[1], "A", *c[3:]])), "appears twice"),
    "NUL byte in a row": (_bytes("observations.csv", b"frame,camera,point,u,v\n0,cam0,A,1,\x00\n"), "row 2"),
    "stamp not a number": (
        _observations(_stamp_at(9, "noon")),
        "row 9: camera 'cam0' frame 1: stamp must be a number of seconds",
    ),
    "stamp NaN": (_observations(_stamp_at(9, "nan")), "row 9"),
    "stamps in nanoseconds": (
        _observations(_with_stamps(lambda c, k: str(1_700_000_000_000_000_000 + int(c[0]) * 33_333_333))),
        "nanoseconds",
    ),
    "stamps of one image differ": (
        _observations(_stamp_at(3, "1700000000.5")),
        "the points of one image share its stamp",
    ),
    "stamps going backwards": (
        _observations(_with_stamps(lambda c, k: f"{1.7e9 - int(c[0]) / 30.0:.6f}")),
        "cam0",
    ),
    "stamps repeating": (_observations(_with_stamps(lambda c, k: "1700000000.0")), "cam0"),
    "point outside the image": (_observations(_cell(5, 3, "700.5")), "row 5: camera 'cam1' frame 0 point A: (700.5,"),
    # the rig against the views (plausibility)
    "wand in metres": (_cameras(_yaml_replace("L1: 400.0, L2: 200.0", "L1: 0.4, L2: 0.2")), "in metres or cm?"),
    "wand segments declared equal": (
        _cameras(_yaml_replace("L1: 400.0, L2: 200.0", "L1: 300.0, L2: 300.0")),
        "L1/L2 = 300/300",
    ),
    "wand segments swapped": (_cameras(_yaml_replace("L1: 400.0, L2: 200.0", "L1: 200.0, L2: 400.0")), "swapped"),
    "focal 1000 mm for a fisheye": (
        _cameras(_yaml_replace("nominal_focal_mm: 1.8", "nominal_focal_mm: 1000")),
        "camera 'cam0': nominal_focal_mm 1000 with max_view_angle_deg 92.5",
    ),
    "one camera never sees the whole wand": (
        _observations(lambda t: "".join(line + "\n" for line in t.splitlines() if ",cam1,C," not in line)),
        "camera(s) cam1 never see the whole wand",
    ),
    # options
    "max placements 1": (lambda f: _calibrate(f, "--max-placements", "1"), "--max-placements must be at least 2"),
    "reference camera unknown": (lambda f: _calibrate(f, "--reference", "cam9"), "cam9"),
    "offsets of independent placements": (lambda f: _calibrate(f, "--time-offsets", "estimate"), "time offsets"),
    "too few placements": (_observations(lambda t: "\n".join(t.splitlines()[:40]) + "\n"), "placements"),
    # outputs (checked before the solve)
    "output is a folder": (_output_is_a_folder, "it is a folder; give a file name"),
    "output's folder is a file": (_output_in_a_file, "plain is a file, not a folder"),
    "camera_info folder is a file": (_camera_info_in_a_file, "plain is a file, not a folder"),
    # simulate
    "simulate noise negative": (
        _argv("simulate", "paper", "--noise", "-1", "--out", "{folder}/out"),
        "--noise must be >= 0",
    ),
    "simulate outliers 1.5": (_argv("simulate", "paper", "--outliers", "1.5", "--out", "{folder}/out"), "--outliers"),
    "simulate no placements": (
        _argv("simulate", "paper", "--placements", "0", "--out", "{folder}/out"),
        "--placements",
    ),
    "simulate take of 0 s": (_argv("simulate", "paper3", "--take", "0", "--out", "{folder}/out"), "--take"),
    # report
    "report result missing": (_report(lambda f: f / "none.yaml"), "none.yaml: cannot read"),
    "report result binary": (_report(_binary_result), "bad-result.yaml: not UTF-8 text"),
    "report result of other cameras": (_report(_other_cameras_result), "cam1"),
    "report result with a negative focal": (
        _report(lambda f: _rewrite(f, "result.yaml", lambda t: t.replace("k: [", "k: [-", 1))),
        "bad-result.yaml: not a wand_calib_ros result file: camera 'cam0': k1 and m must be positive",
    ),
    "report result not a result": (_report(lambda f: f / "cameras.yaml"), "not a wand_calib_ros result file"),
    # detect
    "detect topic with an unknown field": (_detect("/{cam}/image_raw"), "{cam} is not a field"),
    "detect topic with a broken brace": (_detect("/{camera/image_raw"), "--topic '/{camera/image_raw'"),
    "detect topic shared by the cameras": (_detect("/cam0/image_raw"), "gives every camera the same topic"),
    "detect bag missing": (_detect("/{camera}/image_raw"), "no-bag"),
    "detect sync tolerance NaN": (
        lambda f: [*_detect("/{camera}/image_raw")(f), "--sync-tolerance-ms", "nan"],
        "--sync-tolerance-ms must be a finite number, got nan",
    ),
    "detect sync tolerance negative": (
        lambda f: [*_detect("/{camera}/image_raw")(f), "--sync-tolerance-ms", "-3"],
        "--sync-tolerance-ms must be 0 or more",
    ),
    "simulate noise infinite": (
        _argv("simulate", "paper", "--noise", "inf", "--out", "{folder}/out"),
        "--noise must be a finite number, got inf",
    ),
    "simulate a frame rate NaN": (
        _argv("simulate", "paper3", "--take", "2", "--fps", "30", "nan", "30", "--out", "{folder}/out"),
        "--fps must be a finite number, got nan",
    ),
    # the surfaces added since (issue 25): --floor
    "floor file line not a frame": (
        _floor(_floor_file(b"12\nabc\n")),
        "floor.txt, row 2: expected a frame id, got 'abc'",
    ),
    "floor empty text": (_floor(lambda f: ""), "--floor '' names no frame"),
    "floor file empty": (_floor(_floor_file(b"")), "floor.txt: names no frame"),
    "floor file missing": (_floor(lambda f: str(f / "floor_frames.txt")), "floor_frames.txt: no such file"),
    "floor a folder": (_floor(lambda f: str(f)), "is a folder, not a floor_frames.txt"),
    "floor file binary": (_floor(_floor_file(PNG)), "floor.txt: not UTF-8 text"),
    "floor frames of the waved take": (_floor(lambda f: "0-29"), "the wand was not lying still"),
    # the wand and given intrinsics
    "wand L1 L2 and points_mm": (
        _cameras(_yaml_replace("wand: {L1: 400.0, L2: 200.0}", "wand: {L1: 200, L2: 400, points_mm: [0, 400, 600]}")),
        "wand: give L1 and L2 or points_mm, not both",
    ),
    "given focal 25 % too large": (
        _given_intrinsics(_scaled_focal),
        "camera 'cam1': the views disagree with its given intrinsics",
    ),
    "given tangential terms of 0.01": (
        _plumb_bob_given(0.01, 0.01),
        "its given tangential terms p1 0.01, p2 0.01 are larger than a lens's (a few thousandths)",
    ),
    "given principal point outside the image": (
        _given_intrinsics(lambda g: {**g, "K": [[g["K"][0][0], 0, 900], [0, g["K"][1][1], 250], [0, 0, 1]]}),
        "camera 'cam1' intrinsics: the principal point (900, 250) is outside its 640 x 480 image",
    ),
    "given D with a NaN": (
        _given_intrinsics(lambda g: {**g, "D": [float("nan"), 0, 0, 0]}),
        "intrinsics D must be a finite number, got nan",
    ),
    "camera_info not YAML": (
        _camera_info(INFO.replace("image_height: 480", "image_height: [480")),
        "cam0-info.yaml: not valid YAML",
    ),
    "camera_info with a K of 2 numbers": (
        _camera_info(INFO.replace("[356, 0, 310, 0, 356, 250, 0, 0, 1]", "[356, 356]")),
        "cam0-info.yaml: camera_matrix data must be a list of 9 numbers, got [356, 356]",
    ),
    "camera_info with a short K": (
        _camera_info(INFO.replace("0, 0, 1]}", "0]}")),
        "cam0-info.yaml: camera_matrix data must be a list of 9 numbers",
    ),
    # export
    "export of a result without cameras": (
        _result_command("export", _result_document(_no_cameras)),
        "bad-result.yaml: no cameras",
    ),
    "export with an unknown reference camera": (
        _result_command("export", _result_document(_unknown_reference)),
        "bad-result.yaml: its reference_camera 'cam9' is not one of its cameras (cam0, cam1)",
    ),
    "export of a rotation that is not one": (
        _result_command("export", _result_document(_scale_rotation)),
        "bad-result.yaml: camera 'cam1': its rotation is not a rotation matrix",
    ),
    "export of a truncated result": (
        _result_command("export", _result_text(lambda t: t[: len(t) // 3])),
        "bad-result.yaml: not valid YAML",
    ),
    "export of an empty result": (_result_command("export", _result_text(lambda t: "")), "bad-result.yaml: empty"),
    "export of cameras.yaml": (
        _result_command("export", lambda f: f / "cameras.yaml"),
        "cameras.yaml: not a wand_calib_ros result file (a rig description?",
    ),
    "export of an OpenCV FileStorage": (
        _result_command("export", _result_text(lambda t: "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n")),
        "bad-result.yaml: an OpenCV FileStorage file, not a wand_calib_ros result",
    ),
    "export of an anipose TOML": (
        _result_command("export", _result_text(lambda t: '[cam_0]\nname = "cam0"\nsize = [640, 480]\n')),
        "(a TOML file? give the result YAML wand-calib wrote)",
    ),
    # refine
    "refine of a result without metrics": (
        _result_command("refine", _result_document(_drop_metrics)),
        "bad-result.yaml: no metrics sigma_px",
    ),
    "refine of a NaN rotation": (
        _result_command("refine", _result_document(_nan_rotation)),
        "bad-result.yaml: camera 'cam1': its rotation must be finite numbers",
    ),
    "refine on 5 placements": (
        _refine_views(lambda cells: int(cells[0]) < 5),
        "only 5 placements show the whole wand to two cameras",
    ),
    "refine on one camera's rows": (
        _refine_views(lambda cells: cells[1] == "cam0"),
        "only 0 placements show the whole wand",
    ),
    # report
    "report of another rig with the same camera names": (_other_rig, "does not fit these observations"),
    "report out an existing file": (
        lambda f: [*_report(lambda g: g / "result.yaml")(f)[:-1], str(f / "cameras.yaml")],
        "cameras.yaml: it is a file; give a folder",
    ),
    # import
    "import 0-based header": (
        lambda f: (
            (f / "p.csv").write_text("pt0_cam0_x,pt0_cam0_y\n1,2\n")
            and [
                "import",
                "--format",
                "xypts",
                "--points",
                str(f / "p.csv"),
                "--cameras",
                str(f / "cameras.yaml"),
                "--out",
                str(f / "out" / "o.csv"),
            ]
        ),
        "markers and cameras count from 1",
    ),
}


def _digests(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_and_exit_code_2(
    good: Path, tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "run"
    shutil.copytree(good, folder)
    spoil, expected = CASES[case]
    argv = spoil(folder)
    before = _digests(folder)
    capsys.readouterr()
    code = main(["-q", *argv])
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("wand-calib: error:")]
    assert code == 2, err
    assert len(errors) == 1 and expected in errors[0], err
    assert "Traceback" not in err
    assert _only_own_lines(err), err  # the error in one line: no continuation
    for python in ("np.float64", "NoneType", "object has no attribute", "subscriptable", "_frame_ranges", "Errno"):
        assert python not in errors[0], err
    assert _digests(folder) == before  # no input changed
    assert not (folder / "out").exists() or not any(p.is_file() for p in (folder / "out").rglob("*"))


def _only_own_lines(err: str) -> bool:
    """Whether stderr holds the package's lines only (each ``wand-calib: ...``) and Python's warnings
    (a ``...Warning: ...`` line, then its indented source line)."""
    lines = err.splitlines()
    for i, line in enumerate(lines):
        warning = "Warning: " in line or (i > 0 and "Warning: " in lines[i - 1] and line.startswith("  "))
        if not (line.startswith("wand-calib: ") or warning):
            return False
    return True


def test_the_catalogue_is_broad() -> None:
    assert len(CASES) >= 50


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_a_read_only_output_folder_is_refused_before_the_solve(good: Path, tmp_path: Path) -> None:
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        argv = _calibrate(good)
        argv[argv.index("--output") + 1] = str(folder / "result.yaml")
        assert main(["-q", *argv]) == 2
    finally:
        folder.chmod(0o700)
