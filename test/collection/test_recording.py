"""A recording's images through the detector: stamp order from a bag's arrival order, in bounded memory; a recording
kept a camera to a file searched a camera to a worker process, with the same detections."""

from __future__ import annotations

from collections.abc import Iterator
from functools import partial

import numpy as np
import pytest

from wand_calib_ros.collection.recording import REORDER_S, detect_cameras_apart, detect_recording, in_stamp_order
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.bags import ImageFrame
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario

PIXEL = np.zeros((1, 1), np.uint8)


def test_frames_come_in_stamp_order_holding_only_the_reorder_window() -> None:
    rng = np.random.default_rng(0)
    stamps = np.arange(600) * 10_000_000 + rng.integers(0, 300_000_000, 600)  # 10 ms apart, up to 0.3 s late
    arrived = [ImageFrame("cam", int(s), PIXEL, "mono8") for s in stamps]
    read = 0

    def reading() -> Iterator[ImageFrame]:
        nonlocal read
        for frame in arrived:
            read += 1
            yield frame

    held = []
    out = []
    for frame in in_stamp_order(reading(), 500_000_000):
        out.append(frame.stamp_ns)
        held.append(read - len(out))
    assert out == sorted(stamps.tolist())
    assert max(held) <= 0.5e9 / 10e6 + 30 + 1  # the window's frames and the ones arriving late into it, not all 600


def test_images_arriving_out_of_order_are_searched_in_order_and_a_late_one_is_counted() -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 240, 30.0, RenderOptions(), np.random.default_rng(3))
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    in_order = detect_recording(frames, scenario.rig)
    # as a bag may store them: each camera's images a few frames behind the others'
    delay = {name: 0.1 * c for c, name in enumerate(scenario.rig.camera_names)}
    arrived = sorted(frames, key=lambda f: f.stamp_ns + delay[f.camera] * 1e9)
    shuffled = detect_recording(arrived, scenario.rig)
    assert np.array_equal(shuffled.observations.uv, in_order.observations.uv, equal_nan=True)
    # one image stored long after its time: counted late, everything else as before
    first = next(k for k, f in enumerate(frames) if f.camera == "cam1" and f.stamp_ns > frames[0].stamp_ns + 1e9)
    stored_late = [*frames[:first], *frames[first + 1 :]]
    stored_late.insert(
        next(k for k, f in enumerate(stored_late) if f.stamp_ns > frames[first].stamp_ns + 1.5e9 * REORDER_S),
        frames[first],
    )
    late = detect_recording(stored_late, scenario.rig)
    assert late.stats["cam1"].rejected["late"] == 1
    assert late.stats["cam1"].images == in_order.stats["cam1"].images
    assert late.reports["cam1"].no_view.get("late") == 1


def test_cameras_searched_apart_in_worker_processes_give_the_recordings_detections() -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 150, 30.0, RenderOptions(), np.random.default_rng(5))
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    together = detect_recording(frames, scenario.rig)
    readers = {name: partial(_camera_of, frames, name) for name in scenario.rig.camera_names}
    counted: list[int] = []
    for workers in (1, 2):
        apart = detect_cameras_apart(readers, scenario.rig, workers=workers, progress=counted.append)
        np.testing.assert_array_equal(apart.observations.uv, together.observations.uv)
        np.testing.assert_array_equal(apart.observations.stamps, together.observations.stamps)
        np.testing.assert_array_equal(apart.tracks, together.tracks)
        assert apart.stats == together.stats and apart.reports == together.reports
        assert counted[-1] == len(frames)  # every image counted once, the last count told


def test_a_camera_that_cannot_be_read_in_its_worker_is_one_error_naming_it() -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 30, 30.0, RenderOptions(), np.random.default_rng(5))
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    readers = {name: partial(_camera_of, frames, name) for name in scenario.rig.camera_names}
    readers[scenario.rig.camera_names[1]] = _broken
    with pytest.raises(WandCalibError, match=r"cam1\.mp4: cannot be decoded"):
        detect_cameras_apart(readers, scenario.rig, workers=2)


def _camera_of(frames: list[ImageFrame], camera: str) -> Iterator[ImageFrame]:
    return (frame for frame in frames if frame.camera == camera)


def _broken() -> Iterator[ImageFrame]:
    raise FormatError("cam1.mp4", "cannot be decoded as a video")
    yield  # (a generator)
