"""The live collection without ROS, fed as a rig's cameras feed the collector: stamps that jump, a camera that
pauses, falls silent or sends images it cannot use, images dropped on the way, a clock step under every camera,
a bag replayed after /reset, and auto_calibrate. Nothing collected is lost, each fault is said once per cause
and shown while it lasts, and the stored buffer calibrates. The collector node hands its messages to this
session (a few tests in ``test/nodes`` keep the real node and messages)."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from wand_calib_ros import cli
from wand_calib_ros.collection.coverage import CoverageThresholds
from wand_calib_ros.collection.estimate import Estimate
from wand_calib_ros.collection.estimate_round import Round
from wand_calib_ros.collection.session import CollectionSession, SessionSettings
from wand_calib_ros.collection.stream_faults import Said
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.io.rig_yaml import save_rig
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.render import Recording, RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, paper_three_camera_scenario, simulate

EPOCH = 1_700_000_000 * 10**9
PERIOD = 33_333_333
#: A stamp per (frame, camera), or None: the camera sends nothing for that frame.
Stamps = Callable[[int, int], int | None]
#: Each part of a take keeps at least this share of the frames a clean take keeps.
KEPT = 0.95
FRAMES = 240
HALF = FRAMES // 2


def _settings(**changed: Any) -> SessionSettings:
    """The collector's defaults (no running estimate, no auto_calibrate), with ``changed``."""
    values: dict[str, Any] = {
        "capacity": 20000,
        "min_motion_px": 2.0,
        "measure_brightness": True,
        "sync_tolerance_ns": 0,
        "label_hold_ns": 1_000_000_000,
        "floor_hold_s": 2.0,
        "mask_take_ns": 1_000_000_000,
        "coverage": CoverageThresholds(),
        "estimate_period_s": None,
        "estimate_max_placements": 200,
        "auto": None,
    }
    return SessionSettings(**(values | changed))


class Rig:
    """A session and the cameras feeding it, on an arrival clock of the test's own (nothing waits): a frame's
    images 2 ms apart, frames at the cameras' period plus any ``pause_ns``; feedback once a second of it, as the
    collector's timer asks."""

    def __init__(self, tmp_path: Path, rig: RigSpec, *, points: bool = False, **settings: Any) -> None:
        save_rig(rig, tmp_path / "cameras.yaml")
        self.tmp_path, self.rig = tmp_path, rig
        topics = {name: f"/{name}/{'wand_points' if points else 'image_raw'}" for name in rig.camera_names}
        changed = {"measure_brightness": not points, **settings}
        self.session = CollectionSession(rig, _settings(**changed), tmp_path / "out", {}, topics)
        self.said: list[Said] = []
        self.now_ns, self.pause_ns, self.frame, self.asked_ns = 10**9, 0, 0, 10**9
        self.feedback: list[Any] = []

    def _arrive(self, index: int, period_ns: int) -> int:
        self.now_ns = 10**9 + self.pause_ns + self.frame * period_ns + index * 2_000_000
        return self.now_ns

    def _tick(self) -> None:
        while self.now_ns - self.asked_ns >= 10**9:
            self.asked_ns += 10**9
            answer = self.session.feedback(self.asked_ns)
            self.said += answer.said
            self.feedback.append(answer)

    def points(self, uv: np.ndarray, stamps: Stamps, period_ns: int = PERIOD) -> None:
        """(F, C, 3, 2) views as a detector's points, camera by camera within a frame, stamped by ``stamps``."""
        for k, frame in enumerate(uv):
            for c, name in enumerate(self.rig.camera_names):
                stamp = stamps(k, c)
                if stamp is None:
                    continue
                seen = frame[c] if np.all(np.isfinite(frame[c])) else None
                self.said += self.session.points(name, stamp, self._arrive(c, period_ns), seen)
            self.frame += 1
            self._tick()
        self.session.flush()

    def images(self, frames: list[list[tuple[str, int, Any, str]]], period_ns: int = PERIOD) -> None:
        """Frames of (camera, stamp, pixels or None, encoding) images."""
        for frame in frames:
            for c, (camera, stamp, pixels, encoding) in enumerate(frame):
                answer = self.session.image(camera, stamp, self._arrive(c, period_ns), pixels, encoding, show=False)
                self.said += answer.said
            self.frame += 1
            self._tick()

    def log(self) -> str:
        return "\n".join(item.line for item in self.said)

    def views(self) -> int:
        return int(self.session.buffer.observations().complete.sum())

    def calibrates(self, time_offsets: str = "fixed") -> dict[str, Any]:
        """The stored buffer calibrates (``wand-calib calibrate`` on its file; the time offsets fixed: independent
        placements have no motion to time)."""
        self.session.flush()
        self.session.buffer.sync()
        out = self.tmp_path / "out"
        command = ["-q", "calibrate", "--time-offsets", time_offsets, "--cameras", str(self.tmp_path / "cameras.yaml")]
        command += ["--observations", str(out / "observations.csv"), "--output", str(out / "result.yaml")]
        assert cli.main(command) == 0
        return dict(yaml.safe_load((out / "result.yaml").read_text()))


