"""A rig's camera streams' faults: silence (after a start-up grace), unusable images, said once per cause."""

from __future__ import annotations

from wand_calib_ros.collection.stream_faults import StreamFaults, image_problem

S = 10**9
EPOCH = 1_700_000_000 * S


def _send(faults: StreamFaults, camera: str, t: float) -> list[str]:
    _, said = faults.arrived(camera, EPOCH + int(t * S), int(t * S))
    return [item.line for item in said]


def test_silence_is_said_once_shown_while_it_lasts_and_its_end_said() -> None:
    faults = StreamFaults(("cam0", "cam1"), {"cam0": "cam0/image_raw", "cam1": "cam1/image_raw"})
    _send(faults, "cam0", 0.0)
    shown, said = faults.check(int(0.005 * S))  # cam1's first image is about to come: no fault yet
    assert shown == {"cam0": [], "cam1": []} and said == []
    for k in range(1, 100):  # cam0 sends; cam1 never does
        _send(faults, "cam0", k / 30)
    shown, said = faults.check(int(3.3 * S))
    assert shown["cam1"] == ["no image on cam1/image_raw yet while the other cameras send (check its topic)"]
    assert [s.line for s in said] == ["cam1: " + shown["cam1"][0]]
    assert _send(faults, "cam1", 3.31) == ["cam1: images again after 3.3 s without"]  # since the rig began
    for k in range(100, 200):  # both send, then cam1 falls silent at 5 s
        _send(faults, "cam0", k / 30)
        if k < 150:
            _send(faults, "cam1", k / 30)
    shown, said = faults.check(int(7.1 * S))
    assert shown["cam1"] == ["no image for 2 s while the other cameras send (unplugged? its driver stopped?)"]
    assert len(said) == 1 and faults.check(int(7.1 * S))[1] == []  # said once
    assert faults.check(int(9.0 * S)) == ({"cam0": [], "cam1": []}, [])  # every camera stopped: the take ended


def test_unusable_images_are_said_once_per_cause_and_shown_for_a_while() -> None:
    faults = StreamFaults(("cam0",), {})
    text = image_problem("wrong_size", (240, 320), "mono8", (640, 480))
    assert text == (
        "its images are 320x240, the rig file says 640x480: check its image_size and image_topic (a scaled or "
        "cropped stream?)"
    )
    assert [s.line for s in faults.unusable("cam0", "wrong_size", text, 0)] == [f"cam0: {text}"]
    assert faults.unusable("cam0", "wrong_size", text, S) == []  # the same cause, again: not said again
    assert faults.check(3 * S)[0]["cam0"] == [text]  # shown for 5 s after the last
    assert faults.check(7 * S)[0]["cam0"] == []
    assert image_problem("no_blobs", (480, 640), "mono8", (640, 480)) is None  # not a fault of the stream
    assert "32FC1, which the detector does not read" in str(image_problem("encoding", (480, 640), "32FC1", (640, 480)))
