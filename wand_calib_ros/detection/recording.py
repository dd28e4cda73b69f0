"""From a stream of camera images to wand observations: detect, track labels, group by time.

Each camera's images go through a :class:`CameraStream` (blobs, wand, labels).
An ambiguous A/C labelling is settled by continuity with a neighbouring
detection in time (before or after it), otherwise the view is rejected as
"ambiguous" rather than risk swapped labels. For recordings, images of
different cameras are grouped into frames by nearest stamps, with the same
synchroniser the live collector uses.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.collection.sync import frames_to_observations, group_by_stamps
from wand_calib_ros.core.initialise.intrinsics_init import nominal_bearings
from wand_calib_ros.core.model.bearings import BearingTable
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec, WandObservations
from wand_calib_ros.detection.blobs import BlobOptions, Blobs, find_blobs, to_gray
from wand_calib_ros.detection.errors import ImageError
from wand_calib_ros.detection.wand import (
    WandDetection,
    WandOptions,
    identify_wand,
    resolve_with_previous,
)
from wand_calib_ros.io.bags import ImageFrame

#: Detections further apart in time than this do not belong to one continuity track.
TRACK_GAP_NS = 200_000_000
#: A track's labels are decided once its votes (log image ratios) add up to log(ANCHOR_RATIO).
ANCHOR_RATIO = 1.5


class Detections(NamedTuple):
    """What a recording gave.

    Attributes:
        observations: labelled wand points per frame (time slot) and camera.
        stats: per camera counts.
        ambiguous: (frame id, camera, (3, 2) points in either order, stamp in s) of views whose
            A/C labels neither the image nor time settled; other cameras can (see
            :func:`wand_calib_ros.detection.consistency.label_across_cameras`).
    """

    observations: WandObservations
    stats: dict[str, CameraStats]
    ambiguous: list[tuple[int, str, NDArray[np.float64], float]]


@dataclass
class CameraStats:
    """Counts of one camera's images."""

    images: int = 0
    detected: int = 0
    rejected: Counter[str] = field(default_factory=Counter)


def detect_image(
    image: NDArray[Any],
    encoding: str,
    blob_options: BlobOptions,
    wand_options: WandOptions,
    model: CameraModel | BearingTable | None,
) -> tuple[Blobs, WandDetection]:
    """Blobs and wand of one decoded image (ImageError for unusable images)."""
    gray = to_gray(image, encoding)
    saturation = 65535.0 if encoding == "mono16" else 255.0
    blobs = find_blobs(gray, blob_options, saturation=saturation)
    return blobs, identify_wand(blobs, wand_options, model)


class Labelled(NamedTuple):
    """One image's outcome once its labels are decided.

    Attributes:
        stamp_ns: the image's stamp.
        points: (3, 2) pixels of A, B, C, or None (no wand, or A and C could not be told apart).
        unsettled: (3, 2) the wand's ends and middle in either order when only the A/C labels were
            missing (other cameras may settle them), else None.
    """

    stamp_ns: int
    points: NDArray[np.float64] | None
    unsettled: NDArray[np.float64] | None = None


