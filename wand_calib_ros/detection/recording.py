"""From a stream of camera images to wand observations: the detector's pipeline, per camera.

Each camera's images go through a :class:`CameraStream`:

1. the grey image (:func:`~wand_calib_ros.detection.blobs.to_gray`);
2. its local background and noise (:mod:`~wand_calib_ros.detection.background`, refreshed every
   BACKGROUND_REFRESH images: a room's background changes slowly);
3. the blobs that stand out of it, outside the camera's mask (the user's and the learned lights',
   :mod:`~wand_calib_ros.detection.masks`), with their centres (:mod:`~wand_calib_ros.detection.centres`);
4. the wand among the blobs that may be part of it (not still lights), preferring the triple that
   continues the camera's track (:mod:`~wand_calib_ros.detection.wand`);
5. the track: views confirmed once it moved, labels decided by its votes
   (:mod:`~wand_calib_ros.detection.tracking`); the static lights learned from what is left.

An ambiguous A/C labelling is settled by the track, otherwise the view is rejected as
"ambiguous" rather than risk swapped labels. A recording's cameras are put on their time lines and
grouped into frames by :mod:`wand_calib_ros.collection.recording`, a live rig's by the collection
session (:mod:`wand_calib_ros.collection.session`).
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.initialise.clock_alignment import ClockAlignment
from wand_calib_ros.core.initialise.intrinsics_init import nominal_bearings
from wand_calib_ros.core.model.bearings import BearingTable
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.rig import CameraSpec, WandObservations
from wand_calib_ros.detection.background import Background, box_sums, estimate_background, masked, sums_dtype
from wand_calib_ros.detection.blobs import ENCODINGS, BlobOptions, Blobs, distances, find_blobs, to_gray
from wand_calib_ros.detection.errors import ImageError
from wand_calib_ros.detection.health import CameraHealth, HealthReport, ViewLight, health_report, view_light
from wand_calib_ros.detection.masks import Mask, MaskTaker, StaticSources
from wand_calib_ros.detection.structure import StaticStructure
from wand_calib_ros.detection.tracking import Prediction, Released, StreamLabeller
from wand_calib_ros.detection.wand import WandDetection, WandOptions, identify_wand

#: A camera's background is estimated again every this many images.
BACKGROUND_REFRESH = 8
#: The wand is kept out of the static structure this far (px) beyond its spots' extent and its track's gate.
WAND_MARGIN_PX = 4.0
#: The value a saturated pixel of each encoding reads (a 12-bit camera's mono16 is scaled to 16 bits).
SATURATION = {"mono16": 65520.0}


class Unsettled(NamedTuple):
    """A view whose A/C labels neither its image nor its track settled (other cameras can,
    :func:`wand_calib_ros.detection.consistency.label_across_cameras`).

    Attributes:
        frame: the frame id of the recording's observations it belongs to.
        camera: its camera.
        points: (K, 2) its points, the wand's ends in either order.
        stamp_s: its image's stamp, s.
        brightness: (K,) how bright each of ``points`` was, stops over full scale, or None: not measured.
    """

    frame: int
    camera: str
    points: NDArray[np.float64]
    stamp_s: float
    brightness: NDArray[np.float64] | None = None


@dataclass(frozen=True, eq=False)
class Detections:
    """What a recording gave.

    Attributes:
        observations: labelled wand points per frame (time slot) and camera.
        stats: per camera counts.
        ambiguous: the views whose A/C labels neither the image nor time settled (other cameras can).
        tracks: (F, C) the camera's track of each view (-1: no view): views of one track were labelled together.
        reports: per camera what it saw (:mod:`~wand_calib_ros.detection.health`).
        masks: per camera the pixels its detector ignored at the end (given and learned), or None: none.
        clocks: the cameras' clock offsets the wand's motion gave for the grouping (the calibration of the same
            views need not search them again), or None: not decided.
    """

    observations: WandObservations
    stats: dict[str, CameraStats]
    ambiguous: list[Unsettled]
    tracks: NDArray[np.int64]
    reports: dict[str, HealthReport]
    masks: dict[str, Mask | None]
    clocks: ClockAlignment | None = None


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
    mask: Mask | None = None,
) -> tuple[Blobs, WandDetection]:
    """Blobs and wand of one decoded image on its own, with no track or learned lights (ImageError for
    unusable images)."""
    gray = to_gray(image, encoding)
    blobs = find_blobs(gray, blob_options, saturation=SATURATION.get(encoding, 255.0), mask=mask)
    return blobs, identify_wand(blobs, wand_options, model)


class Labelled(NamedTuple):
    """One image's outcome once its labels are decided.

    Attributes:
        stamp_ns: the image's stamp.
        points: (3, 2) pixels of A, B, C, or None (no wand, or A and C could not be told apart).
        unsettled: (3, 2) the wand's ends and middle in either order when only the A/C labels were
            missing (other cameras may settle them), else None.
        track: the camera's track the view belongs to (-1: none): its views' labels stand or fall together.
        brightness: (K,) how bright each of ``points`` (or ``unsettled``) was, stops over full scale
            (:mod:`~wand_calib_ros.core.model.brightness`; 0 and more: a saturated spot), or None: not known.
    """

    stamp_ns: int
    points: NDArray[np.float64] | None
    unsettled: NDArray[np.float64] | None = None
    track: int = -1
    brightness: NDArray[np.float64] | None = None


class CameraStream:
    """One camera's images in, labelled wand points out (see the module docstring).

    Feed images in time order with :meth:`push` (or :meth:`detect` and :meth:`label` to see each
    image's blobs); results come out in time order, held ones up to ``max_hold_ns`` late.
    ``stats`` counts images, labelled wands and rejections by reason.
    """

    def __init__(
        self,
        spec: CameraSpec,
        wand_options: WandOptions,
        blob_options: BlobOptions = BlobOptions(),
        *,
        max_hold_ns: int | None = 1_000_000_000,
        mask: Mask | None = None,
    ) -> None:
        self.spec = spec
        self.wand_options = wand_options
        self.blob_options = blob_options
        self.model = nominal_bearings(spec)
        self.labeller = StreamLabeller(max_hold_ns)
        self.sources = StaticSources(spec.image_size)
        self.structure = StaticStructure(blob_options.background)
        self._wand_spots: tuple[NDArray[np.float64], Blobs] | None = None  # the newest wand's points, its image's blobs
        self._encoding = "mono8"  # the newest image's
        self.given_mask = mask
        self.stats = CameraStats()
        self.health = CameraHealth()
        self._lights: dict[int, ViewLight] = {}  # the light of a detected view, until labelled
        self._background: Background | None = None
        self._searched: tuple[Background, Mask | None, Background] | None = None  # (background, mask, both)
        self._since_background = 0
        self._mask: Mask | None = mask
        self._pending: deque[tuple[int, WandDetection, ViewLight | None]] = deque()  # pushed, not yet released
        self._gaps: deque[Labelled] = deque()  # images without a view, waiting behind older held views
        self._taker: MaskTaker | None = None  # a mask being taken (take_mask)
        self._taking_ns = 0
        self._taking_from: int | None = None
        self.taken: Mask | None = None  #: the masks taken so far (take_mask), together

    @property
    def mask(self) -> Mask | None:
        """What the detector ignores: the user's mask and the learned lights'."""
        return self._mask

    def take_mask(self, duration_ns: int) -> None:
        """Take a mask from the next ``duration_ns`` of images (the wand out of sight): every blob in them is
        ignored from then on. Meanwhile the images give no view ("taking_mask")."""
        self._taker, self._taking_ns, self._taking_from = MaskTaker(self.spec.image_size), duration_ns, None

    @property
    def taking_mask(self) -> bool:
        """Whether a mask is being taken."""
        return self._taker is not None

    def detect(
        self, image: NDArray[Any] | None, encoding: str, stamp_ns: int
    ) -> tuple[Blobs | None, WandDetection | None, str | None]:
        """Blobs, wand and rejection reason (None when the wand was found) of one image at ``stamp_ns`` (None:
        its pixels could not be read)."""
        self.stats.images += 1
        self._encoding = encoding
        if image is None:
            return None, None, "bad_image"
        if encoding not in ENCODINGS:
            return None, None, "encoding"
        height, width = image.shape[:2]
        if (width, height) != self.spec.image_size:
            return None, None, "wrong_size"
        try:
            gray = to_gray(image, encoding)
        except ImageError:
            return None, None, "bad_image"
        raw, gray = gray, self.sources.clean(gray)  # the learned lights' halos taken away
        prediction = self.labeller.predict(stamp_ns)
        background = self._search_of(self._background_of(gray, stamp_ns, prediction))
        blobs = find_blobs(
            gray, self.blob_options, saturation=SATURATION.get(encoding, 255.0), mask=self._mask, background=background
        )
        if self._taker is not None:
            return blobs, None, self._take(stamp_ns, blobs)
        claimed = np.zeros(blobs.centres.shape[0], dtype=bool)
        if prediction is not None and prediction.moved and blobs.centres.size:
            gaps = distances(blobs.centres, prediction.points).min(axis=1)
            claimed = gaps <= prediction.gate_px
        usable = ~self.sources.still(blobs)  # (the wand's own blobs are never learned: it cannot be still)
        near = None if prediction is None else (prediction.points, prediction.gate_px)
        detection = identify_wand(blobs, self.wand_options, self.model, usable=usable, near=near)
        if detection.points is not None and prediction is not None and prediction.moved and blobs.centres.size:
            gaps = distances(blobs.centres, detection.points).min(axis=1)
            claimed |= gaps < 1e-6
        if detection.points is not None and blobs.centres.size:  # (how far its spots reach: when a snapshot needs it)
            self._wand_spots = (detection.points, blobs)
        standing_out = self.sources.centres_standing_out(raw, background.threshold)
        since = self.labeller.since_ns if prediction is not None else None
        if self.sources.observe(stamp_ns, blobs, claimed, standing_out, since, raw):  # the mask changed
            learned, given = self.sources.mask, self.given_mask
            self._mask = learned if given is None else np.maximum(given, learned).astype(np.uint8)
        if detection.points is not None:
            light = view_light(blobs, detection.points)
            if light is not None:
                self._lights[stamp_ns] = light
        return blobs, detection, detection.reason if detection.points is None else None

    def _take(self, stamp_ns: int, blobs: Blobs) -> str:
        """One image of a mask being taken; the mask joins the given one once its time is up."""
        assert self._taker is not None
        start = self._taking_from = stamp_ns if self._taking_from is None else self._taking_from
        if stamp_ns - start <= self._taking_ns:
            self._taker.add(blobs)
            return "taking_mask"
        taken = self._taker.mask
        self.taken = taken if self.taken is None else np.maximum(self.taken, taken).astype(np.uint8)
        self.given_mask = taken if self.given_mask is None else np.maximum(self.given_mask, taken).astype(np.uint8)
        learned = self.sources.mask
        self._mask = np.maximum(self.given_mask, learned).astype(np.uint8)
        self._taker = None
        return "taking_mask"

    def passed_over(self, repeated: bool) -> str:
        """Count an image its camera's time line did not place next (behind a newer one, or its previous stamp
        again: ``repeated``; it is not searched); its reason."""
        reason = "repeated_stamp" if repeated else "late"
        self.stats.images += 1
        self.stats.rejected[reason] += 1
        return reason

    def report(self) -> HealthReport:
        """What this camera saw so far (:mod:`~wand_calib_ros.detection.health`)."""
        full = SATURATION.get(self._encoding, 255.0)
        learned = tuple((s.centre[0], s.centre[1], s.radius_px) for s in self.sources.sources)
        sources = learned + self.structure.lights(full)
        ignored = self.structure.saturated(full)
        if self._mask is not None:
            ignored = self._mask > 0 if ignored is None else ignored | (self._mask > 0)
        masked = 0.0 if ignored is None else float(np.count_nonzero(ignored)) / ignored.size
        stats = self.stats
        return health_report(self.spec.name, stats.images, stats.detected, stats.rejected, self.health, sources, masked)

    def _search_of(self, background: Background) -> Background:
        """The background with the current mask in its search threshold (made again when either changed)."""
        current, mask = self._background, self._mask
        assert current is not None
        if self._searched is None or self._searched[0] is not current or self._searched[1] is not mask:
            self._searched = (current, mask, masked(current, mask))
        searched = self._searched[2]
        return searched if background.sums is None else replace(searched, sums=background.sums)

    def _keep_out(self, prediction: Prediction | None) -> list[tuple[float, float, float]]:
        """(u, v, radius px) where the wand's LEDs are expected (kept out of the structure): the track's predicted
        points, as far as its gate and the newest wand's spots reach beyond them (none while it has not moved)."""
        if prediction is None or not prediction.moved:
            return []
        reach = WAND_MARGIN_PX
        if self._wand_spots is not None:
            points, blobs = self._wand_spots
            spots = distances(points, blobs.centres).argmin(axis=1)
            reach += float(np.max(blobs.radii()[spots]))
        return [(float(u), float(v), prediction.gate_px + reach) for u, v in prediction.points]

    def _background_of(self, gray: NDArray[Any], stamp_ns: int, prediction: Prediction | None) -> Background:
        """The background of the image's box sums, estimated again every BACKGROUND_REFRESH images until a static
        structure is learned, then with each snapshot of it (and when the image changed kind), with the structure's
        threshold; ``prediction``: where the track expects the wand (kept out of the structure)."""
        current = self._background
        learned = current is not None and current.structure is not None  # (then the spatial background only shapes
        # the structure's threshold, made once per snapshot)
        stale = (self._since_background >= BACKGROUND_REFRESH and not learned) or self.structure.due(stamp_ns)
        depth = sums_dtype(gray)
        self._since_background += 1
        if current is None or stale or current.threshold.shape != gray.shape or current.threshold.dtype != depth:
            sums, unit = box_sums(gray)
            if self.structure.due(stamp_ns):
                keep_out = self._keep_out(prediction)
                if self.structure.worth_keeping(stamp_ns, sums, keep_out):
                    self.structure.add(stamp_ns, gray, sums, keep_out)
            if current is not None and learned and self.structure.unchanged and current.threshold.dtype == depth:
                self._since_background = 1  # (a still room's snapshot: the structure and its threshold stand)
                self._background = replace(current, static=self.structure.pixels)
                return replace(self._background, sums=sums)
            background = estimate_background(sums, self.blob_options.background, unit=unit)
            self._background = self.structure.apply(background)
            self._since_background = 1
            return replace(self._background, sums=sums)  # this image's sums: find_blobs need not sum again
        return current

    def label(self, stamp_ns: int, detection: WandDetection | None, reason: str | None) -> list[Labelled]:
        """Hand one image's detection to the labeller; returns the outcomes it releases."""
        light = self._lights.pop(stamp_ns, None)
        if reason is not None or detection is None:
            self.stats.rejected[reason or "no_wand"] += 1
            self._gaps.append(Labelled(stamp_ns, None))
            return self._in_order(self._released(self.labeller.advance(stamp_ns)))  # (time passes for held views)
        if self.wand_options.n_points != 3 or detection.tool:  # two or a tool: the calibration labels them
            self.stats.detected += 1
            self.health.add(light)
            stops = None if light is None or detection.tool else light.brightness
            return [*self.flush(), Labelled(stamp_ns, detection.points, brightness=stops)]
        self._pending.append((stamp_ns, detection, light))
        return self._in_order(self._released(self.labeller.push(stamp_ns, detection)))

    def push(self, stamp_ns: int, image: NDArray[Any], encoding: str) -> list[Labelled]:
        """:meth:`detect` then :meth:`label`."""
        _, detection, reason = self.detect(image, encoding, stamp_ns)
        return self.label(stamp_ns, detection, reason)

    def flush(self) -> list[Labelled]:
        """Release what the labeller holds back (unsettled)."""
        return self._in_order(self._released(self.labeller.flush()))

    def _in_order(self, released: list[Labelled]) -> list[Labelled]:
        """The released views and the images without a view older than every view still held, in stamp order
        (a synchroniser downstream takes a camera's stamps going backwards for a lossy transport)."""
        held_from = self._pending[0][0] if self._pending else None
        count = len(self._gaps) if held_from is None else sum(g.stamp_ns < held_from for g in self._gaps)
        gaps = [self._gaps.popleft() for _ in range(count)]
        return sorted([*released, *gaps], key=lambda outcome: outcome.stamp_ns)

    def _released(self, results: list[Released]) -> list[Labelled]:
        out = []
        for stamp, points, reason, track in results:
            _, detection, light = self._pending.popleft()
            stops = None if light is None else light.brightness  # (in the order of detection.points)
            if points is not None:
                self.stats.detected += 1
                self.health.add(light)
                labelled = (
                    stops if stops is None or detection.points is None else _reordered(stops, detection.points, points)
                )
                out.append(Labelled(stamp, points, None, track, labelled))
            elif reason == "ambiguous":
                self.stats.rejected["ambiguous"] += 1
                out.append(Labelled(stamp, None, detection.points, track, stops))
            else:
                self.stats.rejected[reason or "no_wand"] += 1
                out.append(Labelled(stamp, None))
        return out


def _reordered(
    values: NDArray[np.float64], found: NDArray[np.float64], labelled: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(K,) the values of the ``found`` (K, 2) points in the order of the same points ``labelled`` (A and C
    exchanged or not)."""
    return np.asarray(values[distances(labelled, found).argmin(axis=1)])
