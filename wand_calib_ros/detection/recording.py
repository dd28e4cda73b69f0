"""From a stream of camera images to wand observations: detect, track labels, group by time.

Images of different cameras whose header stamps lie within a tolerance form
one frame. Each camera keeps its last detection: an ambiguous A/C labelling is
settled by continuity with it when it is recent, otherwise the view is
rejected as "ambiguous" rather than risk swapped labels.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.camera_model import CameraModel
from wand_calib_ros.core.errors import CoreError
from wand_calib_ros.core.intrinsics_init import initial_model, lens_candidates
from wand_calib_ros.core.rig import CameraSpec, RigSpec, WandObservations
from wand_calib_ros.detection.blobs import BlobOptions, Blobs, find_blobs, to_gray
from wand_calib_ros.detection.errors import ImageError
from wand_calib_ros.detection.wand import (
    BearingTable,
    WandDetection,
    WandOptions,
    identify_wand,
    resolve_with_previous,
)
from wand_calib_ros.io.bags import ImageFrame

#: A previous detection older than this cannot settle an ambiguous one.
TRACK_GAP_NS = 200_000_000
#: Image ratios |AB|/|BC| from which the labels are trusted without tracking (the wand's is L1/L2).
ANCHOR_RATIO = 1.5


class Detections(NamedTuple):
    """What a recording gave.

    Attributes:
        observations: labelled wand points per frame (time slot) and camera.
        stats: per camera counts.
        ambiguous: (frame id, camera, (3, 2) points in either order) of views whose A/C
            labels neither the image nor time settled; other cameras can (see
            :func:`wand_calib_ros.detection.consistency.label_across_cameras`).
    """

    observations: WandObservations
    stats: dict[str, CameraStats]
    ambiguous: list[tuple[int, str, NDArray[np.float64]]]


@dataclass
class CameraStats:
    """Counts of one camera's images."""

    images: int = 0
    detected: int = 0
    rejected: Counter[str] = field(default_factory=Counter)


