"""The timing model's pieces: timelines from stamps, the wand's motion, aligned views, the tests of auto."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.core.adjust.timing import (
    MOTION_WINDOWS,
    WINDOW_CHOICE_BLOCKS,
    align_views,
    clearly_independent,
    fit_motion,
    frame_period,
    rate_warnings,
    significant,
    smooth_motion,
    timeline,
)
from wand_calib_ros.core.errors import TimingError
from wand_calib_ros.core.model.rig import WandObservations

PERIOD = 1 / 30


def _cubic(t: np.ndarray) -> np.ndarray:
    """(T, 3, 3) points moving along a cubic in time (mm, t in s)."""
    base = np.arange(9, dtype=float).reshape(3, 3) * 100
    return base + (t * 900 - t**2 * 400 + t**3 * 250)[:, None, None] * np.array([1.0, -0.5, 0.2])


def test_the_motion_of_a_cubic_path_is_exact_and_each_fit_leaves_its_own_placement_out() -> None:
    t = np.arange(60) * PERIOD
    points = _cubic(t)
    motion = fit_motion(t, points, PERIOD)
    known = motion.known
    assert known.sum() == 56  # two at each end lack neighbours on one side
    direction = np.array([1.0, -0.5, 0.2])
    assert np.allclose(motion.velocity[known], ((900 - 800 * t + 750 * t**2)[:, None, None] * direction)[known])
    assert np.allclose(motion.acceleration[known], ((-800 + 1500 * t)[:, None, None] * direction)[known])
    assert np.allclose(motion.jerk[known], 1500 * direction)
    assert motion.continuous
    noisy = points.copy()
    noisy[30] += 5.0  # the placement's own noise must not reach its own motion
    again = fit_motion(t, noisy, PERIOD)
    assert np.allclose(again.velocity[30], motion.velocity[30])
    assert again.residual[30] == pytest.approx(5.0 * np.sqrt(1.0), rel=1e-6)


def test_gaps_and_order_do_not_matter_and_independent_placements_are_not_a_motion() -> None:
    t = np.arange(80) * PERIOD
    keep = (np.arange(80) < 30) | (np.arange(80) >= 50)  # the wand left the view for 20 frames
    order = np.random.default_rng(0).permutation(keep.sum())
    motion = fit_motion(t[keep][order], _cubic(t)[keep][order], PERIOD)
    assert not motion.known[np.flatnonzero(np.isin(t[keep][order], t[[28, 29, 50, 51]]))].any()
    assert motion.continuous
    scattered = np.random.default_rng(1).uniform(-400, 400, size=(80, 3, 3))
    assert not fit_motion(t, scattered, PERIOD).continuous


def test_a_sample_of_a_long_recording_tells_independent_placements_from_a_waved_wand() -> None:
    n = 2 * WINDOW_CHOICE_BLOCKS[0] * WINDOW_CHOICE_BLOCKS[1] + 1000  # longer than the sample
    t = np.arange(n) * PERIOD
    rng = np.random.default_rng(3)
    swing = 400 * np.sin(2 * np.pi * 0.7 * t)[:, None, None] * np.array([1.0, 0.3, -0.5])
    waved = swing + np.arange(9).reshape(3, 3) * 100 + rng.normal(0, 1.0, (n, 3, 3))  # 1 mm noise
    scattered = rng.uniform(-400, 400, size=(n, 3, 3))
    assert not clearly_independent(t, waved, PERIOD) and smooth_motion(t, waved, PERIOD).continuous
    assert clearly_independent(t, scattered, PERIOD) and not smooth_motion(t, scattered, PERIOD).continuous
    # a short recording is all sample: its fits decide
    assert not clearly_independent(t[:300], scattered[:300], PERIOD)


def test_the_motion_window_is_chosen_by_how_well_it_predicts_the_placements() -> None:
    t = np.arange(300) * PERIOD
    rng = np.random.default_rng(2)
    fast = 200 * np.sin(2 * np.pi * 2.0 * t)[:, None, None] * np.ones((3, 3))  # 2.5 m/s, 2 Hz
    slow = 200 * np.sin(2 * np.pi * 0.2 * t)[:, None, None] * np.ones((3, 3)) + rng.normal(0, 2.0, (300, 3, 3))
    fast_window, slow_window = (smooth_motion(t, points, PERIOD).window for points in (fast, slow))
    assert fast_window in MOTION_WINDOWS and slow_window in MOTION_WINDOWS
    assert fast_window[0] < slow_window[0]  # a narrow window for the fast wave, a wide one for the noisy slow one


def test_a_timeline_from_stamps_places_each_view_at_its_own_instant() -> None:
    stamps = 1.7e9 + np.arange(10)[:, None] * PERIOD + np.array([0.0, 0.012, -0.004])
    stamps[3, 2] = np.nan
    observations = WandObservations(np.arange(10), ("a", "b", "c"), np.zeros((10, 3, 3, 2)), stamps)
    line = timeline(observations)
    assert line.unit == "s" and not line.simultaneous
    assert np.allclose(line.periods, PERIOD) and line.period == pytest.approx(PERIOD)
    assert np.allclose(
        line.view_times[0], [-0.008 / 3, 0.012 - 0.008 / 3, -0.004 - 0.008 / 3], atol=1e-6
    )  # 0.24 us: float64 at 1.7e9 s
    assert np.allclose(line.view_times[3], [-0.006, 0.006, 0.0], atol=1e-6)
    assert np.allclose(line.placement_times + line.origin, np.nanmean(stamps, axis=1), rtol=0, atol=1e-6)
    frames = timeline(WandObservations(np.array([4, 5, 7]), ("a",), np.zeros((3, 1, 3, 2))))
    assert frames.unit == "frames" and frames.simultaneous and frames.placement_times.tolist() == [4, 5, 7]


def test_stamps_that_cannot_be_seconds_are_refused_naming_the_camera() -> None:
    stamps = np.stack([np.arange(10) * 33.3, np.arange(10) * PERIOD], axis=1) + 1000.0  # milliseconds in "a"
    observations = WandObservations(np.arange(10), ("a", "b"), np.zeros((10, 2, 3, 2)), stamps)
    with pytest.raises(TimingError, match=r"camera 'a': its images are 33\.3 apart"):
        timeline(observations)


def test_a_frame_period_survives_dropped_images() -> None:
    stamps = np.arange(100) * PERIOD
    dropped = np.delete(stamps, np.random.default_rng(3).choice(100, 40, replace=False))
    assert frame_period(dropped) == pytest.approx(PERIOD, rel=1e-9)


@pytest.mark.parametrize("kept", [0.1, 0.2, 0.3])
def test_a_frame_period_survives_losing_most_images(kept: float) -> None:
    # A lossy transport (or a camera that rarely sees the wand): under a quarter of the spacings are
    # single periods, so their lower quartile is two or more (before: 2 and 3 periods, a collector's
    # result said 66.7 ms for a 30 fps rig).
    for seed in range(5):
        rng = np.random.default_rng(seed)
        stamps = np.flatnonzero(rng.random(600) < kept) * PERIOD + rng.normal(0.0, 2e-4, size=1)
        jittered = stamps + rng.normal(0.0, 2e-4, stamps.size)  # free-running cameras' stamp jitter
        assert frame_period(stamps) == pytest.approx(PERIOD, rel=1e-9)
        assert frame_period(jittered) == pytest.approx(PERIOD, rel=0.01)
    assert frame_period(np.array([0.0, 2, 4, 6, 8, 10]) * PERIOD) == pytest.approx(2 * PERIOD)  # no single seen
    bursts = np.r_[np.arange(100) * PERIOD, 10 * PERIOD + 0.001, 50 * PERIOD + 0.001]  # two images 1 ms late
    assert frame_period(bursts) == pytest.approx(PERIOD, rel=1e-9)


def test_views_are_moved_along_their_cameras_image_track_to_the_placement_time() -> None:
    n = 40
    t = np.arange(n) * PERIOD
    track = lambda time: np.stack([100 + 600 * time, 50 + 300 * time**2], axis=-1)  # noqa: E731  px
    offset = np.array([0.0, 0.011])  # camera b exposes 11 ms after a
    stamps = 1.7e9 + t[:, None] + offset
    uv = np.stack([np.repeat(track(t + o)[:, None, :], 3, axis=1) for o in offset], axis=1)  # (n, 2, 3, 2)
    line = timeline(WandObservations(np.arange(n), ("a", "b"), uv, stamps))
    aligned = align_views(uv, line)
    middle = slice(6, n - 6)
    at_placement = track(line.placement_times[middle] + stamps[0, 0] - 1.7e9)
    for c in range(2):
        assert np.allclose(aligned[middle, c, 0], at_placement, atol=1e-6)


@pytest.mark.parametrize("markers", [2, 3, 5])
def test_views_of_any_wand_are_moved_with_the_cameras_timing(markers: int) -> None:
    # Each camera's estimated offset (and readout) moves every marker of its views, whatever the wand's count.
    n = 40
    t = np.arange(n) * PERIOD
    track = lambda time: np.stack([100 + 600 * time, 50 + 300 * time**2], axis=-1)  # noqa: E731  px
    offset = np.array([0.0, 0.011])
    stamps = 1.7e9 + np.repeat(t[:, None], 2, axis=1)  # stamped together, exposed 11 ms apart
    uv = np.stack([np.repeat(track(t + o)[:, None, :], markers, axis=1) for o in offset], axis=1)
    line = timeline(WandObservations(np.arange(n), ("a", "b"), uv, stamps))
    aligned = align_views(uv, line, np.array([[0.0, 0.0], [-0.011, 0.0]]), np.array([480.0, 480.0]))
    middle = slice(6, n - 6)
    for c in range(2):
        assert np.allclose(aligned[middle, c], track(t[middle])[:, None, :], atol=1e-6)


def test_significance_is_a_joint_chi_square_test() -> None:
    covariance = np.diag([1e-6, 1e-6])  # 1 ms standard deviations
    assert not significant(np.array([0.001, -0.001]), covariance)  # chi2 2 < 9.2
    assert significant(np.array([0.0035, 0.0]), covariance)  # chi2 12.25
    assert not significant(np.zeros(0), np.zeros((0, 0)))


def test_a_camera_whose_rate_changes_gets_a_warning() -> None:
    steady = 1.7e9 + np.arange(200) / 30.0
    slowing = np.concatenate([1.7e9 + np.arange(100) / 30.0, 1.7e9 + 100 / 30.0 + np.arange(1, 101) / 25.0])
    stamps = np.stack([steady, slowing[:200]], axis=1)
    observations = WandObservations(np.arange(200), ("a", "b"), np.zeros((200, 2, 3, 2)), stamps)
    (warning,) = rate_warnings(observations, timeline(observations))
    assert warning.startswith("b: its frame period changed from 33.33 ms to 40.00 ms")
