"""Camera images from one video file (or one folder of numbered images) per camera.

Consumer cameras, phones and machine-vision cameras recording to files give one video per camera, each started
by hand: no common stamps, only each file's own times. A video's frame times are its per-frame timestamps
where the container has them (OpenCV's ``CAP_PROP_POS_MSEC`` after each read), else its frame index over its
frame rate; a folder's images are taken in the order of the number in their names, at the frame rate given.
Every file's times start at its first frame: the calibration lines the cameras' clocks up from the wand
(:mod:`~wand_calib_ros.core.initialise.clock_alignment`). Images are read as mono8 (the detector's input), the
cameras' frames interleaved in time order as a bag's are. Any container and codec OpenCV's FFmpeg reads work
(mp4, mov, avi, mkv; MPEG-4, H.264, MJPEG).
"""

from __future__ import annotations

import heapq
import queue
import re
import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.io.bags import ImageFrame
from wand_calib_ros.io.errors import FormatError

#: Image files a folder of frames may hold.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm")
#: Frame rates outside this range cannot be a camera's (a container that does not say gives 0 or 1000).
FPS_RANGE = (0.5, 1000.0)
#: A spot in a video stands at least this many grey levels above its background (the detector's
#: ``min_contrast``): a codec's predicted frames copy a still background from image to image, so the noise
#: measured between images is the codec's, near zero, and its block noise around a moving spot (4-8 grey levels
#: at 4 Mbit/s in 640x480 MPEG-4) would count as spots (75-90 an image at the detector's default of 5).
VIDEO_MIN_CONTRAST = 10.0


@dataclass(frozen=True)
class CameraSource:
    """Where one camera's images are.

    Attributes:
        camera: the camera's name in the rig.
        path: a video file or a folder of numbered images.
        fps: the folder's frame rate (None for a video: its own).
    """

    camera: str
    path: Path
    fps: float | None = None

    @property
    def is_folder(self) -> bool:
        return self.path.is_dir()


def _numbered(folder: Path) -> list[Path]:
    """The folder's images in the order of the (last) number in their names."""

    def number(path: Path) -> tuple[int, str]:
        found = re.findall(r"\d+", path.stem)
        return (int(found[-1]) if found else -1, path.name)

    images = sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), key=number)
    if not images:
        raise FormatError(folder, f"no images ({', '.join(IMAGE_SUFFIXES)}) in this folder of frames")
    return images


def _capture(path: Path) -> Any:
    """An opened OpenCV capture of ``path`` (FormatError: it cannot be decoded)."""
    import cv2

    capture = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG, [cv2.CAP_PROP_N_THREADS, 1])
    if not capture.isOpened():
        raise FormatError(path, "cannot be decoded as a video (a file OpenCV's FFmpeg reads: mp4, mov, avi, mkv)")
    return capture


def count_frames(sources: Mapping[str, CameraSource]) -> int:
    """How many images the sources hold (a container's own count: 0 where it does not say)."""
    import cv2

    total = 0
    for source in sources.values():
        if source.is_folder:
            total += len(_numbered(source.path))
            continue
        capture = _capture(source.path)
        total += max(int(capture.get(cv2.CAP_PROP_FRAME_COUNT)), 0)
        capture.release()
    return total


def check_sources(sources: Mapping[str, CameraSource], sizes: Mapping[str, tuple[int, int]]) -> None:
    """Every source opens, and its first frame is its camera's size.

    Raises:
        FormatError: a file that is missing or cannot be decoded, a folder without --fps or images, or frames of
            another size than cameras.yaml's, naming the camera and the file.
    """
    for name, source in sources.items():
        if not source.path.exists():
            raise FormatError(source.path, f"no such file or folder (the video of camera '{name}')")
        first = next(_frames(source), None)
        if first is None:
            raise FormatError(source.path, f"holds no frame (the video of camera '{name}')")
        height, width = first[1].shape[:2]
        if (width, height) != tuple(sizes[name]):
            raise FormatError(
                source.path,
                f"its frames are {width}x{height}, cameras.yaml says {sizes[name][0]}x{sizes[name][1]} for camera "
                f"'{name}': the right file for the camera? the right image_size?",
            )


def _frames(source: CameraSource) -> Iterator[tuple[float, NDArray[np.uint8]]]:
    """(time in seconds from the first frame, mono8 image) of each of one source's frames."""
    import cv2

    if source.is_folder:
        if source.fps is None:
            raise FormatError(source.path, "a folder of images has no frame times: give its frame rate (--fps)")
        for index, path in enumerate(_numbered(source.path)):
            image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise FormatError(path, f"cannot be read as an image (a frame of camera '{source.camera}')")
            yield index / source.fps, np.asarray(image, dtype=np.uint8)
        return
    capture = _capture(source.path)
    fps = float(capture.get(cv2.CAP_PROP_FPS))
    rate_known = FPS_RANGE[0] <= fps <= FPS_RANGE[1]
    first: float | None = None
    index = 0
    try:
        while True:
            ok, image = capture.read()
            if not ok:
                break
            stamp = float(capture.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0
            if not np.isfinite(stamp) or (index > 0 and stamp <= 0.0):  # no per-frame times: the frame rate's
                if not rate_known:
                    raise FormatError(source.path, "has neither frame times nor a frame rate")
                stamp = index / fps
            first = stamp if first is None else first
            gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            yield stamp - first, np.ascontiguousarray(gray)
            index += 1
    finally:
        capture.release()


def read_source_frames(sources: Mapping[str, CameraSource]) -> Iterator[ImageFrame]:
    """Every source's frames as mono8 images, the cameras' interleaved in time order (a camera's on a tie
    in rig order), stamped in ns from each file's first frame. They are decoded in a thread of their own,
    PREFETCH frames ahead: decoding (0.4-0.8 ms a 640x480 frame) then runs beside the detector."""
    streams = [((_stamped(name, source)), order) for order, (name, source) in enumerate(sources.items())]
    merged = heapq.merge(*(_keyed(stream, order) for stream, order in streams))
    for _, _, frame in _prefetched(merged):
        yield frame


#: Frames decoded ahead of the one being detected.
PREFETCH = 32
_DONE = object()


def _prefetched(items: Iterator[Any]) -> Iterator[Any]:
    """``items`` produced by a thread of their own, at most PREFETCH ahead; its error raised here."""
    ahead: queue.Queue[Any] = queue.Queue(maxsize=PREFETCH)
    stop = threading.Event()

    def produce() -> None:
        try:
            for item in items:
                while not stop.is_set():
                    try:
                        ahead.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            ahead.put(_DONE)
        except BaseException as error:  # (raised in the consumer, where it can be handled)
            ahead.put(error)

    worker = threading.Thread(target=produce, name="video decoding", daemon=True)
    worker.start()
    try:
        while True:
            item = ahead.get()
            if item is _DONE:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        worker.join(timeout=5.0)


def _stamped(name: str, source: CameraSource) -> Iterator[ImageFrame]:
    for seconds, image in _frames(source):
        yield ImageFrame(name, round(seconds * 1e9), image, "mono8")


def _keyed(frames: Iterator[ImageFrame], order: int) -> Iterator[tuple[int, int, ImageFrame]]:
    for frame in frames:
        yield frame.stamp_ns, order, frame
