"""rosbag2 image recordings: write-read round trip (mcap, sqlite3) and clear errors."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from wand_calib_ros.io.bags import COMPRESSED, read_image_frames, write_image_bag
from wand_calib_ros.io.errors import FormatError


def _frames(rng: np.random.Generator) -> list[tuple[str, int, np.ndarray]]:
    return [
        (camera, 1_000_000_000 + i * 33_333_333, rng.integers(0, 255, size=(48, 64), dtype=np.uint8))
        for i in range(5)
        for camera in ("cam0", "cam1")
    ]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_write_read_round_trip(tmp_path: Path, storage: str) -> None:
    frames = _frames(np.random.default_rng(0))
    write_image_bag(tmp_path / "bag", frames, ("cam0", "cam1"), storage=storage)
    back = list(read_image_frames(tmp_path / "bag", {"cam0": "/cam0/image_raw", "cam1": "/cam1/image_raw"}))
    assert len(back) == len(frames)
    for (camera, stamp, image), frame in zip(frames, back, strict=True):
        assert frame.camera == camera and frame.stamp_ns == stamp and frame.encoding == "mono8"
        assert np.array_equal(frame.image, image)


def test_compressed_images_are_decoded(tmp_path: Path) -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    image = np.zeros((48, 64), np.uint8)
    image[10:14, 20:24] = 200
    ok, png = cv2.imencode(".png", image)
    assert ok
    header = store.types["std_msgs/msg/Header"](
        stamp=store.types["builtin_interfaces/msg/Time"](sec=1, nanosec=5), frame_id="cam0"
    )
    message = store.types[COMPRESSED](header=header, format="png", data=png.ravel())
    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection("/cam0/image_raw", COMPRESSED, typestore=store)
        writer.write(connection, 1_000_000_005, store.serialize_cdr(message, COMPRESSED))
    (frame,) = read_image_frames(tmp_path / "bag", {"cam0": "/cam0/image_raw"})
    assert frame.stamp_ns == 1_000_000_005 and np.array_equal(frame.image, image)


def test_missing_topics_name_what_the_bag_has(tmp_path: Path) -> None:
    write_image_bag(tmp_path / "bag", _frames(np.random.default_rng(1)), ("cam0", "cam1"))
    with pytest.raises(
        FormatError, match=r"none of the image topics /camX/image_raw is in the bag \(it has: /cam0/image_raw"
    ):
        list(read_image_frames(tmp_path / "bag", {"camX": "/camX/image_raw"}))


def test_corrupt_or_missing_bag_is_a_format_error(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="not a readable rosbag2"):
        list(read_image_frames(tmp_path / "nothing", {"cam0": "/cam0/image_raw"}))
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9, storage_identifier: mcap}\n")
    with pytest.raises(FormatError):
        list(read_image_frames(broken, {"cam0": "/cam0/image_raw"}))


def test_ros1_bag_reads_after_rosbags_convert(tmp_path: Path) -> None:
    frames = _frames(np.random.default_rng(2))
    write_image_bag(tmp_path / "in.bag", frames, ("cam0", "cam1"), storage="ros1")
    convert = shutil.which("rosbags-convert", path=str(Path(sys.executable).parent))
    assert convert is not None
    subprocess.run(
        [convert, "--src", str(tmp_path / "in.bag"), "--dst", str(tmp_path / "out")],
        check=True,
        capture_output=True,
        timeout=120,
    )
    back = list(read_image_frames(tmp_path / "out", {"cam0": "/cam0/image_raw", "cam1": "/cam1/image_raw"}))
    assert [(f.camera, f.stamp_ns) for f in back] == [(camera, stamp) for camera, stamp, _ in frames]
    assert all(np.array_equal(f.image, image) for f, (_, _, image) in zip(back, frames, strict=True))
