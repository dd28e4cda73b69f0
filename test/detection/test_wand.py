"""Wand identification and label tracking on rendered recordings with known truth."""

from __future__ import annotations

import numpy as np
import pytest
from rigs import true_views

from wand_calib_ros.collection.recording import detect_recording
from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.detection.blobs import Blobs
from wand_calib_ros.detection.tracking import track_labels
from wand_calib_ros.detection.wand import WandDetection, WandOptions, identify_wand
from wand_calib_ros.io.bags import ImageFrame
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario


def _blobs(points: list[list[float]]) -> Blobs:
    n = len(points)
    return Blobs(np.array(points, dtype=float), np.ones(n, np.int64), np.ones(n), np.zeros(n, bool))


def test_collinear_triple_is_labelled_by_the_longer_side() -> None:
    detection = identify_wand(_blobs([[300, 100], [100, 100], [233.4, 100.2], [50, 400]]), WandOptions(ratio=2.0))
    assert detection.reason is None
    # B is the middle point; A is the end farther from it (|AB| = L1 > L2 = |BC|)
    assert np.allclose(detection.points, [[100, 100], [233.4, 100.2], [300, 100]])
    assert not detection.ambiguous and abs(detection.image_ratio - 2.0) < 0.01


def test_no_wand_reasons() -> None:
    assert identify_wand(_blobs([])).reason == "no_blobs"
    assert identify_wand(_blobs([[1, 1], [50, 50]])).reason == "too_few_blobs"
    assert identify_wand(_blobs([[0, 0], [100, 0], [50, 60]])).reason == "not_collinear"
    two_wands = [[0, 0], [200, 0], [300, 0], [0, 300], [200, 300], [300, 300]]
    assert identify_wand(_blobs(two_wands)).reason == "competing_triples"


def _moving(detection: WandDetection, step: int) -> WandDetection:
    """The detection moved down by 4 px per step (a waved wand: every point moves)."""
    assert detection.points is not None
    moved = detection.points + np.array([0.0, 4.0 * step])
    return WandDetection(moved, detection.quality, None, detection.ambiguous, detection.image_ratio)


CLEAR = WandDetection(np.array([[0.0, 0], [20, 0], [30, 0]]), 1.0, None, False, 2.0)  # ratio 2: trusted
AMBIGUOUS = WandDetection(np.array([[31.0, 0], [16, 0], [1, 0]]), 1.0, None, True, 1.0)


def test_ambiguous_labels_are_settled_by_neighbouring_frames() -> None:
    sequence = [(0, _moving(AMBIGUOUS, 0)), (33_000_000, _moving(CLEAR, 1)), (66_000_000, _moving(AMBIGUOUS, 2))]
    labelled = track_labels(sequence)
    assert labelled[0] is not None and labelled[2] is not None
    assert np.allclose(labelled[0][0], [1, 0]) and np.allclose(labelled[2][0], [1, 8])
    far = track_labels([(0, AMBIGUOUS), (10**9, CLEAR)])
    assert far[0] is None


def test_a_track_that_never_moves_is_no_wand_and_one_that_stops_stays_the_wand() -> None:
    from wand_calib_ros.detection.tracking import StreamLabeller

    still = [(i * 33_000_000, CLEAR) for i in range(60)]  # lamps in a row, two seconds long
    assert all(points is None for points in track_labels(still))
    labeller = StreamLabeller(max_hold_ns=100_000_000)
    out = [r for i in range(12) for r in labeller.push(i * 33_000_000, CLEAR)] + labeller.flush()
    assert len(out) == 12 and all(r.points is None and r.reason == "still" for r in out)  # held, then given up
    arrives = [(i * 33_000_000, _moving(CLEAR, i)) for i in range(5)]  # the wand laid on the floor ...
    rests = [(int((5 + i) * 33_000_000), _moving(CLEAR, 4)) for i in range(60)]  # ... and left there 2 s
    labelled = track_labels(arrives + rests)
    assert all(points is not None for points in labelled)