def detect_image(
    image: NDArray,
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


def nominal_model(spec: CameraSpec) -> BearingTable | None:
    """Bearings under the camera's Step 1 model (best classic projection at the nominal focal length)."""
    try:
        return BearingTable(initial_model(spec, lens_candidates(spec)[0]))
    except CoreError:
        return None


def detect_recording(
    frames: Iterable[ImageFrame],
    rig: RigSpec,
    *,
    tolerance_ns: int = 5_000_000,
    blob_options: BlobOptions = BlobOptions(),
    inspect: Callable[[ImageFrame, Blobs | None, WandDetection | None, str | None], None] | None = None,
) -> Detections:
    """Wand observations of a recording, with per-camera counts (detected, rejected by reason).

    Args:
        frames: decoded images of the rig's cameras, roughly in time order.
        rig: the rig description (image sizes, wand lengths).
        tolerance_ns: images closer in time than this belong to the same frame.
        blob_options: blob extraction settings.
        inspect: called for every image with its blobs, detection and rejection reason
            (progress reports, debug overlays).
    """
    wand_options = WandOptions(ratio=rig.wand.L1 / rig.wand.L2)
    sizes = {c.name: c.image_size for c in rig.cameras}
    models = {c.name: nominal_model(c) for c in rig.cameras}
    stats = {name: CameraStats() for name in rig.camera_names}
    found: dict[str, list[tuple[int, WandDetection]]] = {name: [] for name in rig.camera_names}
    stamps: list[int] = []
    for frame in sorted(frames, key=lambda f: f.stamp_ns):
        stamps.append(frame.stamp_ns)
        counts = stats[frame.camera]
        counts.images += 1
        height, width = frame.image.shape[:2]
        blobs: Blobs | None = None
        detection: WandDetection | None = None
        if (width, height) != sizes[frame.camera]:
            reason: str | None = "wrong_size"
        else:
            try:
                blobs, detection = detect_image(
                    frame.image, frame.encoding, blob_options, wand_options, models[frame.camera]
                )
                reason = detection.reason if detection.points is None else None
            except ImageError:
                reason = "bad_image"
        if inspect is not None:
            inspect(frame, blobs, detection, reason)
        if reason is not None or detection is None:
            counts.rejected[reason or "no_wand"] += 1
            continue
        found[frame.camera].append((frame.stamp_ns, detection))
    detections: list[tuple[int, str, NDArray[np.float64]]] = []
    unsettled: list[tuple[int, str, NDArray[np.float64]]] = []
    for camera, sequence in found.items():
        labelled = track_labels(sequence)
        for (stamp, detection), points in zip(sequence, labelled, strict=True):
            if points is None:
                stats[camera].rejected["ambiguous"] += 1
                unsettled.append((stamp, camera, detection.points))  # type: ignore[arg-type]
            else:
                stats[camera].detected += 1
                detections.append((stamp, camera, points))
    slots = _slots(np.array(stamps, dtype=np.int64), tolerance_ns)
    observations = _group(detections, slots, rig.camera_names)
    ambiguous = [
        (int(np.searchsorted(slots, stamp, side="right")) - 1, camera, points) for stamp, camera, points in unsettled
    ]
    return Detections(observations, stats, ambiguous)


class OnlineLabeller:
    """Labels one camera's detections as they come (the forward pass of :func:`track_labels`)."""

    def __init__(self) -> None:
        self._last: tuple[int, NDArray[np.float64]] | None = None

    def update(
        self, stamp_ns: int, detection: WandDetection, known: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64] | None:
        """A, B, C of the detection, or None when neither its image nor the previous detection settles them.

        Only confident labellings (image ratio >= ANCHOR_RATIO) stand on their own: perspective can
        shrink |AB| below |BC| when the wand points steeply at the camera. Others follow the previous
        settled detection when it is at most TRACK_GAP_NS away. A chain never bridges a detection
        it could not settle: the wand may have turned through the line of sight there, swapping
        which image end is A. ``known`` labels from an earlier pass are taken as they are.
        """
        points = known
        if points is None and detection.points is not None and detection.image_ratio >= ANCHOR_RATIO:
            points = detection.points
        elif points is None and self._last is not None and abs(stamp_ns - self._last[0]) <= TRACK_GAP_NS:
            resolved = resolve_with_previous(detection, self._last[1])
            points = None if resolved.ambiguous else resolved.points
        self._last = None if points is None else (stamp_ns, points)
        return points


def track_labels(sequence: list[tuple[int, WandDetection]]) -> list[NDArray[np.float64] | None]:
    """A, B, C of each detection of one camera, ambiguous ones settled by their neighbours in time.

    A forward pass of :class:`OnlineLabeller`, then a backward one that settles what is left from
    the next detection. Detections nothing settles are None.
    """
    forward = OnlineLabeller()
    labelled = [forward.update(stamp, detection) for stamp, detection in sequence]
    backward = OnlineLabeller()
    for i in range(len(sequence) - 1, -1, -1):
        stamp, detection = sequence[i]
        labelled[i] = backward.update(stamp, detection, known=labelled[i])
    return labelled


def _slots(stamps: NDArray[np.int64], tolerance_ns: int) -> NDArray[np.int64]:
    """First stamp of each time slot: an image opens a new slot when it lies more than
    ``tolerance_ns`` after the current slot's first stamp."""
    starts: list[int] = []
    for stamp in np.sort(stamps):
        if not starts or stamp - starts[-1] > tolerance_ns:
            starts.append(int(stamp))
    return np.array(starts, dtype=np.int64)


def _group(
    detections: list[tuple[int, str, NDArray[np.float64]]], slots: NDArray[np.int64], names: tuple[str, ...]
) -> WandObservations:
    """Observations whose frame ids number the recording's time slots (frames without a wand left out)."""
    uv = np.full((slots.size, len(names), 3, 2), np.nan)
    index = {name: i for i, name in enumerate(names)}
    for stamp, camera, points in detections:
        uv[int(np.searchsorted(slots, stamp, side="right")) - 1, index[camera]] = points
    seen = np.any(np.isfinite(uv), axis=(1, 2, 3))
    return WandObservations(np.flatnonzero(seen), names, uv[seen])
