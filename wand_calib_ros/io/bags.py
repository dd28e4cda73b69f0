"""rosbag2 image recordings (mcap or sqlite3) through the ``rosbags`` library, no ROS install needed.

Writing: one ``sensor_msgs/Image`` topic per camera (``/<camera>/image_raw``), or
``sensor_msgs/CompressedImage`` on ``/<camera>/image_raw/compressed`` (image_transport's
name) for compressed frames, as rosbag2 (mcap, sqlite3) or as a ROS 1 ``.bag`` (for ROS 1
tools and conversion tests). Reading: ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``
messages of the requested topics, decoded to numpy arrays with their encoding and header
stamp (:func:`read_image_frames`), or as they are (:func:`read_image_messages`, for a replay).
ROS 1 bags can be read after ``rosbags-convert --src x.bag --dst out``.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.images import decode_compressed, image_array

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
#: image_transport's suffix of a compressed image topic.
COMPRESSED_SUFFIX = "/compressed"
_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

#: A frame to write: (camera, stamp ns, mono8 image) or (camera, stamp ns, image or compressed bytes, encoding
#: or CompressedImage format).
BagFrame = tuple[str, int, NDArray[Any]] | tuple[str, int, NDArray[Any] | bytes, str]


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


def _header(stamp_ns: int, frame_id: str) -> Any:
    return _TYPESTORE.types["std_msgs/msg/Header"](
        stamp=_TYPESTORE.types["builtin_interfaces/msg/Time"](
            sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9)
        ),
        frame_id=frame_id,
    )


def image_message(image: NDArray[Any], stamp_ns: int, frame_id: str, encoding: str = "mono8") -> object:
    """A sensor_msgs/Image of an array (mono8 (H, W), mono16, or 3-channel colour)."""
    height, width = image.shape[:2]
    data = np.ascontiguousarray(image).reshape(-1).view(np.uint8)
    return _TYPESTORE.types[IMAGE](
        header=_header(stamp_ns, frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=data.size // height,
        data=data,
    )


def compressed_message(data: bytes, stamp_ns: int, frame_id: str, fmt: str) -> object:
    """A sensor_msgs/CompressedImage."""
    payload = np.frombuffer(data, dtype=np.uint8)
    return _TYPESTORE.types[COMPRESSED](header=_header(stamp_ns, frame_id), format=fmt, data=payload)


def write_image_bag(path: Path, frames: Iterable[BagFrame], cameras: Iterable[str], *, storage: str = "mcap") -> None:
    """Write frames to a new bag at ``path``.

    Args:
        path: the rosbag2 directory (or ROS 1 ``.bag`` file) to create; must not exist.
        frames: in time order; compressed ones (bytes) go to ``/<camera>/image_raw/compressed``.
        cameras: camera names; raw topics are ``/<camera>/image_raw``.
        storage: "mcap" or "sqlite3" (rosbag2), or "ros1" (raw mono8 only).
    """
    if storage == "ros1":
        _write_ros1(path, frames, cameras)
        return
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
    names = list(cameras)
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections: dict[tuple[str, bool], Any] = {}
        for frame in frames:
            camera, stamp_ns, payload = frame[0], frame[1], frame[2]
            encoding = frame[3] if len(frame) == 4 else "mono8"
            compressed = isinstance(payload, bytes)
            key = (camera, compressed)
            if key not in connections:
                if camera not in names:
                    raise ValueError(f"frame of camera {camera!r}, not one of {names}")
                topic = f"/{camera}/image_raw" + (COMPRESSED_SUFFIX if compressed else "")
                connections[key] = writer.add_connection(
                    topic, COMPRESSED if compressed else IMAGE, typestore=_TYPESTORE
                )
            if isinstance(payload, bytes):
                message = compressed_message(payload, stamp_ns, camera, encoding)
                writer.write(connections[key], stamp_ns, _TYPESTORE.serialize_cdr(message, COMPRESSED))
            else:
                message = image_message(payload, stamp_ns, camera, encoding)
                writer.write(connections[key], stamp_ns, _TYPESTORE.serialize_cdr(message, IMAGE))


def _write_ros1(path: Path, frames: Iterable[BagFrame], cameras: Iterable[str]) -> None:
    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    with Ros1Writer(path) as writer:
        connections = {name: writer.add_connection(f"/{name}/image_raw", IMAGE, typestore=store) for name in cameras}
        for seq, frame in enumerate(frames):
            camera, stamp_ns, image = frame[0], frame[1], frame[2]
            if isinstance(image, bytes) or (len(frame) == 4 and frame[3] != "mono8"):
                raise ValueError("a ROS 1 bag is written with raw mono8 images only")
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
    try:
        if msgtype == COMPRESSED:
            return decode_compressed(bytes(message.data), str(message.format))
        return image_array(message), message.encoding
    except ValueError as error:
        raise FormatError(where, str(error)) from None


def bag_topics(path: Path) -> dict[str, str]:
    """The bag's topics and their message types (empty when the bag cannot be read: reading reports the error)."""
    try:
        reader = Reader(path)
        reader.open()
    except Exception:
        return {}
    try:
        return {c.topic: c.msgtype for c in reader.connections}
    finally:
        reader.close()


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


