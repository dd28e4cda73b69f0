"""Coverage feedback while waving."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wand_calib_ros.collection.coverage import CoverageThresholds, CoverageTracker
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, paper_three_camera_scenario, ring_scenario, simulate


def test_a_well_waved_wand_is_ready() -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(0))
    tracker = CoverageTracker(scenario.rig, CoverageThresholds(min_theta_fraction=0.5))
    for uv in data.observations.uv:
        tracker.add(uv)
    status = tracker.status()
    assert status.ready, status.messages()
    assert status.shared[0, 1] == 300


def test_a_small_corner_of_the_view_is_named() -> None:
    scenario = replace(paper_fisheye_scenario(), volume=np.array([[-150.0, -150.0, 1350.0], [150.0, 150.0, 1650.0]]))
    data = simulate(scenario, 0.5, np.random.default_rng(1), n=60)
    tracker = CoverageTracker(scenario.rig)
    for uv in data.observations.uv:
        tracker.add(uv)
    status = tracker.status()
    assert not status.ready
    message = next(m for m in status.messages() if m.startswith("cam0:"))
    assert "60 of 100 placements" in message and "top-left" in message and "uncovered" in message


def test_disconnected_groups_are_reported() -> None:
    scenario = ring_scenario()
    data = simulate(scenario, 0.5, np.random.default_rng(2))
    tracker = CoverageTracker(scenario.rig, CoverageThresholds(min_placements=1, min_image_fraction=0.0))
    complete = data.observations.complete
    for uv, row in zip(data.observations.uv, complete, strict=True):
        if not (row[:3].any() and row[3:].any()):  # hide every placement linking the two halves
            tracker.add(uv)
    status = tracker.status()
    assert not status.connected
    assert any("cam0, cam1, cam2 | cam3, cam4, cam5" in m for m in status.messages())


def test_a_wand_always_level_and_equally_far_is_told_to_turn_and_move() -> None:
    scenario = paper_fisheye_scenario()
    rng = np.random.default_rng(3)
    tracker = CoverageTracker(scenario.rig, CoverageThresholds(min_placements=1, min_image_fraction=0.0))
    for _ in range(100):  # level, 200 px long, anywhere in the images
        start = rng.uniform([20, 20], [400, 460])
        points = start + np.array([[0.0, 0.0], [133.3, 0.0], [200.0, 0.0]])
        tracker.add(np.stack([points, points]))
    message = tracker.status().messages()[0]
    assert "wand held in 1 of 6 directions in the image (need 4): turn it" in message
    assert "always about as far (image length ratio 1.00, need 1.2)" in message


def test_a_minute_of_waving_meets_the_default_thresholds_on_every_simulated_rig() -> None:
    from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
    from wand_calib_ros.sim.scenarios import SCENARIOS

    for name, seconds in (("paper", 20.0), ("mixed", 20.0), ("paper3", 60.0), ("mixed3", 60.0), ("ring6", 60.0)):
        scenario = SCENARIOS[name]()
        rng = np.random.default_rng(7)
        options = TakeOptions(duration_s=seconds, free_running=False)
        clocks = options.clocks(len(scenario.cameras), rng)
        takes = film(scenario, take_trajectory(scenario, options, rng), clocks, seconds, rng)
        tracker = CoverageTracker(scenario.rig)
        for uv in observe(scenario.rig.camera_names, takes, 0.3, rng).uv:
            tracker.add(uv)
        status = tracker.status()
        assert status.ready, (name, status.messages())


def test_what_is_missing_says_what_would_be_enough() -> None:
    scenario = replace(paper_fisheye_scenario(), volume=np.array([[-150.0, -150.0, 1350.0], [150.0, 150.0, 1650.0]]))
    tracker = CoverageTracker(scenario.rig, CoverageThresholds(min_image_fraction=0.5, min_theta_fraction=0.7))
    for uv in simulate(scenario, 0.5, np.random.default_rng(1), n=60).observations.uv:
        tracker.add(uv)
    message = next(m for m in tracker.status().messages() if m.startswith("cam0:"))
    assert "% of the image covered (need 50 %)" in message
    reach = np.degrees(tracker.reach[0])
    assert f"deg off-axis of {reach:.0f} (need {0.7 * reach:.0f}): move it towards the image border" in message


def test_frames_added_at_once_count_as_added_one_by_one() -> None:
    scenario = ring_scenario()  # mixed lenses: not every camera sees every frame
    data = simulate(scenario, 0.5, np.random.default_rng(3), n=200)
    one_by_one, at_once = CoverageTracker(scenario.rig), CoverageTracker(scenario.rig)
    for uv in data.observations.uv:
        one_by_one.add(uv)
    at_once.add(data.observations.uv)
    at_once.add(data.observations.uv[:0])  # nothing: nothing changes
    for name in ("cells", "placements", "shared", "max_theta", "directions", "lengths"):
        assert np.array_equal(getattr(one_by_one, name), getattr(at_once, name)), name
    assert one_by_one.status().messages() == at_once.status().messages()


def _wands(rng: np.random.Generator, n: int, u_range: tuple[float, float], half: tuple[float, float]) -> np.ndarray:
    """(n, 3, 2) wands of every direction, their half lengths uniform in ``half``, their centres uniform in
    ``u_range`` x the image's height."""
    centre = np.column_stack([rng.uniform(*u_range, n), rng.uniform(60, 420, n)])
    angle, half = rng.uniform(0, np.pi, n), rng.uniform(*half, n)
    step = np.column_stack([np.cos(angle), np.sin(angle)]) * half[:, None]
    return np.stack([centre - step, centre, centre + step], axis=1)


def test_progress_is_one_short_line_per_camera_naming_its_worst_gap() -> None:
    scenario = paper_three_camera_scenario()
    rng = np.random.default_rng(4)
    everywhere, right = _wands(rng, 300, (70, 570), (15, 60)), _wands(rng, 300, (600, 615), (8, 20))  # cam1: its right
    tracker = CoverageTracker(scenario.rig)
    tracker.add(np.stack([everywhere, right, everywhere], axis=1))
    lines = tracker.status().progress()
    assert len(lines) == 1 and lines[0].startswith("cam1: "), lines  # the others miss nothing: no line of theirs
    assert lines[0].endswith("% of the image covered, left side empty") and len(lines[0]) <= 100, lines
