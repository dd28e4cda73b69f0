"""The HTML report renders with every figure, for simulated and real data."""

from __future__ import annotations

from pathlib import Path

import pytest

from wand_calib_ros.cli import main
from wand_calib_ros.report.figures import FIGURES

DATA = Path(__file__).resolve().parents[1] / "data" / "ewand"


def _check(out: Path, *, timing: bool) -> str:
    """The page has every figure (the timing one only where the result has a timing to show)."""
    page = (out / "index.html").read_text()
    expected = [name for name in FIGURES if timing or name != "timing"]
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