@pytest.fixture
def rigs(tmp_path: Path) -> Any:
    made: list[Rig] = []

    def make(rig: RigSpec, **settings: Any) -> Rig:
        made.append(Rig(tmp_path / f"rig{len(made)}", rig, **settings))
        return made[-1]

    yield make
    for each in made:
        each.session.close()


def _steady(k: int, c: int) -> int:
    return EPOCH + k * PERIOD


FAULTS: dict[str, tuple[Stamps, str]] = {
    # cam1's driver restarted on a clock 60 s behind
    "restarted driver": (lambda k, c: _steady(k, c) - (60 * 10**9 if c == 1 and k >= 100 else 0), "60.0 s back"),
    # cam1's stamps leapt 3 h ahead (the others must not lose their views)
    "stamps 3 h ahead": (lambda k, c: _steady(k, c) + (3 * 3600 * 10**9 if c == 1 and k >= 100 else 0), "3.0 h ahead"),
    # the host's clock stepped back 30 s under every camera
    "clock step": (lambda k, c: _steady(k, c) - (30 * 10**9 if k >= 100 else 0), "30.0 s back"),
    # cam1's driver does not stamp
    "unstamped": (lambda k, c: 0 if c == 1 else _steady(k, c), "stamped 0"),
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_stamps_that_jump_start_a_segment_and_lose_nothing(rigs: Any, fault: str) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(7), n=240).observations.uv
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0)
    stamps, said = FAULTS[fault]
    if fault == "unstamped":  # stamped by their arrival: at the camera's own pace
        uv = uv[:90]
    rig.points(uv, stamps)
    complete = int(np.all(np.isfinite(uv), axis=(2, 3)).all(axis=1).sum())
    stored = rig.session.buffer.observations()
    assert int(stored.complete.all(axis=1).sum()) == complete  # every frame all cameras saw, whole
    assert rig.views() == int(np.all(np.isfinite(uv), axis=(2, 3)).sum())  # and every single view
    assert stored.stamps is not None and np.all(np.diff(stored.stamps[np.isfinite(stored.stamps[:, 0]), 0]) > 0)
    log = rig.log()
    assert said in log and log.count("new segment") <= 3  # said once per jump (the clock step: per camera)
    result = rig.calibrates()
    if fault == "restarted driver":  # every placement after the jump too
        assert result["metrics"]["placements_used"] == complete


def test_a_silent_camera_is_said_while_silent_and_resumes(rigs: Any) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(9), n=300).observations.uv
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0)
    silent = range(100, 200)  # cam1 sends nothing for 100 frames, 3.3 s of stamps and of time

    def stamps(k: int, c: int) -> int | None:
        return None if c == 1 and k in silent else _steady(k, c)

    rig.points(uv[:200], stamps)
    during = rig.feedback[-1]
    assert any("no image for" in line for line in during.faults["cam1"])  # shown while it lasts
    rig.points(uv[200:], lambda k, c: stamps(k + 200, c))
    assert not any("no image for" in line for line in rig.feedback[-1].faults["cam1"])
    log = rig.log()
    assert log.count("cam1: no image for") == 1 and "cam1: images again after 3." in log
    seen = np.all(np.isfinite(uv), axis=(2, 3))
    seen[100:200, 1] = False
    assert rig.views() == int(seen.sum())  # the others' views while it was silent, its own after
    rig.calibrates()


