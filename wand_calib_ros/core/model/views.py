"""What dense views hold: which markers, which cameras' views and which observations are there.

The calibration keeps its image points as dense (P, C, K, 2) arrays of pixels, NaN where a camera did
not see a marker (P placements, C cameras, K markers). On a large rig most of such an array is NaN (64
cameras x 50,000 placements: 87 %), and a reduction over its two or three trailing entries costs numpy
an inner loop per view: these functions take the few trailing entries one by one instead (2-8x faster
on such arrays), so that every pass over the views costs about one read of them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


def seen_points(uv: FloatArray) -> BoolArray:
    """(..., K) the markers seen (both coordinates finite) of (..., K, 2) pixels."""
    return np.isfinite(uv[..., 0]) & np.isfinite(uv[..., 1])


def whole_views(uv: FloatArray) -> BoolArray:
    """(...) the views that see every marker, of (..., K, 2) pixels."""
    return _across_markers(np.logical_and, seen_points(uv))


def some_views(uv: FloatArray) -> BoolArray:
    """(...) the views that see at least one marker, of (..., K, 2) pixels."""
    return _across_markers(np.logical_or, seen_points(uv))


def enough_views(uv: FloatArray, rows: IntArray | None = None, left_out: BoolArray | None = None) -> BoolArray:
    """(P,) the placements of (P, C, K, 2) pixels seen whole by at least two cameras, or (R,) those of the
    placements ``rows`` (no copy of their views), the views ``left_out`` ((P or R, C), e.g. rejected) not
    counted."""
    whole = whole_views(uv) if rows is None else whole_views(uv)[rows]
    if left_out is not None:
        whole &= ~left_out
    return np.asarray(whole.sum(axis=1) >= 2)


def _across_markers(combine: np.ufunc, seen: BoolArray) -> BoolArray:
    """(...) ``combine`` of (..., K) over its K markers, one marker's array at a time."""
    out = seen[..., 0].copy()
    for k in range(1, seen.shape[-1]):
        combine(out, seen[..., k], out=out)
    return out


def observed_points(uv: FloatArray, rows: IntArray | None = None) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    """Every point seen in (P, C, K, 2) pixels, or in their placements ``rows`` (R,) (no copy of those), sorted by
    placement, then camera, then marker (``np.nonzero``'s order): (M,) its index into the (P C K, 2) rows of
    ``uv``, its placement (among ``rows`` where given), camera and marker."""
    _, n_cameras, n_points = uv.shape[:3]
    seen = seen_points(uv)
    flat = np.flatnonzero(seen if rows is None else seen[rows])
    placement, rest = np.divmod(flat, n_cameras * n_points)
    camera, point = np.divmod(rest, n_points)
    return flat if rows is None else rows[placement] * (n_cameras * n_points) + rest, placement, camera, point


def appended(views: FloatArray, uv: FloatArray, rows: IntArray) -> FloatArray:
    """(N + R, ...) the (N, ...) ``views`` followed by the rows ``rows`` (R,) of ``uv``, each written once (no copy
    of those rows first: at 64 cameras a copy of the views is 150 MB)."""
    out = np.empty((views.shape[0] + rows.size, *views.shape[1:]), dtype=views.dtype)
    out[: views.shape[0]] = views
    np.take(uv, rows, axis=0, out=out[views.shape[0] :])
    return out
