"""A recording's images through each camera's detector, on their cameras' time lines, grouped into frames.

Images are searched in stamp order (within REORDER_S: a recording is read as it goes, only that much of it in
memory), each camera's by its own :class:`~wand_calib_ros.detection.recording.CameraStream`, and grouped into
frames by nearest stamps with the synchroniser the live collection uses
(:func:`~wand_calib_ros.collection.sync.group_by_stamps`).
"""

from __future__ import annotations

import heapq
import logging
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import replace

import numpy as np

from wand_calib_ros.collection.sync import frames_to_observations, group_by_stamps
from wand_calib_ros.collection.timeline import TimeLines
from wand_calib_ros.core.adjust.timing import frame_period
from wand_calib_ros.core.errors import TimingError
from wand_calib_ros.core.initialise.clock_alignment import Track, find_clock_offsets
from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.detection.blobs import BlobOptions, Blobs
from wand_calib_ros.detection.masks import Mask
from wand_calib_ros.detection.recording import CameraStream, Detections, Labelled, Unsettled
from wand_calib_ros.detection.wand import WandDetection, WandOptions
from wand_calib_ros.io.bags import ImageFrame

#: A recording's images are put in stamp order within this much of it (s): a bag stores them as they arrived, a
#: little out of their stamps' order, and only this much of it is held in memory. An image still behind its
#: camera's newest after that is not searched (its time line says so: :mod:`wand_calib_ros.collection.timeline`).
REORDER_S = 2.0

log = logging.getLogger(__name__)


def in_stamp_order(frames: Iterable[ImageFrame], window_ns: int) -> Iterator[ImageFrame]:
    """The frames in stamp order, holding only those within ``window_ns`` of the newest stamp seen so far (a
    frame stamped further back than that comes out as soon as it arrives, out of order)."""
    held: list[tuple[int, int, ImageFrame]] = []  # (stamp, arrival, frame): a heap
    newest: int | None = None
    for arrival, frame in enumerate(frames):
        heapq.heappush(held, (frame.stamp_ns, arrival, frame))
        newest = frame.stamp_ns if newest is None else max(newest, frame.stamp_ns)
        while held[0][0] < newest - window_ns:
            yield heapq.heappop(held)[2]
    while held:
        yield heapq.heappop(held)[2]


def detect_recording(
    frames: Iterable[ImageFrame],
    rig: RigSpec,
    *,
    tolerance_ns: int = 0,
    blob_options: BlobOptions = BlobOptions(),
    inspect: Callable[[ImageFrame, Blobs | None, WandDetection | None, str | None], None] | None = None,
    masks: Mapping[str, Mask] | None = None,
) -> Detections:
    """Wand observations of a recording, with per-camera counts (detected, rejected by reason).

    Images are searched in stamp order (within REORDER_S: a recording is read as it goes, only that much of it in
    memory) and grouped into frames by nearest stamps (:func:`wand_calib_ros.collection.sync.group_by_stamps`,
    hardware-triggered or free-running cameras alike); frame ids count every frame of the recording
    and each view keeps its image's stamp. Cameras whose clocks disagree by seconds (videos started by hand)
    are grouped on their clocks as the wand's motion lines them up
    (:func:`~wand_calib_ros.core.initialise.clock_alignment.align_clocks`), their views keeping their own stamps.

    Args:
        frames: decoded images of the rig's cameras, roughly in time order.
        rig: the rig description (image sizes, wand lengths).
        tolerance_ns: images further apart than this never form a frame (0: half the frame period).
        blob_options: blob extraction settings.
        inspect: called for every image with its blobs, detection and rejection reason
            (progress reports, debug overlays).
        masks: per camera the pixels to ignore (the rig file's ``mask``), if any.
    """
    wand_options = WandOptions.for_rig(rig)
    given = masks or {}
    streams = {
        c.name: CameraStream(c, wand_options, blob_options, max_hold_ns=None, mask=given.get(c.name))
        for c in rig.cameras
    }
    outcomes: list[tuple[str, Labelled]] = []
    timelines = TimeLines(rig.camera_names)
    for frame in in_stamp_order(frames, int(REORDER_S * 1e9)):
        stream = streams[frame.camera]
        placed = timelines.place(frame.camera, frame.stamp_ns, None)  # (a file's stamps are all there is)
        if placed.order != "next":
            skipped = stream.passed_over(placed.order == "repeat")
            if inspect is not None:
                inspect(frame, None, None, skipped)
            continue
        blobs, detection, reason = stream.detect(frame.image, frame.encoding, frame.stamp_ns)
        if inspect is not None:
            inspect(frame, blobs, detection, reason)
        outcomes += [(frame.camera, out) for out in stream.label(frame.stamp_ns, detection, reason)]
    outcomes += [(name, out) for name, stream in streams.items() for out in stream.flush()]
    return _grouped(rig, streams, outcomes, tolerance_ns, _clock_shifts(rig, outcomes))


