"""One camera's wand over time: a track links its views, predicts where it goes, tells a wand
from still lights, and decides its A/C labels.

Views of consecutive images (at most TRACK_GAP_NS apart) whose ends continuity pairs up
clearly (:func:`resolve_with_previous`) and that are near where the track was heading (none
of their points jumped) form a track. A track

- predicts the next image's points (constant velocity) and how far the wand may be from
  them (:meth:`StreamLabeller.predict`), so the assembly prefers the triple that continues it;
- is the wand once each of its points has moved MIN_TRACK_MOTION_PX from where the track
  first saw it: lamps in a row never move, nor does a lamp lined up with two LEDs as a
  whole, while a wand laid on the floor keeps the track it arrived with. Views of a track
  that has not moved are held, and given up as "still" when it has STILL_VIEWS views or
  lasted STILL_TRACK_S without moving, or began in the stream's first STILL_START_S (what was
  there from the start and has not moved is no wand, whatever lamps it took in; later, one or
  two images that continuity cannot link to others tell nothing either way: their views are kept);
- decides its labels: within a track the A/C labels can only all be right or all be
  swapped. Each view votes for its own order with log(|AB|/|BC|) in the image (near 0 for
  ambiguous images), and the track takes the order the votes favour once they sum to at
  least log(ANCHOR_RATIO) either way. One image's ratio alone can mislead: when the wand
  points towards the camera, perspective shrinks the far segment until the image ratio
  favours the wrong order for a stretch of frames; the rest of the track outvotes that stretch.

Live, a track's views are held until ``max_hold_ns`` after its first one (or until the track
ends), then decided and released; later ones of a decided track are released at once. Held
views the vote cannot decide come out unsettled. Results come out in time order. With
``max_hold_ns=None`` every track is decided on all its views (recordings).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.wand import WandDetection, distance_to

FloatArray = NDArray[np.float64]

#: Detections further apart in time than this do not belong to one track.
TRACK_GAP_NS = 200_000_000
#: A track's labels are decided once its votes (log image ratios) add up to log(ANCHOR_RATIO).
ANCHOR_RATIO = 1.5
#: Continuity settles a labelling only when one order is this much closer to the previous frame than the other.
CONTINUITY_MARGIN = 0.5
#: A track is the wand once each of its points has moved this far (px) from where the track began ...
MIN_TRACK_MOTION_PX = 3.0
#: ... and still lights when it has this many views ...
STILL_VIEWS = 5
#: ... or lasted this long (s) without, or began this soon (s) after the stream's first view.
STILL_TRACK_S = 0.3
STILL_START_S = 0.5
#: The wand is looked for within this distance (px) of the track's prediction ...
GATE_PX = 6.0
#: ... plus this fraction of the distance it is predicted to move ...
GATE_MOTION = 0.5
#: ... plus this fraction of its length in the image.
GATE_LENGTH = 0.05
#: A view further than this many gates from the track's prediction starts a new track (a point jumped).
JUMP_GATES = 2.0


class Released(NamedTuple):
    """One view's outcome once its track decided it.

    Attributes:
        stamp_ns: the image's stamp.
        points: (K, 2) A, B, C ... or None.
        reason: None when labelled; "ambiguous" (the labels were not settled) or "still" (its track never moved).
        track: the track it belongs to (numbered from 0 in the order tracks begin).
    """

    stamp_ns: int
    points: FloatArray | None
    reason: str | None = None
    track: int = -1


class Prediction(NamedTuple):
    """Where a track expects the wand in the next image.

    Attributes:
        points: (K, 2) in the track's order.
        gate_px: how far from them the wand may be.
        moved: the track is the wand (it has moved).
    """

    points: FloatArray
    gate_px: float
    moved: bool


def resolve_with_previous(detection: WandDetection, previous: FloatArray | None) -> WandDetection:
    """Label a detection by continuity with a neighbouring frame's A, B, C.

    The order (A, B, C) or (C, B, A) nearer to the neighbour's points wins when it
    is clearly nearer (CONTINUITY_MARGIN); otherwise (the wand turned through the
    line of sight between the frames) the detection stays ambiguous.
    """
    if detection.points is None or previous is None:
        return detection
    mine, theirs = detection.points.tolist(), previous.tolist()  # (scalar sums: cheaper than numpy's calls here)
    straight = sum(math.dist(a, b) for a, b in zip(mine, theirs, strict=True))
    swapped = sum(math.dist(a, b) for a, b in zip(mine[::-1], theirs, strict=True))
    if min(straight, swapped) > CONTINUITY_MARGIN * max(straight, swapped):
        return WandDetection(detection.points, detection.quality, None, True, detection.image_ratio)
    points = detection.points if straight <= swapped else detection.points[::-1].copy()
    return WandDetection(points, detection.quality, None, False, detection.image_ratio)


class StreamLabeller:
    """One camera's wand detections in, labelled and confirmed views out (see the module docstring)."""

    def __init__(self, max_hold_ns: int | None = 1_000_000_000, *, min_motion_px: float = MIN_TRACK_MOTION_PX) -> None:
        self.max_hold_ns = max_hold_ns
        self.min_motion_px = min_motion_px
        self._held: list[tuple[int, FloatArray, float]] = []  # stamp, points in track order, vote
        self._last: tuple[int, FloatArray] | None = None  # newest stamp and points in track order
        self._velocity: FloatArray | None = None  # px/ns of each point, track order
        self._first: FloatArray | None = None  # the track's first points
        self._since = 0  # and their stamp
        self._views = 0  # views in the track
        self._start: int | None = None  # the stream's first view
        self._predicted: tuple[int, Prediction] | None = None  # the newest prediction, by its stamp
        self._track = -1  # its number
        self._moved = False
        self._vote = 0.0
        self._forward: bool | None = None  # None: undecided; True: the track order is A, B, C

    @property
    def since_ns(self) -> int:
        """When the current track began."""
        return self._since

    @property
    def moved(self) -> bool:
        """Whether the current track is the wand (each of its points has moved)."""
        return self._moved

    def predict(self, stamp_ns: int) -> Prediction | None:
        """Where the current track expects the wand at ``stamp_ns`` (None: no track that recent)."""
        if self._last is None or not 0 <= stamp_ns - self._last[0] <= TRACK_GAP_NS:
            return None
        if self._predicted is not None and self._predicted[0] == stamp_ns:
            return self._predicted[1]
        last_ns, points = self._last
        length = math.dist(points[-1].tolist(), points[0].tolist())
        if self._velocity is None:
            prediction = Prediction(points, GATE_PX + GATE_LENGTH * length, self._moved)
        else:
            step = self._velocity * (stamp_ns - last_ns)
            moves = math.sqrt(float((step * step).sum(axis=1).max()))
            prediction = Prediction(points + step, GATE_PX + GATE_MOTION * moves + GATE_LENGTH * length, self._moved)
        self._predicted = (stamp_ns, prediction)
        return prediction

    def push(self, stamp_ns: int, detection: WandDetection) -> list[Released]:
        """Add a detection (in time order); returns the views it releases."""
        assert detection.points is not None
        self._start = stamp_ns if self._start is None else self._start
        released: list[Released] = []
        linked = None
        expected = self.predict(stamp_ns)
        if expected is not None and distance_to(detection.points, expected.points) <= JUMP_GATES * expected.gate_px:
            linked = resolve_with_previous(detection, expected.points)  # where each end was heading
        continues = linked is not None and not linked.ambiguous
        if not continues:
            released += self.flush()
        chosen = linked.points if continues and linked is not None else detection.points
        assert chosen is not None
        points: FloatArray = chosen
        if continues and self._last is not None:
            dt = max(stamp_ns - self._last[0], 1)
            velocity = (points - self._last[1]) / dt
            self._velocity = velocity if self._velocity is None else 0.5 * (self._velocity + velocity)
        else:
            self._first, self._velocity, self._since, self._views = points, None, stamp_ns, 0
            self._track += 1
        self._views += 1
        assert self._first is not None
        if not self._moved:
            gone = [math.dist(a, b) for a, b in zip(points.tolist(), self._first.tolist(), strict=True)]
            self._moved = min(gone) >= self.min_motion_px
        same = points is detection.points or bool(np.array_equal(points, detection.points))
        vote = min(max(math.log(max(detection.image_ratio, 1e-6)), -1.0), 1.0) * (1.0 if same else -1.0)
        self._vote += vote
        self._last, self._predicted = (stamp_ns, points), None
        if self._forward is not None:  # a decided track: its views go at once (unless it turned out still)
            labelled = points if self._forward else points[::-1].copy()
            still = self._still()
            released.append(Released(stamp_ns, None if still else labelled, "still" if still else None, self._track))
            return released
        self._held.append((stamp_ns, points, vote))
        if self.max_hold_ns is None or stamp_ns - self._held[0][0] < self.max_hold_ns:
            return released
        if self._moved or self._still():  # (a track that has not moved is held until it is still)
            released += self._decide()
        return released

    def advance(self, stamp_ns: int) -> list[Released]:
        """Time passes without a view (an image without the wand, or one the detector could not read): the views
        held for ``max_hold_ns`` by ``stamp_ns`` are decided and released, as a view at that time would release
        them (else a stretch of images without a view would hold them until the next view, past their frames)."""
        if self.max_hold_ns is None or not self._held or stamp_ns - self._held[0][0] < self.max_hold_ns:
            return []
        return self._decide() if self._moved or self._still() else []

    def flush(self) -> list[Released]:
        """End the current track: decide and release what it holds (end of a recording, /calibrate)."""
        released = self._decide()
        self._held, self._last, self._vote, self._forward, self._predicted = [], None, 0.0, None, None
        self._velocity, self._first, self._moved = None, None, False
        return released

    def _still(self) -> bool:
        """Whether the current track is still lights: it has not moved in STILL_VIEWS views or STILL_TRACK_S."""
        if self._moved or self._last is None:
            return False
        assert self._start is not None
        early = self._since - self._start < STILL_START_S * 1e9
        return early or self._views >= STILL_VIEWS or self._last[0] - self._since >= STILL_TRACK_S * 1e9

    def _decide(self) -> list[Released]:
        released: list[Released]
        if self._still():  # no point of it has moved for long: still lights, not a wand; keep watching the track
            released = [Released(stamp, None, "still", self._track) for stamp, _, _ in self._held]
        elif abs(self._vote) >= np.log(ANCHOR_RATIO):  # (a short track that has not moved: judged as any)
            self._forward = self._vote > 0
            forward = self._forward
            released = [
                Released(stamp, points if forward else points[::-1].copy(), None, self._track)
                for stamp, points, _ in self._held
            ]
        else:  # too little evidence so far: release unsettled, keep voting on what follows
            released = [Released(stamp, None, "ambiguous", self._track) for stamp, _, _ in self._held]
        self._held = []
        return released


def track_labels(sequence: list[tuple[int, WandDetection]]) -> list[FloatArray | None]:
    """A, B, C of each detection of one camera of a recording (None where the vote cannot decide or the
    track never moved): a :class:`StreamLabeller` that holds each track until it ends."""
    labeller = StreamLabeller(max_hold_ns=None)
    released = [out.points for stamp, detection in sequence for out in labeller.push(stamp, detection)]
    return released + [out.points for out in labeller.flush()]
