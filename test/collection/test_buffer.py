"""The persisted observation buffer: append, resume, thin, reset."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wand_calib_ros.collection.buffer import ObservationBuffer
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.observations_csv import read_observations
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate


def _stamps(frame: int, n_cameras: int = 2) -> np.ndarray:
    """Stamps of free-running cameras at 30 fps (each camera 7 ms after the previous one), s."""
    return 1.7e9 + frame / 30.0 + 0.007 * np.arange(n_cameras)


def test_frames_are_persisted_at_once_and_resumed(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(0), n=40)
    path = tmp_path / "observations.csv"
    buffer = ObservationBuffer.open(path, scenario.rig)
    for k, uv in enumerate(data.observations.uv[:25]):
        assert buffer.offer(uv, _stamps(k))
    on_disk = read_observations(path, scenario.rig.camera_names)  # no close needed: flushed per frame
    assert on_disk.frames.tolist() == list(range(25))
    assert np.allclose(on_disk.uv, data.observations.uv[:25], atol=1e-5)
    assert on_disk.stamps is not None and np.array_equal(on_disk.stamps, np.array([_stamps(k) for k in range(25)]))
    assert b"\r" not in path.read_bytes()  # LF line endings
    again = ObservationBuffer.open(path, scenario.rig)  # a restart after a crash
    assert again.next_frame == 25 and again.with_stamps
    for k, uv in enumerate(data.observations.uv[25:], start=25):
        again.offer(uv, _stamps(k))
    assert read_observations(path, scenario.rig.camera_names).frames.size == 40


def test_a_buffer_written_without_stamps_is_continued_without_them(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(4), n=6)
    path = tmp_path / "observations.csv"
    old = ObservationBuffer.open(path, scenario.rig, with_stamps=False)  # as an older collector wrote it
    for uv in data.observations.uv[:3]:
        old.offer(uv)
    resumed = ObservationBuffer.open(path, scenario.rig)
    assert not resumed.with_stamps
    for k, uv in enumerate(data.observations.uv[3:], start=3):
        resumed.offer(uv, _stamps(k))
    back = read_observations(path, scenario.rig.camera_names)
    assert back.frames.size == 6 and back.stamps is None
    with pytest.raises(ValueError, match="stores the views' stamps"):
        ObservationBuffer.open(tmp_path / "new.csv", scenario.rig).offer(data.observations.uv[0])


def test_a_wand_held_still_is_stored_once(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.0, np.random.default_rng(1), n=2)
    buffer = ObservationBuffer.open(tmp_path / "o.csv", scenario.rig, min_motion_px=2.0)
    still = data.observations.uv[0]
    assert buffer.offer(still, _stamps(0))
    for k in range(10):
        assert not buffer.offer(still + 0.3, _stamps(k + 1))
    assert buffer.offer(data.observations.uv[1], _stamps(11))
    assert buffer.stats.still == 10 and buffer.stats.accepted == 2


def test_a_full_buffer_only_takes_frames_that_add_coverage(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(2), n=400)
    buffer = ObservationBuffer.open(tmp_path / "o.csv", scenario.rig, capacity=100)
    for k, uv in enumerate(data.observations.uv):
        buffer.offer(uv, _stamps(k))
    assert 100 <= len(buffer.frames) < 400 and buffer.stats.full > 0


def test_reset_keeps_a_backup_and_a_corrupt_file_is_refused(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(3), n=5)
    path = tmp_path / "o.csv"
    buffer = ObservationBuffer.open(path, scenario.rig)
    for k, uv in enumerate(data.observations.uv):
        buffer.offer(uv, _stamps(k))
    backup = buffer.reset()
    assert backup is not None and read_observations(backup).frames.size == 5
    assert buffer.next_frame == 0 and path.read_text().strip() == "frame,camera,point,u,v,stamp"
    path.write_text("frame,camera,point,u,v\n0,cam0,A,nan,1\n")
    with pytest.raises(FormatError, match="cannot resume the buffer"):
        ObservationBuffer.open(path, scenario.rig)


def test_a_buffer_that_never_stored_anything_reopens_empty(tmp_path: Path) -> None:
    rig = paper_fisheye_scenario().rig
    ObservationBuffer.open(tmp_path / "observations.csv", rig)  # a collector that saw no wand
    again = ObservationBuffer.open(tmp_path / "observations.csv", rig)
    assert again.frames == [] and again.next_frame == 0


def test_brightness_is_stored_and_resumed(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(3), n=12)
    path = tmp_path / "observations.csv"
    buffer = ObservationBuffer.open(path, scenario.rig, with_brightness=True)
    stops = np.random.default_rng(4).uniform(-3.0, 5.0, (12, 2, 3))
    for k, uv in enumerate(data.observations.uv):
        assert buffer.offer(uv, _stamps(k), brightness=stops[k])
    on_disk = read_observations(path, scenario.rig.camera_names)
    seen = np.isfinite(data.observations.uv[..., 0])
    assert on_disk.brightness is not None
    assert np.array_equal(np.isfinite(on_disk.brightness), seen)
    assert np.allclose(on_disk.brightness[seen], stops[seen], atol=5e-4)  # written to 3 decimals
    assert on_disk.saturated is not None and np.array_equal(on_disk.saturated, (stops >= 0.0) & seen)
    again = ObservationBuffer.open(path, scenario.rig)  # a restart keeps the column
    resumed = again.observations().brightness
    assert again.with_brightness and resumed is not None
    assert np.array_equal(np.isfinite(resumed), seen) and np.allclose(resumed[seen], stops[seen], atol=5e-4)
