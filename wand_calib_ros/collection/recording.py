"""A recording's images through each camera's detector, on their cameras' time lines, grouped into frames.

Images are searched in stamp order (within REORDER_S: a recording is read as it goes, only that much of it in
memory), each camera's by its own :class:`~wand_calib_ros.detection.recording.CameraStream`, and grouped into
frames by nearest stamps with the synchroniser the live collection uses
(:func:`~wand_calib_ros.collection.sync.group_by_stamps`).
"""

from __future__ import annotations

import heapq
import logging
import multiprocessing
from collections.abc import Callable, Iterable, Iterator, Mapping
from concurrent.futures import ProcessPoolExecutor, wait
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wand_calib_ros.collection.sync import frames_to_observations, group_by_stamps
from wand_calib_ros.collection.timeline import TimeLines
from wand_calib_ros.core.adjust.timing import frame_period
from wand_calib_ros.core.errors import TimingError
from wand_calib_ros.core.initialise.clock_alignment import ClockAlignment, Track, find_clock_offsets
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec
from wand_calib_ros.detection.blobs import BlobOptions, Blobs
from wand_calib_ros.detection.health import HealthReport
from wand_calib_ros.detection.masks import Mask
from wand_calib_ros.detection.recording import CameraStats, CameraStream, Detections, Labelled, Unsettled
from wand_calib_ros.detection.wand import WandDetection, WandOptions
from wand_calib_ros.errors import WandCalibError
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
    given = masks or {}
    searches = {c.name: CameraSearch(c, WandOptions.for_rig(rig), blob_options, given.get(c.name)) for c in rig.cameras}
    outcomes: list[tuple[str, Labelled]] = []
    for frame in in_stamp_order(frames, int(REORDER_S * 1e9)):
        outcomes += [(frame.camera, out) for out in searches[frame.camera].see(frame, inspect)]
    ends = [search.finish() for search in searches.values()]
    outcomes += [(camera.camera, out) for held, camera in ends for out in held]
    return grouped_detections(rig, [camera for _, camera in ends], outcomes, tolerance_ns)


def detect_cameras_apart(
    sources: Mapping[str, Callable[[], Iterable[ImageFrame]]],
    rig: RigSpec,
    *,
    workers: int,
    tolerance_ns: int = 0,
    blob_options: BlobOptions = BlobOptions(),
    inspect: Callable[[ImageFrame, Blobs | None, WandDetection | None, str | None], None] | None = None,
    progress: Callable[[int], None] | None = None,
    masks: Mapping[str, Mask] | None = None,
) -> Detections:
    """Wand observations of a recording kept one camera to a file (a video per camera): each camera's images
    searched on their own, up to ``workers`` cameras at a time in processes of their own, then grouped as
    :func:`detect_recording` groups them (the same detections: a camera's search never looks at another's images).

    Args:
        sources: per camera of the rig, what reads its images in stamp order (called in the worker).
        workers: how many cameras are searched at a time (1: here, one after the other).
        inspect: called for every image where it is searched (debug overlays).
        progress: called here with how many images were searched so far, a few times a second.
        tolerance_ns, blob_options, masks: as :func:`detect_recording`'s.

    Raises:
        WandCalibError: what reading a camera's images raised, its message as it was.
    """
    global _APART
    given = masks or {}
    _APART = _Apart(sources, rig, blob_options, dict(given), inspect, multiprocessing.get_context("fork").Value("q", 0))
    try:
        if workers <= 1 or len(rig.cameras) <= 1:
            searched = [_search_camera(name) for name in rig.camera_names]
        else:
            searched = _searched_in_workers(rig.camera_names, workers, progress)
    finally:
        counted, _APART = _APART.counted, None
    if progress is not None:
        progress(int(counted.value))
    outcomes = [(camera.camera, out) for views, camera in searched for out in views]
    outcomes.sort(key=lambda item: item[1].stamp_ns)  # (stable: a camera's own order, cameras in rig order)
    return grouped_detections(rig, [camera for _, camera in searched], outcomes, tolerance_ns)


@dataclass(frozen=True)
class _Apart:
    """What a worker searching one camera of :func:`detect_cameras_apart` needs (inherited as it forks)."""

    sources: Mapping[str, Callable[[], Iterable[ImageFrame]]]
    rig: RigSpec
    blob_options: BlobOptions
    masks: dict[str, Mask]
    inspect: Callable[[ImageFrame, Blobs | None, WandDetection | None, str | None], None] | None
    counted: Any  # a shared count of the images searched


_APART: _Apart | None = None
#: How often (s) the progress of cameras searched in workers is told.
PROGRESS_S = 0.25