def test_rendered_recording_meets_the_detection_targets() -> None:
    scenario = paper_fisheye_scenario()
    rng = np.random.default_rng(3)
    recording = render_recording(scenario, 240, 30.0, RenderOptions(), rng)
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    detected = detect_recording(frames, scenario.rig)
    observations, stats = detected.observations, detected.stats
    drawn = recording.drawn
    assert set(observations.frames) <= set(drawn.frames)  # one frame per instant, numbered alike
    rows = np.searchsorted(drawn.frames, observations.frames)  # (the first ones: the wand not yet seen moving)
    uv, stamps = np.full(drawn.uv.shape, np.nan), np.full(drawn.uv.shape[:2], np.nan)
    uv[rows], stamps[rows] = observations.uv, observations.stamps
    observations = WandObservations(drawn.frames, observations.camera_names, uv, stamps)
    visible = np.all(np.isfinite(drawn.uv), axis=(2, 3))
    found = observations.complete
    assert found[visible].mean() >= 0.98
    errors = np.linalg.norm(observations.uv - true_views(drawn, observations), axis=-1)[found & visible]
    assert (errors > 3).mean() <= 0.005  # labels correct on >= 99.5 % of the points written
    good = errors[errors <= 3]
    assert np.sqrt(np.mean(good**2) / 2) < 0.15  # per-coordinate RMS centre error
    assert sum(s.detected for s in stats.values()) == found.sum()


def test_spurious_reflections_rarely_produce_a_wrong_triple() -> None:
    scenario = paper_fisheye_scenario()
    rng = np.random.default_rng(4)
    recording = render_recording(scenario, 200, 30.0, RenderOptions(reflection_rate=1.0), rng)
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    detected = detect_recording(frames, scenario.rig)
    observations, stats = detected.observations, detected.stats
    written = observations.complete
    errors = np.linalg.norm(observations.uv - true_views(recording.drawn, observations), axis=-1).max(axis=-1)
    wrong = (errors > 3) & written
    assert wrong.sum() <= 0.005 * recording.drawn.uv.shape[0] * len(scenario.cameras)
    assert sum(s.rejected["competing_triples"] for s in stats.values()) + written.sum() > 0


def test_unusable_images_are_counted_by_reason_not_raised() -> None:
    scenario = paper_fisheye_scenario()
    rng = np.random.default_rng(5)
    good = render_recording(scenario, 12, 30.0, RenderOptions(), rng)
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in good.frames]
    t = 2_000_000_000_000_000_000
    frames += [
        ImageFrame("cam0", t, np.zeros((10, 10), np.uint8), "mono8"),  # wrong size
        ImageFrame("cam0", t + 10**8, np.zeros((480, 640), np.uint8), "mono8"),  # empty (black)
        ImageFrame("cam0", t + 2 * 10**8, np.full((480, 640), 255, np.uint8), "mono8"),  # saturated
        ImageFrame("cam0", t + 3 * 10**8, np.zeros((480, 640, 3), np.uint8), "yuv422"),  # unknown encoding
        ImageFrame("cam1", t, rng.integers(0, 255, (480, 640), dtype=np.uint8), "mono8"),  # all noise
    ]
    detected = detect_recording(frames, scenario.rig)
    observations, stats = detected.observations, detected.stats
    assert stats["cam0"].rejected["wrong_size"] == 1
    assert stats["cam0"].rejected["encoding"] == 1  # named for what it is, not as a wrong size
    assert stats["cam0"].rejected["no_blobs"] == 2
    # the first images show a wand not yet seen to move: no view until it has moved from where it began
    assert 12 - 3 <= stats["cam0"].detected == observations.complete[:, 0].sum() <= 12
    cam1 = stats["cam1"]
    assert cam1.images == 13 and cam1.detected + sum(cam1.rejected.values()) == 13
    assert cam1.detected == observations.complete[:, 1].sum() <= 12  # the noise image gives no wand


def test_other_cameras_settle_ambiguous_views_of_independent_placements() -> None:
    from wand_calib_ros.core.pipeline import calibrate
    from wand_calib_ros.detection.consistency import label_across_cameras

    scenario = paper_fisheye_scenario()
    rng = np.random.default_rng(8)
    recording = render_recording(scenario, 200, 30.0, RenderOptions(), rng, independent=True)
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    detected = detect_recording(frames, scenario.rig)
    observations, ambiguous = detected.observations, detected.ambiguous
    assert ambiguous  # no continuity between independent placements
    result = calibrate(scenario.rig, observations)
    settled_obs, settled = label_across_cameras(observations, ambiguous, result, scenario.wand)
    assert len(settled) > 0.3 * len(ambiguous)
    errors = np.linalg.norm(settled_obs.uv - true_views(recording.drawn, settled_obs), axis=-1)
    finite = np.isfinite(errors)
    assert (errors[finite] > 3).sum() == 0


