"""Camera images from one video file (or one folder of numbered images) per camera.

Consumer cameras, phones and machine-vision cameras recording to files give one video per camera, each started
by hand: no common stamps, only each file's own times. A video's frame times are its per-frame timestamps
where the container has them (OpenCV's ``CAP_PROP_POS_MSEC`` after each read), else its frame index over its
frame rate; a folder's images are taken in the order of the number in their names, at the frame rate given.
Every file's times start at its first frame: the calibration lines the cameras' clocks up from the wand
(:mod:`~wand_calib_ros.core.initialise.clock_alignment`). Images are read as mono8 (the detector's input), a
camera at a time (``detect`` searches each camera's in a process of its own:
:func:`~wand_calib_ros.collection.recording.detect_cameras_apart`). Any container and codec OpenCV's FFmpeg reads
work (mp4, mov, avi, mkv; MPEG-4, H.264, MJPEG).
"""

from __future__ import annotations

import re
import threading
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
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


def _capture(path: Path, convert: bool = True) -> Any:
    """An opened OpenCV capture of ``path`` (FormatError: it cannot be decoded); ``convert``: its frames in BGR,
    else as the decoder gave them (a luma plane first: that plane, :func:`_luma_table`)."""
    import cv2

    capture = cv2.VideoCapture(
        str(path), cv2.CAP_FFMPEG, [cv2.CAP_PROP_N_THREADS, 1, cv2.CAP_PROP_CONVERT_RGB, int(convert)]
    )
    if not capture.isOpened():
        raise FormatError(path, "cannot be decoded as a video (a file OpenCV's FFmpeg reads: mp4, mov, avi, mkv)")
    return capture


_quiet_lock = threading.Lock()
_quiet_users = [0, 0]  # (readers decoding luma planes, OpenCV's log level before the first)


@contextmanager
def _opencv_quiet() -> Iterator[None]:
    """OpenCV's warnings held back while any luma plane is read (it warns of every plane it hands over
    unconverted); its log level as it was once the last reader is done."""
    import cv2

    with _quiet_lock:
        if _quiet_users[0] == 0:
            _quiet_users[1] = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        _quiet_users[0] += 1
    try:
        yield
    finally:
        with _quiet_lock:
            _quiet_users[0] -= 1
            if _quiet_users[0] == 0:
                cv2.utils.logging.setLogLevel(_quiet_users[1])


#: Pixel formats (FourCC) whose first plane is the luma: OpenCV hands that plane over when asked not to convert
#: the frames to BGR, which spares the conversion to BGR and back to grey (15 % of decoding a 640x480 MPEG-4
#: frame here).
LUMA_FIRST = frozenset({"I420", "IYUV", "YV12", "NV12", "NV21", "Y800", "GREY", "Y41B", "Y42B", "444P"})


def _luma_table(path: Path) -> NDArray[np.uint8] | None:
    """(256,) the grey level OpenCV's BGR decoding gives each luma value of the file's frames (the identity for a
    full-range file, such as MJPEG's; 16-235 stretched to 0-255 for a video range one, such as MPEG-4's), decided
    on the first frame decoded both ways; None: the frames have no luma plane first, or the first frame does not
    tell (then they are decoded to BGR and converted, as before)."""
    import cv2

    with _opencv_quiet():
        raw, converted = _capture(path, convert=False), _capture(path)
        try:
            code = int(raw.get(cv2.CAP_PROP_CODEC_PIXEL_FORMAT)) & 0xFFFFFFFF  # (-1 or 0 where it is not said)
            tag = code.to_bytes(4, "little").decode("ascii", "replace")
            ok_luma, luma = raw.read()
            ok_bgr, bgr = converted.read()
        finally:
            raw.release()
            converted.release()
    if tag not in LUMA_FIRST or not (ok_luma and ok_bgr) or luma is None or bgr is None or luma.ndim != 2:
        return None
    grey = bgr if bgr.ndim == 2 else cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    if luma.shape != grey.shape:
        return None
    levels = np.arange(256, dtype=np.float64)
    tables = (levels, (levels - 16.0) * 255.0 / 219.0)
    fits = [int(np.max(np.abs(np.clip(np.round(t), 0, 255)[luma] - grey))) for t in tables]
    matching = [table for table, misfit in zip(tables, fits, strict=True) if misfit <= 1]
    if len(matching) != 1:  # (neither, or a frame that cannot tell them apart)
        return None
    return np.clip(np.round(matching[0]), 0, 255).astype(np.uint8)


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
        # (the size alone: a video's first frame decoded as it comes, its luma plane left to the reader)
        first = next(_frames(source) if source.is_folder else _decoded(source, None), None)
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
    table = _luma_table(source.path)
    with _opencv_quiet():
        yield from _decoded(source, table)


def _decoded(source: CameraSource, table: NDArray[np.uint8] | None) -> Iterator[tuple[float, NDArray[np.uint8]]]:
    """(time in seconds from the first frame, mono8 image) of each frame of a video, read as its luma plane mapped
    by ``table`` (:func:`_luma_table`), or None: decoded to BGR and converted."""
    import cv2

    capture = _capture(source.path, convert=table is None)
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
            if table is not None:
                gray = cv2.LUT(image, table)
            else:
                gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            yield stamp - first, np.ascontiguousarray(gray)
            index += 1
    finally:
        capture.release()


def camera_frames(name: str, source: CameraSource) -> Iterator[ImageFrame]:
    """One camera's frames as mono8 images, stamped in ns from its file's first frame."""
    for seconds, image in _frames(source):
        yield ImageFrame(name, round(seconds * 1e9), image, "mono8")
