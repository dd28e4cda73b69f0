"""Reports drawn after the answer: one at a time, the newest last, from the result as it was written."""

from __future__ import annotations

import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from wand_calib_ros.collection.job import report_request, run_calibration
from wand_calib_ros.collection.report_drawer import DrawnReport, ReportDrawer, ReportRequest, draw_report
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.result_yaml import result_document, write_yaml
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate


def _request(folder: Path, source: str) -> ReportRequest:
    """A request whose drawing is faked (only its folder and source are read)."""
    scenario = paper_fisheye_scenario()
    empty = simulate(scenario, 0.5, np.random.default_rng(0), n=2).observations
    return ReportRequest(scenario.rig, empty, folder / "result.yaml", {}, folder / "report", None, source)


class Gate:
    """A fake drawing that waits to be let through, and remembers what it drew."""

    def __init__(self, fail: dict[str, Exception] | None = None) -> None:
        self.open = threading.Event()
        self.started = threading.Event()
        self.drawn: list[str] = []
        self.fail = fail or {}

    def __call__(self, request: ReportRequest) -> None:
        self.started.set()
        assert self.open.wait(10)
        self.drawn.append(request.source)
        if request.source in self.fail:
            raise self.fail[request.source]


def test_a_report_waiting_behind_the_one_being_drawn_is_replaced_by_a_newer_one(tmp_path: Path) -> None:
    said: list[DrawnReport] = []
    gate = Gate()
    drawer = ReportDrawer(said.append, draw=gate)
    page = drawer.submit(_request(tmp_path, "first"))
    assert page == tmp_path / "report" / "index.html"
    assert gate.started.wait(5) and drawer.busy
    drawer.submit(_request(tmp_path, "second"))  # waits behind the first
    drawer.submit(_request(tmp_path, "third"))  # replaces the second: it would be written over at once
    assert not drawer.wait(0.1)  # (still drawing the first)
    gate.open.set()
    assert drawer.wait(10) and not drawer.busy
    assert gate.drawn == ["first", "third"]
    assert [d.request.source for d in said] == ["first", "third"] and all(d.error is None for d in said)
    assert said[0].line().startswith(f"first: report ready in {page} (")


def test_a_failed_report_is_said_and_the_next_one_is_still_drawn(tmp_path: Path) -> None:
    said: list[DrawnReport] = []
    gate = Gate({"disk": OSError(28, "No space left on device"), "bug": RuntimeError("a bug")})
    gate.open.set()
    drawer = ReportDrawer(said.append, draw=gate)
    for source in ("disk", "bug", "fine"):
        drawer.submit(_request(tmp_path, source))
        assert drawer.wait(10)
    assert [d.request.source for d in said] == ["disk", "bug", "fine"]
    failed = "disk: the calibration is written, but its report failed: [Errno 28] No space left on device"
    assert said[0].line() == failed
    assert said[1].error is not None and "unexpected error (please report): RuntimeError('a bug')" in said[1].error
    assert said[2].error is None


def test_a_report_is_of_the_result_as_written_even_when_the_file_was_replaced_since(tmp_path: Path) -> None:
    scenario = paper_fisheye_scenario()
    observations = simulate(scenario, 0.5, np.random.default_rng(4)).observations
    result, files = run_calibration(scenario.rig, observations, tmp_path)
    request = report_request(scenario.rig, observations, files, tmp_path, "/calibrate")
    assert request.document == result_document(files.result)
    # Another calibration replaces result.yaml before the report is drawn: here one with cam1 100 mm
    # further along x, which these views do not fit (a report drawn from the file now refuses it).
    other = result_document(files.result)
    other["cameras"]["cam1"]["translation"][0] += 100.0
    write_yaml(other, files.result)
    with pytest.raises(FormatError, match="does not fit these observations"):
        draw_report(replace(request, document=result_document(files.result)))
    draw_report(request)
    page = request.page.read_text()
    tx = result.camera("cam1").pose.translation[0]
    assert f"<td>{tx:.5g} &plusmn; " in page and f"<td>{tx + 100.0:.5g} &plusmn; " not in page
