"""A rendered take as one video file per camera, each started by hand at its own moment.

The videos of :func:`write_camera_videos` are what consumer cameras or machine-vision cameras recording to files
give: MPEG-4 at the cameras' frame rate and a camera's bit rate, each beginning where its camera was started, so
that the files' times disagree by those starts (``wand-calib detect --video`` reads them, ``calibrate`` lines them
up). Writing them needs PyAV (``pip install av``, a test requirement): OpenCV's own writer gives MPEG-4 at about
0.2 Mbit/s only, far below a camera's.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.sim.errors import SimulationError

#: The videos' codec and bit rate: MPEG-4 Part 2 at what a camera records 640x480 at 30 fps with.
CODEC = "mpeg4"
BIT_RATE = 4_000_000


def write_camera_videos(
    frames: Iterable[tuple[str, int, NDArray[Any]]],
    out: Path,
    fps: float,
    starts_s: Mapping[str, float],
    *,
    bit_rate: int = BIT_RATE,
) -> dict[str, Path]:
    """Each camera's images (camera, stamp ns, mono8 image) from its start on, as ``out/<camera>.mp4`` at ``fps``.

    Args:
        frames: the take's images in stamp order.
        out: the folder to write into.
        fps: the videos' frame rate (the cameras').
        starts_s: per camera, seconds after the take's first image at which it was started.
        bit_rate: the videos' bit rate, bit/s.

    Returns:
        Per camera its video.

    Raises:
        SimulationError: PyAV is not installed.
    """
    try:
        import av
    except ImportError:
        raise SimulationError("writing videos needs PyAV: pip install av") from None
    out.mkdir(parents=True, exist_ok=True)
    containers: dict[str, Any] = {}
    streams: dict[str, Any] = {}
    written: dict[str, int] = {}
    first: int | None = None
    try:
        for camera, stamp, image in frames:
            first = stamp if first is None else first
            if (stamp - first) / 1e9 < starts_s.get(camera, 0.0) - 0.5 / fps:
                continue
            if camera not in containers:
                containers[camera] = av.open(str(out / f"{camera}.mp4"), "w")
                stream = containers[camera].add_stream(CODEC, rate=round(fps))
                stream.width, stream.height, stream.pix_fmt, stream.bit_rate = (
                    image.shape[1], image.shape[0], "yuv420p", bit_rate
                )  # fmt: skip
                streams[camera], written[camera] = stream, 0
            gray = np.ascontiguousarray(image if image.ndim == 2 else image[..., 0])
            frame = av.VideoFrame.from_ndarray(gray, format="gray").reformat(format="yuv420p")
            frame.pts = written[camera]
            written[camera] += 1
            for packet in streams[camera].encode(frame):
                containers[camera].mux(packet)
    finally:
        for camera, container in containers.items():
            for packet in streams[camera].encode():
                container.mux(packet)
            container.close()
    return {camera: out / f"{camera}.mp4" for camera in containers}