def test_dropped_images_are_counted_and_said(rigs: Any) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(10), n=300).observations.uv
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0)
    lost = set(range(60, 84)) | set(range(200, 224))  # 48 images of cam2 at 120 Hz never arrive
    rig.points(uv, lambda k, c: None if c == 2 and k in lost else EPOCH + k * 8_333_333, period_ns=8_333_333)
    counts = rig.session.feedback(rig.now_ns).counts
    assert (counts["cam2"]["dropped"], counts["cam0"]["dropped"]) == (48, 0)
    log = rig.log()  # said once, when the first gap was seen (the count goes on in the diagnostics)
    assert log.count("images missing in its stamps") == 1 and "cam2: 24 images missing in its stamps so far" in log


def test_the_same_bag_replayed_after_reset_is_stored_again(rigs: Any) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(11), n=200).observations.uv
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0)
    rig.points(uv, _steady)
    first = rig.views()
    assert rig.session.reset().startswith("buffer cleared; backup ")
    assert rig.views() == 0
    rig.points(uv, _steady)  # its stamps start over
    assert rig.views() == first == int(np.all(np.isfinite(uv), axis=(2, 3)).sum())
    stored = rig.session.buffer.observations()
    assert stored.stamps is not None  # the new take keeps its images' own stamps
    assert np.allclose(np.nanmin(stored.stamps), EPOCH / 1e9) and np.nanmax(stored.stamps) < EPOCH / 1e9 + 7.0
    assert not (rig.tmp_path / "out" / "events.csv").exists()  # nothing was shifted
    rig.calibrates()


def test_a_clock_step_within_a_take_is_stored_moved_and_kept_in_the_events(rigs: Any) -> None:
    scenario = paper_three_camera_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(15), n=200).observations.uv
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0)
    rig.points(uv, lambda k, c: _steady(k, c) - (30 * 10**9 if k >= 100 else 0))  # the host's clock stepped back
    stored = rig.session.buffer.observations()
    assert stored.stamps is not None and np.all(np.diff(stored.stamps[:, 0]) > 0)  # one time line
    events = (rig.tmp_path / "out" / "events.csv").read_text().splitlines()
    shifted = [line for line in events if ",stamps_shifted," in line]
    assert [line.split(",")[2] for line in shifted] == ["cam0", "cam1", "cam2"]
    assert all("its stamps jumped -30.000 s" in line and "stored moved by +30.000 s" in line for line in shifted)
    assert sum("every camera's stamps jumped together" in line for line in shifted) == 2  # (known from the second)


@pytest.fixture(scope="module")
def recording() -> Recording:
    return render_recording(paper_three_camera_scenario(), FRAMES, 30.0, RenderOptions(), np.random.default_rng(21))


def _by_frame(recording: Recording) -> list[list[tuple[str, int, Any, str]]]:
    """The recording's images grouped by frame (every camera's image of one instant), mono8."""
    stamps = sorted({stamp for _, stamp, _ in recording.frames})
    index = {stamp: k for k, stamp in enumerate(stamps)}
    frames: list[list[tuple[str, int, Any, str]]] = [[] for _ in stamps]
    for camera, stamp, pixels in recording.frames:
        frames[index[stamp]].append((camera, stamp, pixels, "mono8"))
    return frames


def _stored_frames(rig: Rig, stamps_ns: list[int], shift_ns: int = 0) -> int:
    """How many of the given frames' stamps (cam0's, plus ``shift_ns``) the buffer holds with every camera's view."""
    rig.session.flush()
    stored = rig.session.buffer.observations()
    assert stored.stamps is not None
    kept = {round(s, 4) for s in stored.stamps[stored.complete.all(axis=1), 0]}
    return sum(round((s + shift_ns) / 1e9, 4) in kept for s in stamps_ns)


