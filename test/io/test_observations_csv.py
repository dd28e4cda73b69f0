"""Observations CSV: round trip and row-precise errors."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.observations_csv import read_observations, write_observations

HEADER = "frame,camera,point,u,v\n"
ROWS = "0,cam0,A,1.5,2.5\n0,cam0,B,3,4\n0,cam0,C,5,6\n0,cam1,A,7,8\n2,cam1,C,9,10\n"


def test_write_read_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 640, size=(20, 3, 3, 2))
    uv[3, 1] = np.nan
    uv[5, 2, 1] = np.nan
    observations = WandObservations(np.arange(20) * 3, ("a", "b", "c"), uv)
    write_observations(observations, tmp_path / "obs.csv")
    back = read_observations(tmp_path / "obs.csv", ("a", "b", "c"))
    assert back.camera_names == ("a", "b", "c")
    assert np.array_equal(back.frames, observations.frames)
    assert np.allclose(back.uv, uv, atol=1e-6, equal_nan=True)


def test_extra_columns_and_column_order_are_accepted(tmp_path: Path) -> None:
    path = tmp_path / "obs.csv"
    path.write_text("v,quality,u,point,camera,frame\n2.5,0.9,1.5,A,cam0,7\n")
    obs = read_observations(path)
    assert obs.frames.tolist() == [7] and obs.uv[0, 0, 0].tolist() == [1.5, 2.5]


def test_missing_points_are_nan_and_frames_sorted(tmp_path: Path) -> None:
    path = tmp_path / "obs.csv"
    path.write_text(HEADER + "5,cam0,A,1,1\n" + ROWS)
    obs = read_observations(path, ("cam0", "cam1"))
    assert obs.frames.tolist() == [0, 2, 5]
    assert obs.complete.tolist() == [[True, False], [False, False], [False, False]]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("frame,camera,u,v\n0,cam0,1,2\n", "row 1: missing column\\(s\\) point"),
        (HEADER + "0,cam0,A,nan,2\n", "row 2: camera 'cam0' frame 0 point A: u, v must be finite"),
        (HEADER + "0,cam0,A,1,2\n1,cam9,A,1,2\n", "row 3: unknown camera 'cam9'; the rig has cam0, cam1"),
        (HEADER + "0,cam0,D,1,2\n", "row 2: point must be A, B or C"),
        (HEADER + "x,cam0,A,1,2\n", "row 2: frame must be an integer"),
        (HEADER + "0,cam0,A,one,2\n", "row 2: u, v must be numbers"),
        (HEADER + "0,cam0,A,1,2\n0,cam0,A,1,2\n", "row 3: camera 'cam0' frame 0 point A appears twice"),
        (HEADER + "0,cam0\n", "row 2: expected at least 5 columns"),
        (HEADER, "no observations"),
        ("", "empty file"),
    ],
)
def test_bad_files_name_file_row_and_problem(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "obs.csv"
    path.write_text(text)
    with pytest.raises(FormatError, match=message) as error:
        read_observations(path, ("cam0", "cam1"))
    assert str(path) in str(error.value)


STAMPED = "frame,camera,point,u,v,stamp\n"


def test_stamps_round_trip_to_the_nanosecond(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    uv = rng.uniform(0, 640, size=(6, 2, 3, 2))
    stamps = 1_700_000_000.0 + np.arange(6)[:, None] / 30.0 + np.array([0.0, 0.0123456789])
    uv[2, 1] = np.nan
    stamps[2, 1] = np.nan
    write_observations(WandObservations(np.arange(6), ("a", "b"), uv, stamps), tmp_path / "obs.csv")
    back = read_observations(tmp_path / "obs.csv", ("a", "b"))
    assert back.stamps is not None
    assert np.allclose(back.stamps, stamps, rtol=0, atol=1e-9, equal_nan=True)
    assert b"\r" not in (tmp_path / "obs.csv").read_bytes()


def test_without_a_stamp_column_there_are_no_stamps(tmp_path: Path) -> None:
    path = tmp_path / "obs.csv"
    path.write_text(HEADER + ROWS)
    assert read_observations(path, ("cam0", "cam1")).stamps is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (STAMPED + "0,cam0,A,1,2,\n", "row 2: camera 'cam0' frame 0: stamp must be a number of seconds, got ''"),
        (STAMPED + "0,cam0,A,1,2,nan\n", "row 2: camera 'cam0' frame 0: stamp must be finite"),
        (STAMPED + "0,cam0,A,1,2,1700000000123456789\n", "row 2: .*not in seconds \\(nanoseconds\\?\\)"),
        (STAMPED + "0,cam0,A,1,2,10.0\n0,cam0,B,3,4,10.5\n", "row 3: camera 'cam0' frame 0: stamp 10.5 differs"),
        (STAMPED + "0,cam1,A,1,2,10.0\n1,cam1,A,1,2,9.9\n", "row 3: camera 'cam1': its stamp goes backwards"),
        (STAMPED + "0,cam1,A,1,2,10.0\n1,cam1,A,1,2,10.0\n", "row 3: camera 'cam1': its stamp repeats"),
    ],
)
def test_bad_stamps_name_file_row_and_camera(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "obs.csv"
    path.write_text(text)
    with pytest.raises(FormatError, match=message) as error:
        read_observations(path, ("cam0", "cam1"))
    assert str(path) in str(error.value)


def test_a_byte_order_mark_before_the_header_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "o.csv"
    path.write_bytes(b"\xef\xbb\xbfframe,camera,point,u,v\n0,cam0,A,1.5,2.5\n")
    back = read_observations(path)
    assert back.camera_names == ("cam0",) and back.uv[0, 0, 0].tolist() == [1.5, 2.5]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"\x89PNG\r\n\x1a\n" + bytes(range(256)), "not UTF-8 text"),
        (b"frame,camera,point,u,v\n0,cam0,A,1,2\n0,cam0,B,\x00,4\n", "row 3: u, v must be numbers"),
    ],
    ids=["binary", "NUL byte"],
)
def test_files_that_are_not_text_are_format_errors(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "o.csv"
    path.write_bytes(content)
    with pytest.raises(FormatError, match=message) as error:
        read_observations(path)
    assert str(error.value).startswith(str(path)) and "\n" not in str(error.value)


def test_a_last_row_without_its_line_end_is_read_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "o.csv"
    path.write_text("frame,camera,point,u,v\n0,cam0,A,348.375807,19")  # as a writer stopped mid-row leaves it
    back = read_observations(path)
    assert back.uv[0, 0, 0].tolist() == [348.375807, 19.0]
    assert "the last row has no line end" in caplog.text and str(path) in caplog.text


def _row_by_row(path: Path, known: list[str] | None, sizes: dict[str, tuple[int, int]]) -> WandObservations:
    from wand_calib_ros.io.observations_csv import _parse

    with path.open(newline="", encoding="utf-8-sig") as handle:
        return _parse(handle, path, known, sizes)


@pytest.mark.parametrize("stamps", [False, True])
@pytest.mark.parametrize("variant", ["plain", "crlf", "bom", "spaces", "extra column", "unknown cameras"])
def test_the_fast_reader_and_the_row_by_row_reader_agree(tmp_path: Path, stamps: bool, variant: str) -> None:
    from wand_calib_ros.io.observations_csv import _parse_plain

    rng = np.random.default_rng(5)
    uv = rng.uniform(-5, 1020, (40, 3, 3, 2)) * rng.choice([1.0, np.nan], (40, 3, 3, 1), p=[0.8, 0.2])
    times = np.cumsum(rng.uniform(0.01, 0.05, (40, 3)), axis=0) + 1.7e9 if stamps else None
    flags = (rng.random((40, 3, 3)) < 0.4) & np.isfinite(uv[..., 0]) if stamps else None  # (with and without)
    stops = np.where(np.isfinite(uv[..., 0]), rng.uniform(-3, 5, (40, 3, 3)), np.nan) if stamps else None
    if stops is not None:
        stops[0, 0, 0] = np.nan  # (a point whose brightness was not measured)
    observations = WandObservations(np.arange(40) * 3 + 7, ("left", "c2", "right_camera"), uv, times, flags, stops)
    path = tmp_path / "observations.csv"
    write_observations(observations, path)
    text = path.read_text()
    if variant == "crlf":
        text = text.replace("\n", "\r\n")
    elif variant == "bom":
        text = "\ufeff" + text
    elif variant == "spaces":
        text = text.replace(",", ", ")
    elif variant == "extra column":
        text = "\n".join(f"{line},{'note' if i == 0 else i}" for i, line in enumerate(text.splitlines())) + "\n"
    path.write_bytes(text.encode())
    known = None if variant == "unknown cameras" else ["right_camera", "left", "c2"]
    sizes = {"left": (1280, 1024), "c2": (1300, 1300)}
    slow = _row_by_row(path, known, sizes)
    read = read_observations(path, known, image_sizes=sizes)
    assert read.camera_names == slow.camera_names and np.array_equal(read.frames, slow.frames)
    assert np.array_equal(read.uv, slow.uv, equal_nan=True)
    assert (read.stamps is None) == (slow.stamps is None)
    if read.stamps is not None:
        assert np.array_equal(read.stamps, slow.stamps, equal_nan=True)
    assert (read.saturated is None) == (slow.saturated is None) == (flags is None)
    if read.saturated is not None:
        assert np.array_equal(read.saturated, slow.saturated)
        assert read.saturated.sum() == observations.saturated.sum()  # type: ignore[union-attr]
    assert (read.brightness is None) == (slow.brightness is None) == (stops is None)
    if read.brightness is not None:
        assert np.array_equal(read.brightness, slow.brightness, equal_nan=True)
    fast = _parse_plain(path.read_bytes(), known, sizes)
    assert (fast is not None) == (variant in ("plain", "crlf", "bom", "extra column", "unknown cameras"))


@pytest.mark.parametrize(
    ("row", "fast"),
    [
        ("7,left,B,12,5,40.0", False),  # a decimal comma: one cell too many
        ("7,left,B,12.5", False),  # a cell short
        ("7,left,B,12.5,40.0,", False),  # a trailing comma
        ("", True),  # a blank line: skipped by both readers
    ],
)
def test_the_fast_reader_counts_every_rows_cells(tmp_path: Path, row: str, fast: bool) -> None:
    """With the header's columns exactly those read, numpy's reader counts each row's cells itself."""
    from wand_calib_ros.io.observations_csv import _parse_plain

    lines = ["frame,camera,point,u,v", "7,left,A,10.0,20.0", row, "7,right,A,30.0,40.0", "8,left,A,11.0,21.0"]
    path = tmp_path / "observations.csv"
    path.write_text("\n".join(lines) + "\n")
    parsed = _parse_plain(path.read_bytes(), ["left", "right"], {})
    assert (parsed is not None) == fast
    if fast:
        assert parsed is not None
        slow = _row_by_row(path, ["left", "right"], {})
        assert np.array_equal(parsed.uv, slow.uv, equal_nan=True) and np.array_equal(parsed.frames, slow.frames)
    else:
        with pytest.raises(FormatError, match="row 3"):
            read_observations(path, ["left", "right"])


