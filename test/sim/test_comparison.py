"""A reduced run of the checkerboard baseline comparison (the paper's Tables 1-4)."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.core.judge.metrics import camera_errors
from wand_calib_ros.sim.comparison import compare, error_summary, markdown_table


def test_wand_and_checkerboard_calibrate_the_same_rig_comparably() -> None:
    comparison = compare("paper", seed=0, board_views=10)
    table = markdown_table(comparison)
    assert "wand (proposed)" in table and "checkerboard (OpenCV fisheye)" in table and "D_RMS" in table
    for method in comparison.methods:
        for c, camera in enumerate(comparison.scenario.cameras):
            e = camera_errors(method.models[c], method.poses[c], camera.model, camera.pose)
            assert e.focal_px < 0.02 * camera.model.focal_px[0], method.method
            assert e.principal_point_px < 15.0, method.method
            assert method.rms_px[c] < 1.1  # 1 px noise
    wand, board = comparison.methods
    assert 0.5 < wand.d_rms_mm / board.d_rms_mm < 2.0
    summary = error_summary([comparison])
    assert set(summary) == {"wand (proposed)", "checkerboard (OpenCV fisheye)"}
    assert all(np.isfinite(v) for values in summary.values() for v in values.values())