def _clean_count(recording: Recording, frames: range) -> int:
    """Frames whose wand every camera saw whole (what a clean take keeps, but for its first still instants)."""
    seen = np.all(np.isfinite(recording.drawn.uv), axis=(2, 3)).all(axis=1)
    return int(seen[list(frames)].sum())


def _first_half(rigs: Any, recording: Recording) -> tuple[Rig, list[list[tuple[str, int, Any, str]]], list[int]]:
    """A session that has taken the recording's first HALF frames: it, the frames still to come and the first
    half's stamps (cam0's)."""
    rig = rigs(paper_three_camera_scenario().rig)
    frames = _by_frame(recording)
    rig.images(frames[:HALF])
    return rig, frames[HALF:], [frame[0][1] for frame in frames[:HALF]]


@pytest.mark.parametrize("pause_s", [5, 30])
def test_a_paused_stream_loses_nothing_and_is_not_called_a_jump(rigs: Any, recording: Recording, pause_s: int) -> None:
    rig, rest, first = _first_half(rigs, recording)
    rig.pause_ns += pause_s * 10**9  # the bag paused: nothing arrives for pause_s, its stamps then go on
    rig.images(rest)
    second = [frame[0][1] for frame in rest]
    assert _stored_frames(rig, first) >= KEPT * _clean_count(recording, range(10, HALF))
    assert _stored_frames(rig, second) >= KEPT * _clean_count(recording, range(HALF + 10, FRAMES))
    assert "jumped" not in rig.log() and "new segment" not in rig.log()
    rig.calibrates()


@pytest.mark.parametrize("step_s", [-30, 30])
def test_a_clock_step_under_every_camera_is_one_shift_for_all(rigs: Any, recording: Recording, step_s: int) -> None:
    rig, rest, first = _first_half(rigs, recording)
    stepped = [[(c, stamp + step_s * 10**9, p, e) for c, stamp, p, e in frame] for frame in rest]
    rig.images([stepped[0][1:], *stepped[1:]])  # (the step falls between cam0's and cam1's image of a frame)
    assert _stored_frames(rig, first) >= KEPT * _clean_count(recording, range(10, HALF))
    stored = rig.session.buffer.observations()
    whole = int(stored.complete.all(axis=1).sum()) - _stored_frames(rig, first)
    assert whole >= KEPT * _clean_count(recording, range(HALF + 10, FRAMES))
    way = "back" if step_s < 0 else "ahead"
    log = rig.log()
    assert log.count("jumped") == 1 and f"every camera's stamps jumped 30.0 s {way} together" in log  # said once
    rig.calibrates()


def test_the_same_recording_after_reset_is_a_new_take_stored_in_full(rigs: Any, recording: Recording) -> None:
    rig = rigs(paper_three_camera_scenario().rig)
    frames = _by_frame(recording)
    rig.images(frames)
    rig.session.flush()
    first = int(rig.session.buffer.observations().complete.all(axis=1).sum())
    rig.session.reset()
    rig.images(frames)  # its stamps start over
    rig.session.flush()
    again = int(rig.session.buffer.observations().complete.all(axis=1).sum())
    assert first >= KEPT * _clean_count(recording, range(10, FRAMES)) and again >= KEPT * first
    rig.calibrates()