def _clock_shifts(rig: RigSpec, outcomes: list[tuple[str, Labelled]]) -> dict[str, int]:
    """Per camera whose clock the wand's motion lines up with the others' (by more than a frame or two), its
    offset in ns (empty where the clocks agree or cannot be decided: ``calibrate`` says why)."""
    tracks = []
    for name in rig.camera_names:
        views = [(out.stamp_ns / 1e9, out.points) for camera, out in outcomes if camera == name]
        whole = [(s, p) for s, p in views if p is not None and np.all(np.isfinite(p))]
        times = np.array([s for s, _ in whole], dtype=np.float64)
        points = np.array([p for _, p in whole], dtype=np.float64).reshape(-1, rig.wand.n_points, 2)
        period = frame_period(times)
        tracks.append(Track(times, points, period if np.isfinite(period) else 1.0))
    try:
        found = find_clock_offsets(rig, tuple(tracks), frames=False)
    except TimingError as error:
        log.info("the cameras' clocks are not lined up: %s", error)
        return {}
    for line in found.lines:
        log.info(line)
    moved = zip(rig.camera_names, found.offsets, found.moved, strict=True)
    return {name: round(float(offset) * 1e9) for name, offset, is_moved in moved if is_moved}


def _grouped(
    rig: RigSpec,
    streams: Mapping[str, CameraStream],
    outcomes: list[tuple[str, Labelled]],
    tolerance_ns: int,
    shift_ns: Mapping[str, int],
) -> Detections:
    """The cameras' labelled views grouped into frames by nearest stamps, each camera's moved by its ``shift_ns``
    (its clock's offset) for the grouping, each view keeping its own stamp."""
    shifted = [(c, out.stamp_ns - shift_ns.get(c, 0), out) for c, out in outcomes]
    grouped = group_by_stamps(rig.camera_names, [(c, s, out.points) for c, s, out in shifted], tolerance_ns,
                              n_points=rig.wand.n_points)  # fmt: skip
    observations = frames_to_observations(grouped, rig.camera_names, rig.wand.n_points)
    if observations.stamps is not None and shift_ns:
        moved = np.array([shift_ns.get(name, 0) / 1e9 for name in rig.camera_names])
        observations = replace(observations, stamps=observations.stamps + moved[None, :])
    frame_of = {
        (int(c), int(f.stamps_ns[c])): k for k, f in enumerate(grouped) for c in np.flatnonzero(f.reported)
    }  # fmt: skip
    index = {name: i for i, name in enumerate(rig.camera_names)}
    ambiguous = [
        Unsettled(frame_of[(index[camera], stamp)], camera, out.unsettled, out.stamp_ns / 1e9, out.brightness)
        for camera, stamp, out in shifted
        if out.unsettled is not None and (index[camera], stamp) in frame_of
    ]
    tracks = np.full((len(grouped), len(rig.camera_names)), -1, dtype=np.int64)
    brightness = np.full((len(grouped), len(rig.camera_names), rig.wand.n_points), np.nan)
    for camera, stamp, out in shifted:
        row = frame_of.get((index[camera], stamp))
        if out.points is not None and row is not None:
            tracks[row, index[camera]] = out.track
            if out.brightness is not None and out.brightness.size == rig.wand.n_points:
                brightness[row, index[camera]] = out.brightness
    stats = {name: stream.stats for name, stream in streams.items()}
    reports = {name: stream.report() for name, stream in streams.items()}
    ignored: dict[str, Mask | None] = {name: stream.mask for name, stream in streams.items()}
    stops = brightness[observations.frames]
    observations = replace(observations, saturated=np.nan_to_num(stops, nan=-1.0) >= 0.0, brightness=stops)
    return Detections(observations, stats, ambiguous, tracks[observations.frames], reports, ignored)