@pytest.mark.parametrize(
    "text", ["frame,camera,point,u,v\n", "frame,camera,point,u,v\r\n\r\n\n", "frame,camera,point,u,v"]
)
def test_a_header_without_rows_is_one_error_and_no_warning(tmp_path: Path, text: str) -> None:
    path = tmp_path / "observations.csv"
    path.write_bytes(text.encode())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (numpy's reader warned of an empty input before the error)
        with pytest.raises(FormatError, match="no observations after the header"):
            read_observations(path, None)


def test_saturation_flags_round_trip_and_a_bad_flag_names_its_row(tmp_path: Path) -> None:
    uv = np.arange(2 * 2 * 3 * 2, dtype=float).reshape(2, 2, 3, 2) + 10.0
    flags = np.array([[[True, False, False], [False, False, True]], [[False, False, False], [True, True, True]]])
    observations = WandObservations(np.array([0, 1]), ("cam0", "cam1"), uv, None, flags)
    path = tmp_path / "obs.csv"
    write_observations(observations, path)
    assert path.read_text().splitlines()[0] == "frame,camera,point,u,v,saturated"
    back = read_observations(path, ("cam0", "cam1"))
    assert back.saturated is not None and np.array_equal(back.saturated, flags)
    assert np.array_equal(back.select_cameras(("cam1",)).saturated, flags[:, 1:])  # type: ignore[arg-type]
    swapped = back.with_uv(back.uv[:, :, ::-1])  # labels exchanged: each point keeps its own flag
    assert swapped.saturated is not None and np.array_equal(swapped.saturated, flags[:, :, ::-1])
    path.write_text("frame,camera,point,u,v,saturated\n0,cam0,A,1,2,1\n0,cam0,B,3,4,yes\n")
    with pytest.raises(FormatError, match=r"row 3.*saturated must be 0 or 1, got 'yes'"):
        read_observations(path)


def test_brightness_round_trips_beside_the_flags_and_a_bad_cell_names_its_row(tmp_path: Path) -> None:
    uv = np.arange(2 * 2 * 3 * 2, dtype=float).reshape(2, 2, 3, 2) + 10.0
    stops = np.array([[[-1.25, 0.0, 2.5], [np.nan, 4.125, -0.5]], [[3.0, 1.0, 0.5], [-2.0, 5.5, 0.25]]])
    observations = WandObservations(np.array([0, 1]), ("cam0", "cam1"), uv, None, stops >= 0, stops)
    path = tmp_path / "obs.csv"
    write_observations(observations, path)
    assert path.read_text().splitlines()[0] == "frame,camera,point,u,v,saturated,brightness"
    back = read_observations(path, ("cam0", "cam1"))
    assert back.brightness is not None and np.allclose(back.brightness, stops, atol=5e-4, equal_nan=True)
    swapped = back.with_uv(back.uv[:, :, ::-1])  # labels exchanged: each point keeps its own brightness
    assert swapped.brightness is not None
    assert np.array_equal(swapped.brightness, back.brightness[:, :, ::-1], equal_nan=True)
    assert np.array_equal(back.select_frames(np.array([1])).brightness, back.brightness[1:], equal_nan=True)
    path.write_text("frame,camera,point,u,v,brightness\n0,cam0,A,1,2,\n0,cam0,B,3,4,nan\n0,cam0,C,5,6,1.5\n")
    read = read_observations(path)
    assert read.brightness is not None and np.array_equal(read.brightness[0, 0], [np.nan, np.nan, 1.5], equal_nan=True)
    for bad in ("bright", "inf", "99"):
        path.write_text(f"frame,camera,point,u,v,brightness\n0,cam0,A,1,2,1.0\n0,cam0,B,3,4,{bad}\n")
        with pytest.raises(FormatError, match=rf"row 3.*cam0.*brightness must be stops over full scale.*got '{bad}'"):
            read_observations(path)
