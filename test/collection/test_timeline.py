"""Each camera's time line: stamps made continuous across a restarted driver, a clock step, a leap ahead and
unstamped images; images behind or repeated passed over once, here."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.collection.timeline import TimeLines

PERIOD = 33_333_333
EPOCH = 1_700_000_000 * 10**9


def _feed(
    timelines: TimeLines, stamps: dict[str, list[int]], arrivals: list[int]
) -> tuple[dict[str, list[int]], list[str]]:
    """Each frame's images in camera order; the continued stamps per camera and the jumps' descriptions."""
    out: dict[str, list[int]] = {name: [] for name in stamps}
    said = []
    for k, arrival in enumerate(arrivals):
        for name, values in stamps.items():
            placed = timelines.place(name, values[k], arrival + 1_000_000 * list(stamps).index(name))
            out[name].append(placed.stamp_ns)
            if placed.jump is not None:
                said.append(placed.jump.describe())
    return out, said


def test_steady_stamps_are_kept_as_they_are_and_a_silence_is_no_jump() -> None:
    arrivals = [k * PERIOD for k in range(100)] + [(k + 400) * PERIOD for k in range(100)]  # silent for 10 s
    stamps = {name: [EPOCH + a + 5_000_000 for a in arrivals] for name in ("cam0", "cam1")}
    continued, said = _feed(TimeLines(("cam0", "cam1")), stamps, arrivals)
    assert said == [] and continued == stamps


def test_one_restarted_driver_continues_on_the_others_time() -> None:
    arrivals = [k * PERIOD for k in range(200)]
    stamps = {name: [EPOCH + a for a in arrivals] for name in ("cam0", "cam1", "cam2")}
    stamps["cam1"] = [s - (60 * 10**9 if k >= 100 else 0) for k, s in enumerate(stamps["cam1"])]  # back 60 s
    timelines = TimeLines(("cam0", "cam1", "cam2"))
    continued, said = _feed(timelines, stamps, arrivals)
    assert len(said) == 1 and "cam1: its stamps jumped 60.0 s back" in said[0]
    # it stays within the arrival jitter (1 ms between the cameras here) of the others' stamps: frames stay frames
    assert np.max(np.abs(np.array(continued["cam1"]) - np.array(continued["cam0"]))) <= 2_000_000
    assert np.all(np.diff(continued["cam1"]) > 0) and timelines.segments("cam1") == 2


def test_a_clock_step_of_every_camera_shifts_them_alike_and_a_leap_ahead_of_one_does_not_move_the_others() -> None:
    arrivals = [k * PERIOD for k in range(300)]
    stamps = {name: [EPOCH + a for a in arrivals] for name in ("cam0", "cam1")}
    for name in stamps:  # the host's clock stepped back 30 s at frame 100
        stamps[name] = [s - (30 * 10**9 if k >= 100 else 0) for k, s in enumerate(stamps[name])]
    stamps["cam1"] = [s + (3 * 3600 * 10**9 if k >= 200 else 0) for k, s in enumerate(stamps["cam1"])]  # 3 h ahead
    continued, said = _feed(TimeLines(("cam0", "cam1")), stamps, arrivals)
    assert len(said) == 3 and "3.0 h ahead" in said[2]
    assert continued["cam0"] == continued["cam1"]  # triggered together: the same stamps after both jumps
    assert np.all(np.diff(continued["cam0"]) == PERIOD)


def test_unstamped_images_take_the_other_cameras_time_and_gaps_are_counted_as_drops() -> None:
    arrivals = [k * 8_333_333 for k in range(240)]  # 120 Hz
    stamps = {"cam0": [EPOCH + a for a in arrivals], "cam1": [0] * len(arrivals)}
    lost = set(range(40, 64)) | set(range(150, 174))  # 48 images of cam0 never arrive, in two gaps of 0.2 s
    timelines = TimeLines(("cam0", "cam1"))
    said = []
    for k, arrival in enumerate(arrivals):
        if k not in lost:
            timelines.place("cam0", stamps["cam0"][k], arrival)
        placed = timelines.place("cam1", 0, arrival + 1_000_000)
        said += [] if placed.jump is None else [placed.jump.describe()]
        assert k in lost or abs(placed.stamp_ns - stamps["cam0"][k]) <= 1_000_000  # the others' time, arrival later
    assert said == ["cam1: its images are stamped 0 (its driver does not stamp them): using their arrivals"]
    assert timelines.dropped("cam0") == 48 and timelines.dropped("cam1") == 0


def test_images_behind_or_repeated_are_passed_over_and_counted_and_a_file_s_stamps_are_kept() -> None:
    timelines = TimeLines(("cam0", "cam1"))
    arrivals = [k * PERIOD for k in range(10)]
    orders = [timelines.place("cam0", EPOCH + a, a).order for a in arrivals]
    # a lossy transport: an image delivered after a newer one, the same image twice
    late = timelines.place("cam0", EPOCH + 5 * PERIOD, 10 * PERIOD)
    again = timelines.place("cam0", EPOCH + 9 * PERIOD, 10 * PERIOD + 1)
    assert orders == ["next"] * 10 and (late.order, again.order) == ("behind", "repeat")
    assert (late.stamp_ns, late.jump) == (EPOCH + 5 * PERIOD, None)  # a reordering, not a jump
    assert timelines.place("cam0", EPOCH + 10 * PERIOD, 11 * PERIOD).order == "next"
    assert timelines.values("cam0") == {
        "dropped": 0,
        "stamp_segments": 1,
        "out_of_order_images": 1,
        "duplicate_stamps": 1,
    }
    assert timelines.values("cam1") == {"dropped": 0, "stamp_segments": 1} and timelines.totals() == (1, 1)
    # a recording read from a file (no arrivals): its stamps as they are, hours apart or not
    recorded = TimeLines(("cam0",))
    stamps = [EPOCH, EPOCH + 3600 * 10**9, EPOCH + 3600 * 10**9, EPOCH + 10]
    assert [(p.stamp_ns, p.order) for p in (recorded.place("cam0", s, None) for s in stamps)] == [
        (EPOCH, "next"),
        (EPOCH + 3600 * 10**9, "next"),
        (EPOCH + 3600 * 10**9, "repeat"),
        (EPOCH + 10, "behind"),
    ]
