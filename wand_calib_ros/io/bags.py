"""rosbag2 image recordings (mcap or sqlite3) through the ``rosbags`` library, no ROS install needed.

Writing: one ``sensor_msgs/Image`` topic per camera (``/<camera>/image_raw``), as
rosbag2 (mcap, sqlite3) or as a ROS 1 ``.bag`` (for ROS 1 tools and conversion tests).
Reading: ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` messages of
the requested topics, decoded to numpy arrays with their encoding and header
stamp. ROS 1 bags can be read after ``rosbags-convert --src x.bag --dst out``.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.images import image_array

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


@dataclass(frozen=True, eq=False)
class ImageFrame:
    """One decoded image.

    Attributes:
        camera: the camera whose topic it came from.
        stamp_ns: header stamp, nanoseconds.
        image: (H, W) or (H, W, channels) array.
        encoding: sensor_msgs/Image encoding ("mono8" for decoded compressed images).
    """

    camera: str
    stamp_ns: int
    image: NDArray[Any]
    encoding: str


def image_message(image: NDArray[np.uint8], stamp_ns: int, frame_id: str, encoding: str = "mono8") -> object:
    """A sensor_msgs/Image of an 8-bit array (mono8 (H, W) or 3-channel colour)."""
    header = _TYPESTORE.types["std_msgs/msg/Header"](
        stamp=_TYPESTORE.types["builtin_interfaces/msg/Time"](
            sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9)
        ),
        frame_id=frame_id,
    )
    height, width = image.shape[:2]
    data = np.ascontiguousarray(image).reshape(-1).view(np.uint8)
    return _TYPESTORE.types[IMAGE](
        header=header,
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=data.size // height,
        data=data,
    )


def write_image_bag(
    path: Path, frames: Iterable[tuple[str, int, NDArray[np.uint8]]], cameras: Iterable[str], *, storage: str = "mcap"
) -> None:
    """Write (camera, stamp_ns, mono8 image) frames to a new bag at ``path``.

    Args:
        path: the rosbag2 directory (or ROS 1 ``.bag`` file) to create; must not exist.
        frames: in time order.
        cameras: camera names; topics are ``/<camera>/image_raw``.
        storage: "mcap" or "sqlite3" (rosbag2), or "ros1".
    """
    if storage == "ros1":
        _write_ros1(path, frames, cameras)
        return
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections = {
            name: writer.add_connection(f"/{name}/image_raw", IMAGE, typestore=_TYPESTORE) for name in cameras
        }
        for camera, stamp_ns, image in frames:
            message = image_message(image, stamp_ns, camera)
            writer.write(connections[camera], stamp_ns, _TYPESTORE.serialize_cdr(message, IMAGE))


def _write_ros1(path: Path, frames: Iterable[tuple[str, int, NDArray[np.uint8]]], cameras: Iterable[str]) -> None:
    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    with Ros1Writer(path) as writer:
        connections = {name: writer.add_connection(f"/{name}/image_raw", IMAGE, typestore=store) for name in cameras}
        for seq, (camera, stamp_ns, image) in enumerate(frames):
            stamp = types["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9))
            height, width = image.shape[:2]
            message = types[IMAGE](
                header=types["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=camera),
                height=height,
                width=width,
                encoding="mono8",
                is_bigendian=0,
                step=width,
                data=np.ascontiguousarray(image).reshape(-1),
            )
            writer.write(connections[camera], stamp_ns, store.serialize_ros1(message, IMAGE))


def _decode(message: Any, msgtype: str, where: str) -> tuple[NDArray[Any], str]:
    if msgtype == COMPRESSED:
        data = np.frombuffer(bytes(message.data), dtype=np.uint8)
        image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise FormatError(where, "compressed image could not be decoded")
        return image, "mono8"
    try:
        return image_array(message), message.encoding
    except ValueError as error:
        raise FormatError(where, str(error)) from None


def count_images(path: Path, topics: dict[str, str]) -> int:
    """Messages on the given topics (0 when the bag cannot be read: reading reports the error)."""
    try:
        reader = Reader(path)
        reader.open()
    except Exception:
        return 0
    try:
        return sum(c.msgcount for c in reader.connections if c.topic in set(topics.values()))
    finally:
        reader.close()


def read_image_frames(path: Path, topics: dict[str, str]) -> Iterator[ImageFrame]:
    """Decoded images of the given camera topics in bag order.

    Args:
        path: a rosbag2 directory (mcap or sqlite3).
        topics: camera name -> topic.

    Raises:
        FormatError: not a readable bag, none of the topics present, or a broken message.
    """
    try:
        reader = Reader(path)
        reader.open()
    except Exception as error:  # rosbags raises several types for unreadable bags
        raise FormatError(path, f"not a readable rosbag2 ({type(error).__name__}: {error})") from None
    try:
        by_topic = {topic: camera for camera, topic in topics.items()}
        connections = [c for c in reader.connections if c.topic in by_topic and c.msgtype in (IMAGE, COMPRESSED)]
        if not connections:
            available = ", ".join(sorted(f"{c.topic} ({c.msgtype})" for c in reader.connections)) or "none"
            raise FormatError(
                path, f"none of the image topics {', '.join(sorted(by_topic))} is in the bag (it has: {available})"
            )
        try:
            for connection, _, raw in reader.messages(connections=connections):
                where = f"{path} topic {connection.topic}"
                message: Any = _TYPESTORE.deserialize_cdr(raw, connection.msgtype)
                stamp = message.header.stamp
                image, encoding = _decode(message, connection.msgtype, where)
                yield ImageFrame(by_topic[connection.topic], stamp.sec * 10**9 + stamp.nanosec, image, encoding)
        except FormatError:
            raise
        except Exception as error:
            raise FormatError(path, f"corrupt bag ({type(error).__name__}: {error})") from None
    finally:
        reader.close()
