"""The live session's history files: what is appended reads back; a damaged file names its row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.session_csv import append_estimate, append_event, read_estimates, read_events
from wand_calib_ros.sim.scenarios import paper_three_camera_scenario, simulate


def test_rounds_and_events_written_then_read_back(tmp_path: Path) -> None:
    scenario = paper_three_camera_scenario()
    result = calibrate(scenario.rig, simulate(scenario, 1.0, np.random.default_rng(1)).observations)
    assert result.quality is not None
    append_estimate(tmp_path / "estimates.csv", 12.5, 300, result)
    append_estimate(tmp_path / "estimates.csv", 15.5, 390, result)
    history = read_estimates(tmp_path / "estimates.csv")
    assert history.camera == scenario.rig.camera_names * 2 and list(history.frames) == [300] * 3 + [390] * 3
    assert np.allclose(history.rms_px[:3], [c.image_error_px for c in result.quality.cameras], rtol=1e-5)
    assert np.allclose(history.wand_rms_mm, result.wand_length_rms_mm, rtol=1e-5)
    assert set(history.grade) == {result.quality.grade} and history.time[-1] == 15.5
    append_event(tmp_path / "events.csv", 20.0, "moved", "cam1", 'cam1 moved: residual 6.1 px, was 0.4, "quoted"')
    append_event(tmp_path / "events.csv", 21.0, "refined", "cam1", "RMS cam0 0.8 px")
    events = read_events(tmp_path / "events.csv")
    assert [(e.event, e.camera) for e in events] == [("moved", "cam1"), ("refined", "cam1")]
    assert events[0].message == 'cam1 moved: residual 6.1 px, was 0.4, "quoted"' and events[1].time == 21.0
    with pytest.raises(ValueError, match="event must be one of"):
        append_event(tmp_path / "events.csv", 22.0, "exploded", "", "")


def test_a_damaged_history_file_names_its_row(tmp_path: Path) -> None:
    path = tmp_path / "events.csv"
    path.write_text("time,event,camera,message\n1.0,moved,cam1,ok\nlater,moved,cam1,bad\n")
    with pytest.raises(FormatError, match=r"events.csv, row 3: time 'later' is not a number"):
        read_events(path)
    path.write_text("when,what\n")
    with pytest.raises(FormatError, match="expected the header"):
        read_events(path)