class CameraStream:
    """One camera's images in, labelled wand points out: detection, then a :class:`StreamLabeller`.

    Feed images in time order with :meth:`push` (or :meth:`detect` and :meth:`label` to see each
    image's blobs); results come out in time order, ambiguous ones up to ``max_hold_ns`` late.
    ``stats`` counts images, labelled wands and rejections by reason.
    """

    def __init__(
        self,
        spec: CameraSpec,
        wand_options: WandOptions,
        blob_options: BlobOptions = BlobOptions(),
        *,
        max_hold_ns: int | None = 1_000_000_000,
    ) -> None:
        self.spec = spec
        self.wand_options = wand_options
        self.blob_options = blob_options
        self.model = nominal_bearings(spec)
        self.labeller = StreamLabeller(max_hold_ns)
        self.stats = CameraStats()
        self._pending: deque[WandDetection] = deque()  # pushed, not yet released (release keeps the order)

    def detect(self, image: NDArray[Any], encoding: str) -> tuple[Blobs | None, WandDetection | None, str | None]:
        """Blobs, wand and rejection reason (None when the wand was found) of one image."""
        self.stats.images += 1
        height, width = image.shape[:2]
        if (width, height) != self.spec.image_size:
            return None, None, "wrong_size"
        try:
            blobs, detection = detect_image(image, encoding, self.blob_options, self.wand_options, self.model)
        except ImageError:
            return None, None, "bad_image"
        return blobs, detection, detection.reason if detection.points is None else None

    def label(self, stamp_ns: int, detection: WandDetection | None, reason: str | None) -> list[Labelled]:
        """Hand one image's detection to the labeller; returns the outcomes it releases."""
        if reason is not None or detection is None:
            self.stats.rejected[reason or "no_wand"] += 1
            return [Labelled(stamp_ns, None)]
        if self.wand_options.n_points != 3 or detection.tool:  # two or a tool: the calibration labels them
            self.stats.detected += 1
            return [*self.flush(), Labelled(stamp_ns, detection.points)]
        self._pending.append(detection)
        return self._released(self.labeller.push(stamp_ns, detection))

    def push(self, stamp_ns: int, image: NDArray[Any], encoding: str) -> list[Labelled]:
        """:meth:`detect` then :meth:`label`."""
        _, detection, reason = self.detect(image, encoding)
        return self.label(stamp_ns, detection, reason)

    def flush(self) -> list[Labelled]:
        """Release what the labeller holds back (unsettled)."""
        return self._released(self.labeller.flush())

    def _released(self, results: list[tuple[int, NDArray[np.float64] | None]]) -> list[Labelled]:
        out = []
        for stamp, points in results:
            detection = self._pending.popleft()
            if points is None:
                self.stats.rejected["ambiguous"] += 1
                out.append(Labelled(stamp, None, detection.points))
            else:
                self.stats.detected += 1
                out.append(Labelled(stamp, points))
        return out


def detect_recording(
    frames: Iterable[ImageFrame],
    rig: RigSpec,
    *,
    tolerance_ns: int = 0,
    blob_options: BlobOptions = BlobOptions(),
    inspect: Callable[[ImageFrame, Blobs | None, WandDetection | None, str | None], None] | None = None,
) -> Detections:
    """Wand observations of a recording, with per-camera counts (detected, rejected by reason).

    Images are grouped into frames by nearest stamps (:func:`wand_calib_ros.collection.sync.group_by_stamps`,
    hardware-triggered or free-running cameras alike); frame ids count every frame of the recording
    and each view keeps its image's stamp.

    Args:
        frames: decoded images of the rig's cameras, roughly in time order.
        rig: the rig description (image sizes, wand lengths).
        tolerance_ns: images further apart than this never form a frame (0: half the frame period).
        blob_options: blob extraction settings.
        inspect: called for every image with its blobs, detection and rejection reason
            (progress reports, debug overlays).
    """
    wand_options = WandOptions.for_rig(rig)
    streams = {c.name: CameraStream(c, wand_options, blob_options, max_hold_ns=None) for c in rig.cameras}
    outcomes: list[tuple[str, Labelled]] = []
    for frame in sorted(frames, key=lambda f: f.stamp_ns):
        stream = streams[frame.camera]
        blobs, detection, reason = stream.detect(frame.image, frame.encoding)
        if inspect is not None:
            inspect(frame, blobs, detection, reason)
        outcomes += [(frame.camera, out) for out in stream.label(frame.stamp_ns, detection, reason)]
    outcomes += [(name, out) for name, stream in streams.items() for out in stream.flush()]
    detections = [(c, out.stamp_ns, out.points) for c, out in outcomes]
    grouped = group_by_stamps(rig.camera_names, detections, tolerance_ns, n_points=rig.wand.n_points)
    observations = frames_to_observations(grouped, rig.camera_names, rig.wand.n_points)
    frame_of = {
        (int(c), int(f.stamps_ns[c])): k for k, f in enumerate(grouped) for c in np.flatnonzero(f.reported)
    }  # fmt: skip
    index = {name: i for i, name in enumerate(rig.camera_names)}
    ambiguous = [
        (frame_of[(index[camera], out.stamp_ns)], camera, out.unsettled, out.stamp_ns / 1e9)
        for camera, out in outcomes
        if out.unsettled is not None and (index[camera], out.stamp_ns) in frame_of
    ]
    stats = {name: stream.stats for name, stream in streams.items()}
    return Detections(observations, stats, ambiguous)


