"""A rendered take as one video file per camera, each started by hand at its own moment.

The videos of :func:`write_camera_videos` are what consumer cameras or machine-vision cameras recording to files
give: MPEG-4 at the cameras' frame rate, each beginning where its camera was started, so that the files' times
disagree by those starts (``wand-calib detect --video`` reads them, ``calibrate`` lines them up).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.sim.errors import SimulationError

#: The codec of the videos written (MPEG-4 Part 2, which every OpenCV build's FFmpeg writes).
FOURCC = "mp4v"


def write_camera_videos(
    frames: Iterable[tuple[str, int, NDArray[Any]]],
    out: Path,
    fps: float,
    starts_s: Mapping[str, float],
) -> dict[str, Path]:
    """Each camera's images (camera, stamp ns, mono8 image) from its start on, as ``out/<camera>.mp4`` at ``fps``.

    Args:
        frames: the take's images in stamp order.
        out: the folder to write into.
        fps: the videos' frame rate (the cameras').
        starts_s: per camera, seconds after the take's first image at which it was started.

    Returns:
        Per camera its video.

    Raises:
        SimulationError: OpenCV cannot write MPEG-4 here.
    """
    import cv2

    out.mkdir(parents=True, exist_ok=True)
    writers: dict[str, Any] = {}
    paths: dict[str, Path] = {}
    first: int | None = None
    try:
        for camera, stamp, image in frames:
            first = stamp if first is None else first
            if (stamp - first) / 1e9 < starts_s.get(camera, 0.0) - 0.5 / fps:
                continue
            if camera not in writers:
                paths[camera] = out / f"{camera}.mp4"
                size = (image.shape[1], image.shape[0])
                writers[camera] = cv2.VideoWriter(str(paths[camera]), cv2.VideoWriter.fourcc(*FOURCC), fps, size)
                if not writers[camera].isOpened():
                    raise SimulationError(f"OpenCV cannot write {FOURCC} video to {paths[camera]}")
            colour = image if image.ndim == 3 else cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_GRAY2BGR)
            writers[camera].write(colour)
    finally:
        for writer in writers.values():
            writer.release()
    return paths