def test_images_it_cannot_use_are_said_and_the_good_ones_between_are_kept(rigs: Any) -> None:
    scenario = paper_fisheye_scenario()
    recording = render_recording(scenario, 90, 30.0, RenderOptions(), np.random.default_rng(12))
    rig = rigs(scenario.rig)

    def spoiled(k: int, pixels: np.ndarray) -> tuple[Any, str]:
        if not (k % 3 == 1 and 30 <= k < 60):
            return pixels, "mono8"
        kind = (k // 3) % 3  # every third image of cam1 in the middle third is unusable
        if kind == 0:
            return np.ascontiguousarray(pixels[::2, ::2]), "mono8"  # 320x240
        return (pixels.astype(np.float32), "32FC1") if kind == 1 else (None, "mono8")  # (None: truncated data)

    frames: dict[int, list[tuple[str, int, Any, str]]] = {}
    count = dict.fromkeys(scenario.rig.camera_names, 0)
    for camera, stamp, pixels in recording.frames:
        image, encoding = spoiled(count[camera], pixels) if camera == "cam1" else (pixels, "mono8")
        frames.setdefault(count[camera], []).append((camera, stamp, image, encoding))
        count[camera] += 1
    rig.images([frames[k] for k in sorted(frames)])
    shown = " ".join(rig.session.feedback(rig.now_ns).faults["cam1"])
    assert "320x240" in shown and "32FC1" in shown and "truncated" in shown
    stats = rig.session.streams["cam1"].stats.rejected
    assert (stats["wrong_size"], stats["encoding"], stats["bad_image"]) == (3, 4, 3)  # images 31, 34, ... 58
    assert rig.log().count("cam1: its images are 320x240, the rig file says 640x480") == 1
    rig.session.flush()
    stored = rig.session.buffer.observations()
    assert stored.stamps is not None
    kept = {round(s, 6) for s in stored.stamps[np.isfinite(stored.stamps[:, 1]), 1]}
    good = [stamp for camera, stamp, _ in recording.frames if camera == "cam1"]
    usable = [s for k, s in enumerate(good) if not (k % 3 == 1 and 30 <= k < 60)]
    assert len([s for s in usable if round(s / 1e9, 6) in kept]) >= len(usable) - 6  # the first: still, unseen


def test_stretches_of_unusable_images_never_make_the_good_ones_late(rigs: Any, recording: Recording) -> None:
    rig = rigs(paper_three_camera_scenario().rig)
    bad = {*range(40, 70), *range(120, 150)}  # cam1: two stretches of a second of images it cannot use
    frames = [
        [(c, s, None if c == "cam1" and k in bad else p, e) for c, s, p, e in frame]  # (None: truncated data)
        for k, frame in enumerate(_by_frame(recording))
    ]
    rig.images(frames)
    good = [frame[0][1] for k, frame in enumerate(frames) if k not in bad]
    clean = _clean_count(recording, range(10, FRAMES)) - _clean_count(recording, range(40, 70))
    clean -= _clean_count(recording, range(120, 150))
    assert _stored_frames(rig, good) >= KEPT * clean
    assert rig.session.sync.stats.late.get("cam1", 0) == 0
    assert "truncated" in rig.log()
    rig.calibrates()


class _Estimates:
    """A running estimate that has converged: its latest round, the result given."""

    def __init__(self, result: Any) -> None:
        self.latest: Any = Estimate(Round(result, None, None, 100, 0.1), 0.0, {})
        self.failure = None

    def step(self, now: float, snapshot: Any) -> None:
        return None

    def restart(self) -> None:
        pass

    def close(self) -> None:
        pass


def test_auto_calibrate_starts_once_when_ready_retries_after_a_failure_and_stops_after_a_calibration(
    rigs: Any,
) -> None:
    scenario = paper_fisheye_scenario()
    uv = simulate(scenario, 0.5, np.random.default_rng(14), n=300).observations.uv
    ready = CoverageThresholds(20, 0.0, 0.0, 15, 1, 1.0)  # (what this short take has)
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0, auto=(5.0, 20.0), coverage=ready)
    rig.points(uv, _steady)
    result = calibrate(scenario.rig, rig.session.buffer.observations())
    started: list[Callable[[bool, str], None]] = []

    def calibrate_now(source: str, done: Callable[[bool, str], None]) -> bool:
        assert source == "auto-calibrate"
        started.append(done)
        return True

    rig.session.calibrate_now = calibrate_now
    rig.session.estimates = _Estimates(result)  # type: ignore[assignment]
    first = rig.session.feedback(rig.now_ns)
    assert len(started) == 1 and any("auto-calibrate: coverage is ready" in s.line for s in first.said)
    assert first.rig_values["auto_calibrate"] == "calibrating"
    rig.session.feedback(rig.now_ns)
    assert len(started) == 1  # not again while it runs
    started[0](False, "no luck")
    failed = rig.session.feedback(rig.now_ns)
    assert len(started) == 1 and str(failed.rig_values["auto_calibrate"]).startswith("failed, retrying")
    rig.session.estimates = _Estimates(result)  # type: ignore[assignment]  # a new round
    rig.session.feedback(rig.now_ns)
    assert len(started) == 2
    rig.session.after_calibrate(result)
    assert rig.session.feedback(rig.now_ns).rig_values["auto_calibrate"] == "calibrated"
    assert len(started) == 2