def test_stream_labeller_holds_back_then_follows_a_live_stream() -> None:
    from wand_calib_ros.detection.tracking import Released, StreamLabeller

    labeller = StreamLabeller(max_hold_ns=100_000_000)
    assert labeller.push(0, _moving(AMBIGUOUS, 0)) == []  # held: nothing decides it yet
    assert labeller.push(33_000_000, _moving(CLEAR, 1)) == []
    released = labeller.push(100_000_000, _moving(AMBIGUOUS, 2))  # the hold ends: the track is decided
    assert [r.stamp_ns for r in released] == [0, 33_000_000, 100_000_000]
    assert all(r.points is not None and np.allclose(r.points[0], [0, 4 * i], atol=1.5) for i, r in enumerate(released))
    follow = labeller.push(133_000_000, _moving(CLEAR, 3))  # a decided track releases at once
    assert len(follow) == 1 and follow[0].points is not None and np.allclose(follow[0].points[0], [0, 12])
    assert labeller.push(10**9, AMBIGUOUS) == []  # a new track after the gap
    assert labeller.flush() == [Released(10**9, None, "ambiguous", 1)]  # a second track: one view tells nothing


def test_a_misleading_stretch_of_image_ratios_is_outvoted_by_its_track() -> None:
    # The wand turns towards the camera: for a few frames the image ratio favours C, B, A.
    truth = np.array([[0.0, 0], [20, 0], [30, 0]])
    sequence = []
    for i, ratio in enumerate([2.0, 1.8, 1.6, 1.3, 0.8, 0.65, 0.65, 0.8, 1.3, 1.8, 2.0]):
        points = truth + np.array([i * 0.5, 4.0 * i])
        own = points if ratio >= 1 else points[::-1].copy()  # the detector orders by the image ratio
        sequence.append((i * 33_000_000, WandDetection(own, 1.0, None, False, max(ratio, 1 / ratio))))
    labelled = track_labels(sequence)
    assert all(np.allclose(points, truth + np.array([i * 0.5, 4.0 * i])) for i, points in enumerate(labelled))


def test_a_camera_repeating_a_stamp_is_labelled_without_error() -> None:
    from wand_calib_ros.detection.recording import CameraStream

    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 20, 30.0, RenderOptions(), np.random.default_rng(5))
    stream = CameraStream(scenario.cameras[0].spec, WandOptions(ratio=2.0))
    out = []
    for camera, stamp, image in recording.frames:
        if camera == "cam0":
            out += stream.push(stamp, image, "mono8") + stream.push(stamp, image, "mono8")  # a driver sent it twice
    out += stream.flush()
    assert len(out) == 40 and [o.stamp_ns for o in out] == sorted(o.stamp_ns for o in out)


def test_images_without_a_view_wait_behind_the_views_the_labeller_holds() -> None:
    """A camera's outcomes leave in stamp order, whatever the labeller holds back (the synchroniser downstream
    drops a stamp going backwards as a lossy transport's)."""
    from wand_calib_ros.detection.recording import CameraStream

    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 40, 30.0, RenderOptions(), np.random.default_rng(6))
    stream = CameraStream(scenario.cameras[0].spec, WandOptions(ratio=2.0))
    out, held = [], 0
    for i, (_, stamp, image) in enumerate(f for f in recording.frames if f[0] == "cam0"):
        blank = i % 5 == 4  # every fifth image lost its view
        out += stream.push(stamp, np.zeros_like(image) if blank else image, "mono8")
        held = max(held, i + 1 - len(out))
    out += stream.flush()
    assert held > 1  # the labeller did hold views back while blank images came
    assert [o.stamp_ns for o in out] == sorted(f[1] for f in recording.frames if f[0] == "cam0")
    assert sum(o.points is None for o in out) >= 8


