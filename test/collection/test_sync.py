"""Time synchronisation of per-camera detections."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.collection.sync import FrameSynchroniser

POINTS = np.arange(6, dtype=float).reshape(3, 2)


def test_identical_stamps_form_a_frame_as_soon_as_every_camera_reported() -> None:
    sync = FrameSynchroniser(("a", "b"))
    assert sync.add("a", 100, POINTS) == []
    (frame,) = sync.add("b", 100, None)
    assert frame.stamp_ns == 100 and frame.reported.all()
    assert np.array_equal(frame.uv[0], POINTS) and np.all(np.isnan(frame.uv[1]))
    assert sync.stats.complete == 1


def test_stamps_within_the_slop_join_and_stragglers_are_counted() -> None:
    sync = FrameSynchroniser(("a", "b", "c"), slop_ns=5, max_delay_ns=50)
    sync.add("a", 1000, POINTS)
    sync.add("b", 1003, POINTS)
    frames = sync.add("a", 1100, POINTS)  # c never came: the first frame is emitted incomplete
    assert len(frames) == 1 and frames[0].reported.tolist() == [True, True, False]
    sync.add("c", 1001, POINTS)  # for a frame already emitted
    assert sync.stats.late == 1 and sync.stats.out_of_order == 1


def test_out_of_order_within_the_window_still_joins() -> None:
    sync = FrameSynchroniser(("a", "b"), slop_ns=5, max_delay_ns=1000)
    sync.add("a", 2000, POINTS)
    sync.add("a", 1000, POINTS)  # older stamp arrives second
    frames = sync.add("b", 1002, POINTS) + sync.add("b", 2001, POINTS)
    assert [f.stamp_ns for f in frames] == [1000, 2000]
    assert sync.stats.out_of_order == 2 and sync.stats.late == 0  # 1000 and 1002 came after 2000
    sync.add("a", 3000, POINTS)
    sync.add("a", 3000, POINTS)
    assert sync.stats.duplicates == 1
    assert [f.stamp_ns for f in sync.flush_all()] == [3000]
