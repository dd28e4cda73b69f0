"""A buffer survives crashes and resets: torn last writes are cut with a copy kept, backups never replaced."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wand_calib_ros.collection.buffer import ObservationBuffer
from wand_calib_ros.collection.recovery import backup_path, cut_torn_tail
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.observations_csv import observation_rows, read_observations
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate

SCENARIO = paper_fisheye_scenario()
NAMES = SCENARIO.rig.camera_names


def _stamps(frame: int) -> np.ndarray:
    return 1.7e9 + frame / 30.0 + np.array([0.0, 0.007])


def _filled(path: Path, n: int, seed: int = 0) -> np.ndarray:
    """A buffer at ``path`` holding ``n`` frames; returns n + 5 frames' pixels (the rest for later)."""
    uv = simulate(SCENARIO, 0.5, np.random.default_rng(seed), n=n + 5).observations.uv
    buffer = ObservationBuffer.open(path, SCENARIO.rig)
    for k in range(n):
        assert buffer.offer(uv[k], _stamps(k))
    return uv


def _rows_text(frame: int, uv: np.ndarray) -> str:
    rows = observation_rows(frame, NAMES, uv, _stamps(frame))
    return "".join(",".join(str(cell) for cell in row) + "\n" for row in rows)


def test_a_torn_last_row_is_cut_back_to_the_last_complete_frame_and_kept_aside(tmp_path: Path) -> None:
    path = tmp_path / "observations.csv"
    uv = _filled(path, 10)
    frame_10 = _rows_text(10, uv[10])
    with path.open("a") as handle:  # the process died while writing frame 10: 4 rows whole, the 5th torn
        handle.write("".join(frame_10.splitlines(keepends=True)[:4]) + frame_10.splitlines()[4][:19])
    as_found = path.read_bytes()
    resumed = ObservationBuffer.open(path, SCENARIO.rig)
    assert resumed.repaired is not None
    assert resumed.repaired.frame == 10 and resumed.repaired.dropped_rows == 5
    assert resumed.repaired.original.read_bytes() == as_found
    assert "frame 10 cut (5 rows)" in resumed.repaired.describe(path)
    assert resumed.frames == list(range(10)) and resumed.next_frame == 10
    assert resumed.offer(uv[11], _stamps(10))  # continues on a new line, no value glued to the torn one
    back = read_observations(path, NAMES)
    assert back.frames.tolist() == list(range(11))
    assert np.allclose(back.uv[10], uv[11], atol=1e-5)
    assert np.allclose(back.uv[:10], uv[:10], atol=1e-5)
    assert ObservationBuffer.open(path, SCENARIO.rig).repaired is None  # repaired once


def test_a_tear_inside_the_frame_id_cuts_that_row_only(tmp_path: Path) -> None:
    path = tmp_path / "observations.csv"
    _filled(path, 6)
    with path.open("a") as handle:
        handle.write("1")  # the first byte of frame 10's first row... or of frame 1xx: no frame can be named
    resumed = ObservationBuffer.open(path, SCENARIO.rig)
    assert resumed.repaired is not None and resumed.repaired.frame is None and resumed.repaired.dropped_rows == 1
    assert resumed.frames == list(range(6))


def test_nul_padding_after_complete_rows_is_removed_without_dropping_a_frame(tmp_path: Path) -> None:
    path = tmp_path / "observations.csv"
    _filled(path, 6)
    with path.open("ab") as handle:
        handle.write(b"\x00" * 512)  # what a file system may show after power loss
    resumed = ObservationBuffer.open(path, SCENARIO.rig)
    assert resumed.repaired is not None and resumed.repaired.dropped_rows == 0
    assert resumed.frames == list(range(6))
    assert b"\x00" not in path.read_bytes()


def test_a_torn_header_restarts_the_file(tmp_path: Path) -> None:
    path = tmp_path / "observations.csv"
    path.write_text("frame,cam")
    resumed = ObservationBuffer.open(path, SCENARIO.rig)
    assert resumed.repaired is not None and resumed.frames == []
    assert path.read_text() == "frame,camera,point,u,v,stamp\n"


def test_a_complete_file_is_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "observations.csv"
    _filled(path, 4)
    before = path.read_bytes()
    assert cut_torn_tail(path) is None and path.read_bytes() == before
    assert list(tmp_path.iterdir()) == [path]


def test_resets_in_the_same_second_keep_every_backup(tmp_path: Path) -> None:
    path = tmp_path / "observations.csv"
    uv = _filled(path, 8)
    buffer = ObservationBuffer.open(path, SCENARIO.rig)
    first = buffer.reset()
    for k in range(3):
        buffer.offer(uv[k], _stamps(k))
    second = buffer.reset()
    third = buffer.reset()  # nothing stored since: no backup, nothing replaced
    assert first is not None and second is not None and third is None and first != second
    assert read_observations(first, NAMES).frames.size == 8
    assert read_observations(second, NAMES).frames.size == 3
    names = [backup_path(path, "bak") for _ in range(3)]  # three in one second: three names
    assert len(set(names)) == 3 and all(name.exists() for name in names)


@pytest.mark.parametrize(
    "content",
    [bytes(range(256)) * 4, b"frame,camera,point,u,v\n0,cam0,A,1,2\n\xff\xfe0,cam0,B,3,4\n"],
    ids=["binary", "latin-1 byte"],
)
def test_a_buffer_that_is_not_text_is_refused_in_one_line(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "observations.csv"
    path.write_bytes(content + b"\n")
    with pytest.raises(FormatError, match=r"cannot resume the buffer.*not UTF-8 text") as error:
        ObservationBuffer.open(path, SCENARIO.rig)
    assert "\n" not in str(error.value) and path.read_bytes() == content + b"\n"


def test_appends_are_synced_to_disk_at_least_every_second(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from wand_calib_ros.collection import buffer as module

    clock = [100.0]
    synced: list[float] = []
    monkeypatch.setattr(module.time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(module.os, "fsync", lambda descriptor: synced.append(clock[0]))
    uv = simulate(SCENARIO, 0.5, np.random.default_rng(9), n=60).observations.uv
    buffer = ObservationBuffer.open(tmp_path / "observations.csv", SCENARIO.rig)
    for k in range(60):  # 60 frames over 2 s at 30 fps
        clock[0] = 100.0 + k / 30.0
        buffer.offer(uv[k], _stamps(k))
    buffer.sync()  # at exit
    gaps = np.diff([100.0, *synced, clock[0]])
    assert gaps.max() <= module.SYNC_INTERVAL_S + 1 / 30.0 and len(synced) <= 5  # not per frame either
