"""How well a detector did on rendered images: views found, false views, centres and labels against the truth."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.collection.recording import detect_recording
from wand_calib_ros.core.adjust.brightness_bias import MIN_CLASS_POINTS
from wand_calib_ros.core.judge.metrics import camera_errors, rereference
from wand_calib_ros.core.model.brightness import brightness_classes as model_classes
from wand_calib_ros.core.model.brightness import radial_directions
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.detection.consistency import settle_labels
from wand_calib_ros.detection.recording import Detections
from wand_calib_ros.io.bags import ImageFrame
from wand_calib_ros.io.images import decode_compressed
from wand_calib_ros.sim.room import CameraTruth, RoomRecording, clearly_visible
from wand_calib_ros.sim.scenarios import Scenario

FloatArray = NDArray[np.float64]

#: The error classes a calibration from detections is judged in (against the floor of the right views alone).
ERROR_CLASSES = ("focal", "pp", "E_r", "E_t", "curve")
#: A returned view is right when each of its points is within this distance of its LED's truth (px).
RIGHT_PX = 3.0
#: A returned view belongs to the image whose stamp is within this of its own (s).
STAMP_MATCH_S = 1e-4


@dataclass(frozen=True)
class DetectionScore:
    """Counts over the images of one or more cameras.

    Attributes:
        clearly_visible: images whose wand a detector must find (:func:`wand_calib_ros.sim.room.clearly_visible`).
        found: of those, the ones with a right view returned (labels aside).
        returned: views returned.
        false: returned views with a point more than RIGHT_PX from every LED's truth in either order.
        swapped: right views whose A and C are exchanged.
        centre_sq_px: sum of the squared 2D errors of the right views' points, px^2.
        centres: points in ``centre_sq_px``.
    """

    clearly_visible: int
    found: int
    returned: int
    false: int
    swapped: int
    centre_sq_px: float
    centres: int

    @property
    def recall(self) -> float:
        return self.found / max(self.clearly_visible, 1)

    @property
    def false_rate(self) -> float:
        return self.false / max(self.returned, 1)

    @property
    def labels_right(self) -> float:
        right = self.returned - self.false
        return (right - self.swapped) / max(right, 1)

    @property
    def centre_rms_px(self) -> float:
        """RMS of the 2D centre error of the right views' points, px."""
        return float(np.sqrt(self.centre_sq_px / max(self.centres, 1)))

    def __add__(self, other: DetectionScore) -> DetectionScore:
        return DetectionScore(
            *(a + b for a, b in zip(self.counts(), other.counts(), strict=True))  # type: ignore[arg-type]
        )

    def counts(self) -> tuple[float, ...]:
        return (
            self.clearly_visible,
            self.found,
            self.returned,
            self.false,
            self.swapped,
            self.centre_sq_px,
            self.centres,
        )


def right_views(observations: WandObservations, truth: tuple[CameraTruth, ...]) -> NDArray[np.bool_]:
    """(F, C) the returned views that are right (every point within RIGHT_PX of its LED in either order)."""
    return _compare(observations, truth).right


def right_and_labelled(observations: WandObservations, truth: tuple[CameraTruth, ...]) -> NDArray[np.bool_]:
    """(F, C) the returned views that are right with A and C in the right order: the floor a calibration from the
    detections is measured against."""
    compared = _compare(observations, truth)
    return np.asarray(compared.right & ~compared.swapped)


@dataclass(frozen=True)
class _Compared:
    """The returned views against the truth (:func:`_compare`).

    Attributes:
        right: (F, C) right views.
        swapped: (F, C) right views with A and C exchanged.
        offsets: (F, C, K, 2) each point's offset from its LED's truth, in the better order (px).
        images: per camera the image index of each frame (-1: none).
    """

    right: NDArray[np.bool_]
    swapped: NDArray[np.bool_]
    offsets: FloatArray
    images: list[NDArray[np.int64]]

    @property
    def errors(self) -> FloatArray:
        """(F, C, K) each point's distance from its LED's truth (px)."""
        return np.asarray(np.linalg.norm(self.offsets, axis=-1))