def test_a_wand_with_an_led_cut_by_the_border_is_not_written() -> None:
    points = [[2.0, 100.0], [102.0, 100.0], [152.0, 100.0]]
    whole = _blobs(points)
    cut = Blobs(whole.centres, whole.areas, whole.peaks, whole.saturated, np.array([True, False, False]))
    assert identify_wand(whole).points is not None
    detection = identify_wand(cut)
    assert detection.points is None and detection.reason == "at_border"


def test_a_wand_whose_ends_look_alike_is_refused_by_the_detector() -> None:
    from wand_calib_ros.core.model.rig import WandSpec
    from wand_calib_ros.detection.errors import UnsupportedWandError

    assert WandOptions.for_wand(WandSpec.from_lengths(400, 200)).ratio == 2.0
    five = WandOptions.for_wand(WandSpec((0.0, 120.0, 250.0, 400.0, 600.0)))
    assert five.n_points == 5 and five.positions[2] == pytest.approx(250 / 600)
    with pytest.raises(UnsupportedWandError, match="spaced symmetrically"):
        WandOptions.for_wand(WandSpec((0.0, 200.0, 400.0, 600.0)))


def test_a_two_led_wand_is_the_images_two_blobs_and_a_third_blob_rejects_the_view() -> None:
    from wand_calib_ros.core.model.rig import WandSpec

    options = WandOptions.for_wand(WandSpec((0.0, 600.0)))
    two = _blobs([[100.0, 200.0], [300.0, 250.0]])
    found = identify_wand(two, options)
    assert found.reason is None and found.points is not None and np.array_equal(found.points, two.centres)
    three = _blobs([[100.0, 200.0], [300.0, 250.0], [500.0, 20.0]])
    assert identify_wand(three, options).reason == "competing_triples"
    close = _blobs([[100.0, 200.0], [101.0, 201.0]])
    assert identify_wand(close, options).reason == "not_collinear"


def test_an_l_frame_is_the_floor_tools_blobs_as_found_and_the_calibrated_cameras_label_them() -> None:
    from dataclasses import replace

    from wand_calib_ros.core.after.world_frame import floor_of
    from wand_calib_ros.detection.blobs import BlobOptions
    from wand_calib_ros.detection.recording import detect_image
    from wand_calib_ros.sim.floor import floor_tool
    from wand_calib_ros.sim.render import render_image
    from wand_calib_ros.sim.scenarios import SCENARIOS

    scenario = SCENARIOS["ring6"](n_placements=10)
    l_frame = np.array([[0.0, 0.0, 0.0], [500.0, 0.0, 0.0], [0.0, 300.0, 0.0]])
    rig = replace(scenario.rig, floor_tool=tuple(tuple(p) for p in l_frame.tolist()))
    rng = np.random.default_rng(5)
    truth = floor_tool(scenario, l_frame, 0.0, rng)
    detected = np.full_like(truth.observations.uv, np.nan)
    for f, frame in enumerate(truth.observations.uv):
        for c, camera in enumerate(scenario.cameras):
            if not np.all(np.isfinite(frame[c])):
                continue
            image = render_image(camera.spec.image_size, frame[c], RenderOptions(), rng)
            _, found = detect_image(image, "mono8", BlobOptions(), WandOptions.for_rig(rig), None)
            assert found.tool and found.points is not None
            nearest = np.linalg.norm(found.points[:, None] - frame[c][None], axis=-1).min(axis=1)
            assert np.all(nearest < 0.3)  # the three blobs, in the order found
            detected[f, c] = found.points
            _, wand_only = detect_image(image, "mono8", BlobOptions(), WandOptions.for_wand(rig.wand), None)
            assert wand_only.points is None  # no tool in the rig: three blobs that are no wand are rejected
    assert np.isfinite(detected[..., 0]).sum() >= 3 * 15 * 3  # the three fisheyes see it in every frame
    models, poses = tuple(c.model for c in scenario.cameras), tuple(c.pose for c in scenario.cameras)
    exact = np.eye(len(models) * N_CAMERA_PARAMS) * 1e-12
    world = floor_of(models, poses, detected, exact, 0.1, positions_mm=rig.wand.positions_mm, tool_mm=l_frame).world
    estimated, true = world.world_from_reference, truth.world_from_reference
    assert np.linalg.norm(estimated.inverse().translation - true.inverse().translation) < 1.0
    assert np.degrees(np.arccos(np.clip(estimated.rotation[2] @ true.rotation[2], -1.0, 1.0))) < 0.1
