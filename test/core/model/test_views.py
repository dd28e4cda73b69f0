"""What dense views hold: the shortcuts give what numpy's reductions over the trailing axes give."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.core.model.views import (
    appended,
    enough_views,
    observed_points,
    seen_points,
    some_views,
    whole_views,
)


@pytest.mark.parametrize("n_points", [2, 3, 5])
def test_markers_views_and_observations_are_those_numpy_finds(n_points: int) -> None:
    rng = np.random.default_rng(n_points)
    uv = rng.uniform(0, 1000, size=(40, 6, n_points, 2))
    uv[rng.random(uv.shape[:3]) < 0.4] = np.nan  # markers not seen
    uv[rng.random(uv.shape[:2]) < 0.3] = np.nan  # whole views missing
    uv[0, 0, 0, 1] = np.nan  # one coordinate alone: the marker is not seen
    seen = np.all(np.isfinite(uv), axis=-1)
    assert np.array_equal(seen_points(uv), seen)
    assert np.array_equal(whole_views(uv), np.all(np.isfinite(uv), axis=(2, 3)))
    assert np.array_equal(some_views(uv), np.any(seen, axis=2))
    flat, placement, camera, point = observed_points(uv)
    for mine, numpys in zip((placement, camera, point), np.nonzero(seen), strict=True):
        assert np.array_equal(mine, numpys)
    assert np.array_equal(uv.reshape(-1, 2)[flat], uv[seen])
    assert whole_views(uv[:, 0]).shape == (40,)  # any leading shape


def test_rows_appended_are_numpys_concatenation() -> None:
    rng = np.random.default_rng(3)
    views, uv = rng.normal(size=(7, 4, 3, 2)), rng.normal(size=(20, 4, 3, 2))
    uv[rng.random(uv.shape[:3]) < 0.5] = np.nan
    rows = np.array([2, 5, 6, 19])
    assert np.array_equal(appended(views, uv, rows), np.concatenate([views, uv[rows]]), equal_nan=True)
    assert np.array_equal(appended(views, uv, rows[:0]), views)


def test_points_observed_in_some_rows_are_those_of_their_copy_indexed_into_the_whole() -> None:
    rng = np.random.default_rng(4)
    uv = rng.uniform(0, 1000, size=(30, 5, 3, 2))
    uv[rng.random(uv.shape[:3]) < 0.5] = np.nan
    rows = np.array([1, 4, 5, 17, 29])
    flat, placement, camera, point = observed_points(uv, rows)
    flat_copy, *copy = observed_points(uv[rows])
    for mine, theirs in zip((placement, camera, point), copy, strict=True):
        assert np.array_equal(mine, theirs)
    assert np.array_equal(uv.reshape(-1, 2)[flat], uv[rows].reshape(-1, 2)[flat_copy])


def test_enough_views_of_some_rows_and_without_some_views() -> None:
    rng = np.random.default_rng(6)
    uv = rng.uniform(0, 1000, size=(40, 4, 3, 2))
    uv[rng.random(uv.shape[:3]) < 0.3] = np.nan
    whole = np.all(np.isfinite(uv), axis=(2, 3))
    assert np.array_equal(enough_views(uv), whole.sum(axis=1) >= 2)
    rows = np.array([0, 3, 4, 9, 20, 39])
    left_out = rng.random((rows.size, 4)) < 0.3
    assert np.array_equal(enough_views(uv, rows, left_out), (whole[rows] & ~left_out).sum(axis=1) >= 2)
    copy = uv[rows]
    copy[left_out] = np.nan
    assert np.array_equal(enough_views(uv, rows, left_out), enough_views(copy))  # as with the views set NaN