def _compare(observations: WandObservations, truth: tuple[CameraTruth, ...]) -> _Compared:
    """Per returned view: right, swapped, the offsets of its points in the better order, and per camera the image
    index of each frame (-1: none)."""
    if observations.stamps is None:
        raise ValueError("scoring needs the views' stamps")
    shape = observations.uv.shape[:2]
    right = np.zeros(shape, dtype=bool)
    swapped = np.zeros(shape, dtype=bool)
    offsets = np.full(observations.uv.shape, np.nan)
    images = []
    for camera in truth:
        column = observations.camera_names.index(camera.name)
        stamps = camera.stamps_ns / 1e9
        wanted = observations.stamps[:, column]
        index = np.searchsorted(stamps, wanted)
        index = np.clip(index, 1, len(stamps) - 1)
        nearer = np.where(np.abs(stamps[index - 1] - wanted) <= np.abs(stamps[index] - wanted), index - 1, index)
        matched = np.isfinite(wanted) & (np.abs(stamps[nearer] - np.nan_to_num(wanted)) <= STAMP_MATCH_S)
        image = np.where(matched, nearer, -1)
        images.append(image)
        returned = observations.complete[:, column] & matched
        seen = observations.uv[:, column]
        true = camera.uv[np.maximum(image, 0)]
        straight = np.linalg.norm(seen - true, axis=-1)
        reverse = np.linalg.norm(seen - true[:, ::-1], axis=-1)
        with np.errstate(invalid="ignore"):
            straight_ok = np.all(straight <= RIGHT_PX, axis=1)
            reverse_ok = np.all(reverse <= RIGHT_PX, axis=1)
        right[:, column] = returned & (straight_ok | reverse_ok)
        swapped[:, column] = returned & ~straight_ok & reverse_ok
        offsets[:, column] = np.where(swapped[:, column, None, None], seen - true[:, ::-1], seen - true)
    return _Compared(right, swapped, offsets, images)


def centre_bias_by_class(
    observations: WandObservations, truth: tuple[CameraTruth, ...], camera: str, principal_point: FloatArray
) -> dict[int, tuple[float, float, float]]:
    """Where a camera's detected centres sit against the truth, per brightness class of its right views' points
    (:func:`~wand_calib_ros.core.model.brightness.brightness_classes`, 1 and up) relative to class 0's, in the
    adjustment's terms (:class:`~wand_calib_ros.core.model.result.ClassBias`): (offset u, offset v, radial away
    from ``principal_point``), px, by least squares; classes of fewer than MIN_CLASS_POINTS points left out (and
    all of them without class 0's)."""
    if observations.brightness is None:
        return {}
    compared = _compare(observations, truth)
    column = observations.camera_names.index(camera)
    right = compared.right[:, column]
    offsets = compared.offsets[right, column].reshape(-1, 2)
    points = observations.uv[right, column].reshape(-1, 2)
    stops = observations.brightness[right, column].reshape(-1)
    known = np.isfinite(stops) & np.isfinite(offsets).all(axis=1)
    offsets, points, classes = offsets[known], points[known], model_classes(stops[known])
    if np.count_nonzero(classes == 0) < MIN_CLASS_POINTS:
        return {}
    reference = offsets[classes == 0].mean(axis=0)
    away, _ = radial_directions(points, np.broadcast_to(principal_point, points.shape))
    out = {}
    for klass in range(1, int(classes.max(initial=0)) + 1):
        chosen = classes == klass
        if np.count_nonzero(chosen) < MIN_CLASS_POINTS:
            continue
        design = np.zeros((2 * int(chosen.sum()), 3))
        design[0::2, 0], design[1::2, 1], design[:, 2] = 1.0, 1.0, away[chosen].reshape(-1)
        solved, *_ = np.linalg.lstsq(design, (offsets[chosen] - reference).reshape(-1), rcond=None)
        out[klass] = (float(solved[0]), float(solved[1]), float(solved[2]))
    return out


