"""Outlier gating: the views a residual beyond the gate rejects."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.core.adjust.bundle_problem import BundleProblem
from wand_calib_ros.core.adjust.gating import rejected_views
from wand_calib_ros.core.model.rig import WandSpec


def test_a_view_is_rejected_for_its_worst_point_and_only_that_view() -> None:
    rng = np.random.default_rng(4)
    uv = rng.uniform(0, 1000, size=(30, 5, 3, 2))
    uv[rng.random(uv.shape[:3]) < 0.3] = np.nan
    problem = BundleProblem.from_dense(WandSpec((0.0, 200.0, 600.0)), uv)
    residuals = rng.normal(0, 1.0, size=(problem.n_observations, 2)).clip(-2.5, 2.5)  # within 2.5 * sqrt(2) px
    far = [7, problem.n_observations - 1]  # two points far off: their views go
    residuals[far] = 40.0
    rejected = rejected_views(uv, residuals, 5.0)
    expected = np.zeros(uv.shape[:2], dtype=bool)
    expected[problem.placement[far], problem.camera[far]] = True
    assert np.array_equal(rejected, expected)
    assert not rejected_views(uv, residuals, 100.0).any()
