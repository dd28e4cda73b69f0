"""Reduced versions of the paper's sweeps (Figs. 4-6): the trends must hold."""

from __future__ import annotations

from pathlib import Path

from wand_calib_ros.cli import main
from wand_calib_ros.sim.sweeps import SWEEPS, run_sweep, summarise


def test_errors_grow_about_linearly_with_noise() -> None:
    rows = run_sweep(SWEEPS["noise"], 2, runs=3, seed=1, values=(0.5, 1.0, 2.0))
    assert not any(r.failure for r in rows)
    summary = summarise(rows)
    rms = [summary[(2, s)]["rms_px"] for s in (0.5, 1.0, 2.0)]
    # the reprojection error is proportional to the noise
    assert abs(rms[1] / rms[0] - 2.0) < 0.2
    assert abs(rms[2] / rms[0] - 4.0) < 0.4
    # parameter errors grow with the noise (averaged over runs and cameras)
    for metric in ("rotation_error_deg", "translation_error", "focal_error_mm"):
        assert summary[(2, 2.0)][metric] > summary[(2, 0.5)][metric], metric


def test_converges_from_every_initial_focal_and_principal_point_offset() -> None:
    for name, values in (("focal", (1.5, 2.5)), ("principal_point", (0.0, 100.0))):
        rows = run_sweep(SWEEPS[name], 3, runs=1, seed=2, values=values)
        assert not any(r.failure for r in rows), name
        for row in rows:
            assert row.focal_error_mm < 0.02, row  # < 1 % of the focal length
            assert max(row.u0_error_px, row.v0_error_px) < 8.0, row
            assert row.rms_px < 1.0, row


def test_sweep_command_writes_csv_and_png(tmp_path: Path) -> None:
    assert main(["-q", "sweep", "--out", str(tmp_path), "--runs", "1", "--quick"]) == 0
    for figure in ("fig4_noise", "fig5_focal", "fig6_principal_point"):
        assert (tmp_path / f"{figure}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        lines = (tmp_path / f"{figure}.csv").read_text().splitlines()
        assert lines[0].startswith("sweep,n_cameras,value,run,camera")
        assert len(lines) == 1 + 3 * (2 + 3)  # 3 values x (2 + 3 cameras) x 1 run