def score(
    observations: WandObservations,
    truth: tuple[CameraTruth, ...],
    select: Callable[[CameraTruth], NDArray[np.bool_]] | None = None,
) -> DetectionScore:
    """The detector's views against the truth of the images they came from (matched by camera and stamp).

    Args:
        observations: the detector's views, with their stamps.
        truth: per camera what was drawn.
        select: per camera the (N,) images to count (:func:`brightness_classes`), or None: all, and returned
            views that match no image's stamp count as false.
    """
    compared = _compare(observations, truth)
    right, swapped, errors, images = compared.right, compared.swapped, compared.errors, compared.images
    visible = found = returned = false = turned = 0
    squares = 0.0
    centres = 0
    for c, camera in enumerate(truth):
        column = observations.camera_names.index(camera.name)
        chosen = np.ones(camera.stamps_ns.shape, dtype=bool) if select is None else select(camera)
        clear = clearly_visible(camera) & chosen
        visible += int(clear.sum())
        found += int(clear[images[c][right[:, column]]].sum())
        counted = observations.complete[:, column] & (images[c] >= 0)
        counted &= chosen[np.maximum(images[c], 0)]
        if select is None:
            counted = observations.complete[:, column]
        returned += int(counted.sum())
        false += int((counted & ~right[:, column]).sum())
        turned += int((counted & swapped[:, column]).sum())
        good = errors[counted & right[:, column], column]
        squares += float(np.sum(good**2))
        centres += good.size
    return DetectionScore(visible, found, returned, false, turned, squares, centres)


#: Brightness classes of a view (its brightest LED before clipping, in multiples of full scale): lower edges.
BRIGHTNESS_EDGES = (0.0, 4.0, 8.0, 16.0)


def brightness_classes(
    edges: tuple[float, ...] = BRIGHTNESS_EDGES,
) -> dict[str, Callable[[CameraTruth], NDArray[np.bool_]]]:
    """Per class name ("<4x", "4-8x", ...) a selector of the images whose brightest LED falls in it, for
    :func:`score`."""
    bounds = [*edges, np.inf]
    classes: dict[str, Callable[[CameraTruth], NDArray[np.bool_]]] = {}
    for low, high in itertools.pairwise(bounds):
        name = f"<{high:g}x" if low == 0 else (f">{low:g}x" if not np.isfinite(high) else f"{low:g}-{high:g}x")

        def chosen(truth: CameraTruth, low: float = low, high: float = high) -> NDArray[np.bool_]:
            over = truth.over_saturation()
            return np.asarray((over >= low) & (over < high))

        classes[name] = chosen
    return classes


def detect_room_recording(recording: RoomRecording, rig: RigSpec) -> tuple[WandObservations, Detections]:
    """What ``wand-calib detect`` makes of a rendered take: its images decoded as the command decodes a bag's
    (compressed ones included), the detector's pipeline, then the labels checked across cameras."""
    frames = []
    for camera, stamp, payload, encoding in recording.frames:
        if isinstance(payload, bytes):
            image, decoded = decode_compressed(payload, encoding)
            frames.append(ImageFrame(camera, stamp, image, decoded))
        else:
            frames.append(ImageFrame(camera, stamp, payload, encoding))
    detections = detect_recording(frames, rig)
    observations, _ = settle_labels(rig, detections)
    return observations, detections


def calibration_errors(scenario: Scenario, result: CalibrationResult) -> dict[str, list[float]]:
    """Per :data:`ERROR_CLASSES` the errors of a calibration against the scenario's truth: focal, principal
    point and curve (px) of every camera, E_r (deg) and E_t of every camera but the reference."""
    names = [c.spec.name for c in scenario.cameras]
    poses = rereference({n: result.camera(n).pose for n in names}, names[0])
    out: dict[str, list[float]] = {k: [] for k in ERROR_CLASSES}
    for c, camera in enumerate(scenario.cameras):
        e = camera_errors(result.camera(camera.spec.name).model, poses[camera.spec.name], camera.model, camera.pose)
        out["focal"].append(e.focal_px)
        out["pp"].append(e.principal_point_px)
        out["curve"].append(e.curve_px)
        if c:
            out["E_r"].append(e.rotation_deg)
            out["E_t"].append(e.translation)
    return out
