"""Placements from the cameras: the linear triangulation of every wand point, and each placement's fit."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust import placements
from wand_calib_ros.core.adjust.bundle_problem import BundleProblem, BundleState
from wand_calib_ros.core.adjust.gating import rejected_views
from wand_calib_ros.core.adjust.placements import fit_placements, triangulate_placements
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.sim.scenarios import Scenario, SimulatedData, paper_fisheye_scenario, simulate


def _three_cameras(
    noise: float, n: int, seed: int, missing: float
) -> tuple[Scenario, SimulatedData, NDArray[np.float64], tuple[CameraModel, ...], tuple[Pose, ...]]:
    """The paper's fisheye rig of three cameras, its take with ``missing`` of the points not seen (at random),
    those views, and the cameras' models and poses."""
    scenario = paper_fisheye_scenario(n_cameras=3)
    data = simulate(scenario, noise, np.random.default_rng(seed), n=n)
    uv = data.observations.uv.copy()
    uv[np.random.default_rng(seed + 1).random(uv.shape[:3]) < missing] = np.nan
    return scenario, data, uv, tuple(c.model for c in scenario.cameras), tuple(c.pose for c in scenario.cameras)


def test_noise_free_views_triangulate_to_the_true_points_in_one_thread_or_two(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # Three cameras, views missing at random (points seen by none to three of them): where two or more see a
    # point it lands on the truth, elsewhere NaN; in two threads (half of the cameras each) the same numbers.
    monkeypatch.setattr("wand_calib_ros.core.parallel.cores", lambda: 2)
    scenario, data, uv, models, poses = _three_cameras(0.0, 400, 3, 0.4)
    truth = data.wand_a[:, None, :] + scenario.wand.offsets[None, :, None] * data.wand_direction[:, None, :]
    seen = np.isfinite(uv[..., 0]).sum(axis=1) >= 2  # (P, K)
    found = []
    for split_above in (10**9, 0):
        monkeypatch.setattr(placements, "SPLIT_RAYS", split_above)
        points = triangulate_placements(models, poses, uv)
        assert np.array_equal(np.all(np.isfinite(points), axis=-1), seen)
        assert np.max(np.abs(points[seen] - truth[seen])) < 1e-6  # mm, of a metre: rounding
        found.append(points)
    assert np.array_equal(found[0], found[1], equal_nan=True)


def test_placements_read_in_place_are_those_of_a_copy_of_their_views() -> None:
    # Some rows of the views (with missing points): triangulated, fitted and their problem built from the views in
    # place, the same numbers as from a copy of those rows.
    scenario, _, uv, models, poses = _three_cameras(1.0, 300, 5, 0.1)
    rows = np.flatnonzero(np.random.default_rng(7).random(len(uv)) < 0.6)
    copy = uv[rows]
    assert np.array_equal(triangulate_placements(models, poses, uv, rows), triangulate_placements(models, poses, copy),
                          equal_nan=True)  # fmt: skip
    in_place = BundleProblem.from_dense(scenario.wand, uv, rows=rows)
    copied = BundleProblem.from_dense(scenario.wand, copy)
    for name in ("camera", "placement", "point", "uv"):
        assert np.array_equal(getattr(in_place, name), getattr(copied, name)), name
    assert in_place.n_placements == rows.size
    cameras = BundleState(models, poses, np.zeros((0, 3)), np.zeros((0, 3)))
    index, fitted = fit_placements(scenario.wand, cameras, uv, rows=rows, loss_scale=2.0)
    index_copy, fitted_copy = fit_placements(scenario.wand, cameras, copy, loss_scale=2.0)
    assert np.array_equal(index, index_copy) and 0.6 * rows.size < index.size < rows.size  # (some not seen whole)
    assert np.array_equal(fitted.state.wand_a, fitted_copy.state.wand_a)
    assert np.array_equal(fitted.residuals, fitted_copy.residuals)
    rejected = rejected_views(uv, fitted.residuals, 3.0, rows[index])
    assert np.array_equal(rejected, rejected_views(copy[index], fitted_copy.residuals, 3.0)) and rejected.any()