class StreamLabeller:
    """Labels one camera's wand detections as they come: continuity tracks, then a vote per track.

    Consecutive detections at most TRACK_GAP_NS apart whose ends continuity pairs up clearly
    (:func:`resolve_with_previous`) form a track; within a track the A/C labels can only all be
    right or all be swapped. Each detection votes for its own order with log(|AB|/|BC|) in the
    image (near 0 for ambiguous images), and the track takes the order the votes favour once
    they sum to at least log(ANCHOR_RATIO) either way. One image's ratio alone can mislead:
    when the wand points towards the camera, perspective shrinks the far segment until the
    image ratio favours the wrong order for a stretch of frames; the rest of the track outvotes
    that stretch.

    Live, a track's detections are held until ``max_hold_ns`` after its first one (or until the
    track ends), then decided and released; later ones of a decided track are released at once.
    Held detections the vote cannot decide come out unsettled (None). Results come out in time
    order. With ``max_hold_ns=None`` every track is decided on all its detections (recordings).
    """

    def __init__(self, max_hold_ns: int | None = 1_000_000_000) -> None:
        self.max_hold_ns = max_hold_ns
        self._held: list[tuple[int, NDArray[np.float64], float]] = []  # stamp, points in track order, vote
        self._last: tuple[int, NDArray[np.float64]] | None = None  # newest stamp and points in track order
        self._vote = 0.0
        self._forward: bool | None = None  # None: undecided; True: the track order is A, B, C

    def push(self, stamp_ns: int, detection: WandDetection) -> list[tuple[int, NDArray[np.float64] | None]]:
        """Add a detection (in time order); returns the (stamp, A B C or None) results it releases."""
        assert detection.points is not None
        released: list[tuple[int, NDArray[np.float64] | None]] = []
        linked = None
        if self._last is not None and stamp_ns - self._last[0] <= TRACK_GAP_NS:
            linked = resolve_with_previous(detection, self._last[1])
        chosen = detection.points if linked is None or linked.ambiguous else linked.points
        if linked is None or linked.ambiguous:
            released += self.flush()
        assert chosen is not None
        points: NDArray[np.float64] = chosen
        same = bool(np.array_equal(points, detection.points))
        vote = float(np.clip(np.log(max(detection.image_ratio, 1e-6)), -1.0, 1.0)) * (1.0 if same else -1.0)
        self._vote += vote
        self._last = (stamp_ns, points)
        if self._forward is not None:
            released.append((stamp_ns, points if self._forward else points[::-1].copy()))
            return released
        self._held.append((stamp_ns, points, vote))
        if self.max_hold_ns is not None and stamp_ns - self._held[0][0] >= self.max_hold_ns:
            released += self._decide()
        return released

    def flush(self) -> list[tuple[int, NDArray[np.float64] | None]]:
        """End the current track: decide and release what it holds (end of a recording, /calibrate)."""
        released = self._decide()
        self._held, self._last, self._vote, self._forward = [], None, 0.0, None
        return released

    def _decide(self) -> list[tuple[int, NDArray[np.float64] | None]]:
        released: list[tuple[int, NDArray[np.float64] | None]]
        if abs(self._vote) >= np.log(ANCHOR_RATIO):
            self._forward = self._vote > 0
            forward = self._forward
            released = [(stamp, points if forward else points[::-1].copy()) for stamp, points, _ in self._held]
        else:  # too little evidence so far: release unsettled, keep voting on what follows
            released = [(stamp, None) for stamp, _, _ in self._held]
        self._held = []
        return released


def track_labels(sequence: list[tuple[int, WandDetection]]) -> list[NDArray[np.float64] | None]:
    """A, B, C of each detection of one camera of a recording (None where the vote cannot decide).

    A :class:`StreamLabeller` that holds each track until it ends.
    """
    labeller = StreamLabeller(max_hold_ns=None)
    released = [labels for stamp, detection in sequence for _, labels in labeller.push(stamp, detection)]
    return released + [labels for _, labels in labeller.flush()]