def _searched_in_workers(
    names: tuple[str, ...], workers: int, progress: Callable[[int], None] | None
) -> list[tuple[list[Labelled], Searched]]:
    """Each camera searched in a worker process (forked: it inherits _APART), in rig order."""
    assert _APART is not None
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork")) as pool:
        futures = [pool.submit(_search_camera, name) for name in names]
        pending = set(futures)
        while pending:
            _, pending = wait(pending, timeout=PROGRESS_S)
            if progress is not None:
                progress(int(_APART.counted.value))
        return [future.result() for future in futures]


def _search_camera(name: str) -> tuple[list[Labelled], Searched]:
    """One camera's images searched (in a worker, or here): its labelled views and images without one, in stamp
    order, and its search's end; a reading error comes back as a WandCalibError with its message (a worker's
    exceptions travel by pickle)."""
    assert _APART is not None
    work = _APART
    search = CameraSearch(work.rig.camera(name), WandOptions.for_rig(work.rig), work.blob_options, work.masks.get(name))
    outcomes: list[Labelled] = []
    try:
        for frame in in_stamp_order(work.sources[name](), int(REORDER_S * 1e9)):
            outcomes += search.see(frame, work.inspect)
            with work.counted.get_lock():
                work.counted.value += 1
    except WandCalibError as error:
        raise WandCalibError(str(error)) from None
    held, searched = search.finish()
    return [*outcomes, *held], searched


@dataclass(frozen=True)
class Searched:
    """One camera's images, searched: what is known of it once its labelled views are given out.

    Attributes:
        camera: its name.
        stats: its counts.
        report: what it saw.
        mask: the pixels its detector ignored at the end (given and learned), or None: none.
    """

    camera: str
    stats: CameraStats
    report: HealthReport
    mask: Mask | None


class CameraSearch:
    """One camera's images of a recording through its time line and detector, in stamp order."""

    def __init__(self, spec: CameraSpec, wand: WandOptions, blobs: BlobOptions, mask: Mask | None) -> None:
        self.stream = CameraStream(spec, wand, blobs, max_hold_ns=None, mask=mask)
        self.timeline = TimeLines((spec.name,))

    def see(
        self,
        frame: ImageFrame,
        inspect: Callable[[ImageFrame, Blobs | None, WandDetection | None, str | None], None] | None,
    ) -> list[Labelled]:
        """One image searched (unless its time line does not place it next); what the labeller releases."""
        placed = self.timeline.place(frame.camera, frame.stamp_ns, None)  # (a file's stamps are all there is)
        if placed.order != "next":
            skipped = self.stream.passed_over(placed.order == "repeat")
            if inspect is not None:
                inspect(frame, None, None, skipped)
            return []
        blobs, detection, reason = self.stream.detect(frame.image, frame.encoding, frame.stamp_ns)
        if inspect is not None:
            inspect(frame, blobs, detection, reason)
        return self.stream.label(frame.stamp_ns, detection, reason)

    def finish(self) -> tuple[list[Labelled], Searched]:
        """The search's end: what the labeller still held, and the counts, the report and the mask."""
        stream = self.stream
        held = stream.flush()
        return held, Searched(stream.spec.name, stream.stats, stream.report(), stream.mask)


def grouped_detections(
    rig: RigSpec, searched: list[Searched], outcomes: list[tuple[str, Labelled]], tolerance_ns: int
) -> Detections:
    """The searched cameras' labelled views (``outcomes``: (camera, view)) grouped into frames, the cameras'
    clocks lined up by the wand's motion first where they disagree."""
    clocks = _clocks(rig, outcomes)
    return replace(_grouped(rig, searched, outcomes, tolerance_ns, _shifts_ns(rig, clocks)), clocks=clocks)


def _shifts_ns(rig: RigSpec, clocks: ClockAlignment | None) -> dict[str, int]:
    """Per camera whose clock the wand's motion lines up with the others' (by more than a frame or two), its
    offset in ns (empty where the clocks agree or cannot be decided: ``calibrate`` says why)."""
    if clocks is None:
        return {}
    moved = zip(rig.camera_names, clocks.offsets, clocks.moved, strict=True)
    return {name: round(float(offset) * 1e9) for name, offset, is_moved in moved if is_moved}


def _clocks(rig: RigSpec, outcomes: list[tuple[str, Labelled]]) -> ClockAlignment | None:
    """The cameras' clock offsets from the wand's motion in their labelled views (None: they cannot be decided,
    ``calibrate`` says why)."""
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
        return None
    for line in found.lines:
        log.info(line)
    return found


def _grouped(
    rig: RigSpec,
    searched: list[Searched],
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
    stats = {camera.camera: camera.stats for camera in searched}
    reports = {camera.camera: camera.report for camera in searched}
    ignored: dict[str, Mask | None] = {camera.camera: camera.mask for camera in searched}
    stops = brightness[observations.frames]
    observations = replace(observations, saturated=np.nan_to_num(stops, nan=-1.0) >= 0.0, brightness=stops)
    return Detections(observations, stats, ambiguous, tracks[observations.frames], reports, ignored)