def read_image_messages(path: Path, topics: dict[str, str]) -> Iterator[tuple[str, int, str, Any]]:
    """The image messages of the given camera topics in bag order, as stored: (camera, stamp ns, message type,
    message).

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
                message: Any = _TYPESTORE.deserialize_cdr(raw, connection.msgtype)
                stamp = message.header.stamp
                yield by_topic[connection.topic], stamp.sec * 10**9 + stamp.nanosec, connection.msgtype, message
        except FormatError:
            raise
        except Exception as error:
            raise FormatError(path, f"corrupt bag ({type(error).__name__}: {error})") from None
    finally:
        reader.close()


def read_image_frames(path: Path, topics: dict[str, str]) -> Iterator[ImageFrame]:
    """Decoded images of the given camera topics in bag order (compressed ones as the detector reads them).

    Args:
        path: a rosbag2 directory (mcap or sqlite3).
        topics: camera name -> topic.

    Raises:
        FormatError: not a readable bag, none of the topics present, or a broken message.
    """
    for camera, stamp_ns, msgtype, message in read_image_messages(path, topics):
        image, encoding = _decode(message, msgtype, f"{path} topic {topics[camera]}")
        yield ImageFrame(camera, stamp_ns, image, encoding)


def absolute_topic(topic: str, available: dict[str, str]) -> str:
    """A rig file's topic as a bag names it: an absolute name as it is; a relative one (``cam0/image_raw``,
    resolved in the recording node's namespace) in the root namespace, or the one namespace the bag
    recorded it in (``/rigA/cam0/image_raw``)."""
    if topic.startswith("/"):
        return topic
    rooted = "/" + topic
    if rooted in available or rooted + COMPRESSED_SUFFIX in available:
        return rooted
    for suffix in ("", COMPRESSED_SUFFIX):
        found = sorted(t[: len(t) - len(suffix)] for t in available if t.endswith(rooted + suffix))
        if len(found) == 1:
            return found[0]
    return rooted


def choose_topics(available: dict[str, str], wanted: dict[str, str], transport: str) -> dict[str, str]:
    """Per camera the topic to read: its raw image topic, or image_transport's ``<topic>/compressed``.

    Args:
        available: the bag's topics and message types (:func:`bag_topics`).
        wanted: camera -> raw image topic.
        transport: "raw", "compressed", or "auto": the raw topic when the bag has it, else the compressed one.
    """
    chosen = {}
    for camera, topic in wanted.items():
        topic = absolute_topic(topic, available)
        compressed = topic + COMPRESSED_SUFFIX
        if transport == "compressed" or (transport == "auto" and topic not in available and compressed in available):
            chosen[camera] = compressed
        else:
            chosen[camera] = topic
    return chosen