def _free_running_take(seconds: float, seed: int) -> tuple[Any, WandObservations, tuple[Any, ...]]:
    """paper3 waved for ``seconds`` by free-running cameras at 30 fps (0.25 px): its scenario, its views and clocks."""
    scenario = paper_three_camera_scenario()
    options = TakeOptions(duration_s=seconds)
    trajectory = take_trajectory(scenario, options, np.random.default_rng(seed))
    clocks = options.clocks(3, np.random.default_rng(seed + 1))
    takes = film(scenario, trajectory, clocks, seconds, np.random.default_rng(seed + 2))
    return scenario, observe(scenario.rig.camera_names, takes, 0.25, np.random.default_rng(seed + 3)), clocks


def test_a_camera_seconds_ahead_is_held_lined_up_from_the_wand_and_then_stored_with_the_others(rigs: Any) -> None:
    scenario, observations, clocks = _free_running_take(20.0, 5)
    stamps = observations.stamps
    assert stamps is not None
    uv, ahead = observations.uv, 2_300_000_000  # cam1's clock is 2.3 s ahead from its first image
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0)

    def stamp(k: int, c: int) -> int | None:
        return None if not np.isfinite(stamps[k, c]) else round(stamps[k, c] * 1e9) + (ahead if c == 1 else 0)

    rig.points(uv, stamp)
    log = rig.log()
    assert log.count("cam1: its stamps stand 2.3 s from the other cameras'") == 1  # said once, while held
    found = re.findall(r"cam1's clock is (2\.\d{3}) s ahead of cam0's, found from the wand's motion", log)
    assert len(found) == 1 and abs(float(found[0]) - 2.3) < 0.02  # (2.3 s and the free-running latencies)
    stored = rig.session.buffer.observations()
    assert stored.stamps is not None
    with_cam1 = np.flatnonzero(stored.complete[:, 1] & stored.complete[:, 0])
    first = stored.stamps[with_cam1[0], 0] - np.nanmin(stamps)
    assert first < 8.0  # stored with the others from a few seconds into the take on
    seen = np.isfinite(uv).all(axis=(2, 3))
    later = np.flatnonzero(np.isfinite(stamps[:, 0]) & (stamps[:, 0] - np.nanmin(stamps) > first + 1.0))
    kept = int(stored.complete[:, 1].sum())
    assert kept >= 0.95 * int(seen[later, 1].sum())  # and from then on, every view of it
    assert np.nanmedian(stored.stamps[with_cam1, 1] - stored.stamps[with_cam1, 0]) > 2.29  # its own stamps kept
    result = rig.calibrates("auto")  # the buffer's calibration finds the offset again: the whole of it
    latency = {f"cam{c}": clock.latency_s for c, clock in enumerate(clocks)}
    offsets = {name: entry.get("time_offset_s", 0.0) for name, entry in result["cameras"].items()}
    reference = result["reference_camera"]
    truth = {n: latency[n] + (2.3 if n == "cam1" else 0.0) for n in latency}
    for name, offset in offsets.items():
        assert abs(offset - (truth[name] - truth[reference])) < 0.002


def test_cameras_whose_clocks_agree_are_never_held(rigs: Any) -> None:
    scenario, observations, _ = _free_running_take(8.0, 6)
    stamps = observations.stamps
    assert stamps is not None
    rig = rigs(scenario.rig, points=True, min_motion_px=0.0)
    rig.points(observations.uv, lambda k, c: None if not np.isfinite(stamps[k, c]) else round(stamps[k, c] * 1e9))
    assert "held" not in rig.log() and "found from the wand's motion" not in rig.log()
    assert rig.views() == int(np.isfinite(observations.uv).all(axis=(2, 3)).sum())
