"""Placements from the cameras: the linear triangulation of every wand point."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.core.adjust import placements
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate


def test_noise_free_views_triangulate_to_the_true_points_in_one_thread_or_two(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # Three cameras, views missing at random (points seen by none to three of them): where two or more see a
    # point it lands on the truth, elsewhere NaN; in two threads (half of the cameras each) the same numbers.
    monkeypatch.setattr("wand_calib_ros.core.parallel.cores", lambda: 2)
    scenario = paper_fisheye_scenario(n_cameras=3)
    data = simulate(scenario, 0.0, np.random.default_rng(3), n=400)
    uv = data.observations.uv.copy()
    uv[np.random.default_rng(4).random(uv.shape[:3]) < 0.4] = np.nan
    models = tuple(c.model for c in scenario.cameras)
    poses = tuple(c.pose for c in scenario.cameras)
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
