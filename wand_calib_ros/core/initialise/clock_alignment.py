"""Step 0: the cameras' clocks lined up from the wand's own motion, where they disagree by more than a frame or two.

A camera on a second computer, a driver that stamps with the camera's own clock, bags merged from two
machines, videos started by hand: their stamps (or frame counters) disagree by seconds, and frames grouped by
them pair views of different instants. The epipolar geometry tells which instants belong together. For a
pair of cameras and a lag D, the views of one camera at t and the other's at t + D (its track interpolated
in time) are correspondences of one rigid pair of cameras only at the true lag: there a linear essential
matrix fits them (m1^T E m0 = 0 on the cameras' nominal bearings) and its residual, the smallest eigenvalue
of sum a a^T over a = vec(m1 m0^T), is smallest. Those 81 sums are cross-correlations of products of bearing
components, so every lag is scored at once by FFT (:func:`lag_scores`); the best lag is then refined between
grid steps (:func:`pair_offset`). A lag is taken only where it fits clearly better than any other lag half a
second or more away: a motion so regular that two lags fit alike is said, not guessed.

Each camera's offset follows from the pairs that decided theirs, through whichever cameras share its view
(:func:`align_clocks`); cameras whose offset exceeds SHIFT_FRAMES frames are moved and the frames formed again
by nearest stamps (:func:`shifted`); what is left within a frame or two is the timing model's
(:mod:`~wand_calib_ros.core.adjust.timing`), which the calibration estimates as before. Offsets are in the
observations' time unit: seconds with stamps, frames with frame ids alone (exposure = stamp - offset).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.timing import frame_period
from wand_calib_ros.core.errors import TimingError
from wand_calib_ros.core.initialise.lens_choice import nominal_model
from wand_calib_ros.core.model.camera_model import CameraModel, unproject
from wand_calib_ros.core.model.rig import RigSpec, WandObservations

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: A camera's track is a continuous motion when its centre moves between consecutive images by less than this
#: fraction of its spread.
CONTINUOUS_STEP = 0.3
#: Between groups of cameras whose views do not line up with each other as they are, every pair is scanned in a
#: rig of up to ALL_PAIRS cameras, at most CROSS_PAIRS pairs of each two groups in a larger one.
ALL_PAIRS = 6
CROSS_PAIRS = 3
#: Cameras whose clock is off by more than this many frame periods are moved (less is the timing model's, which
#: estimates offsets of a frame or so from the views as they are grouped).
SHIFT_FRAMES = 2.0
#: A camera's track is interpolated across gaps of at most this many frame periods.
MAX_GAP_FRAMES = 1.6
#: Two cameras' views must overlap this many frame periods at a lag for it to be scored, and this fraction of the
#: shorter track (a few seconds of a small part of the volume can fit a wrong lag's views by chance).
MIN_OVERLAP_FRAMES = 90
MIN_OVERLAP = 0.3
#: A lag is decided when every lag at least DISTINCT_FRAMES frame periods away fits this many times worse.
DISTINCT = 3.0
DISTINCT_FRAMES = 15
#: Lags of each scan scored again on every marker.
CANDIDATES = 3
#: Steps a frame of the refinement between frames (seconds only: frame ids are whole frames).
REFINE_STEPS = 8
#: At zero lag a pair that fits this many times worse than at its best lag is not lined up.
MISALIGNED = 10.0


@dataclass(frozen=True, eq=False)
class Track:
    """One camera's views of the whole wand over time.

    Attributes:
        times: (N,) increasing times of its views, in the observations' unit.
        points: (N, K, 2) the wand's markers, px.
        period: its frame period in the unit.
    """

    times: FloatArray
    points: FloatArray
    period: float

    def at(self, when: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """(M, K, 2) the markers at the times ``when`` (M,), interpolated linearly between views at most
        MAX_GAP_FRAMES periods apart, and (M,) where they are known."""
        if self.times.size < 2:
            return np.zeros((when.size, *self.points.shape[1:])), np.zeros(when.size, dtype=bool)
        after = np.searchsorted(self.times, when).clip(1, self.times.size - 1)
        t0, t1 = self.times[after - 1], self.times[after]
        span = t1 - t0
        weight = ((when - t0) / np.where(span > 0, span, 1.0)).clip(0.0, 1.0)[:, None, None]
        points = self.points[after - 1] * (1.0 - weight) + self.points[after] * weight
        known = (span <= MAX_GAP_FRAMES * self.period) & (when >= self.times[0]) & (when <= self.times[-1])
        return points, known


def camera_tracks(observations: WandObservations) -> tuple[Track, ...]:
    """Each camera's track: its views of the whole wand in time order, by their stamps (or frame ids)."""
    whole = np.all(np.isfinite(observations.uv), axis=(2, 3))
    tracks = []
    for c in range(len(observations.camera_names)):
        if observations.stamps is None:
            times = observations.frames.astype(np.float64)
            seen = whole[:, c]
        else:
            times = observations.stamps[:, c]
            seen = whole[:, c] & np.isfinite(times)
        order = np.argsort(times[seen], kind="stable")
        mine = times[seen][order]
        period = 1.0 if observations.stamps is None else frame_period(mine)
        tracks.append(Track(mine, observations.uv[seen, c][order], period if np.isfinite(period) else 1.0))
    return tuple(tracks)


#: The six distinct products m_a m_b (a <= b) of a bearing's components, and where each of the nine goes.
_UPPER = np.triu_indices(3)
_SYMMETRIC = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])


def _products(bearings: FloatArray, known: NDArray[np.bool_]) -> FloatArray:
    """(n, 6) the distinct products m_a m_b (a <= b) of (n, 3) bearings (zero where not known)."""
    products = bearings[:, _UPPER[0]] * bearings[:, _UPPER[1]]
    return np.where(known[:, None], np.nan_to_num(products), 0.0)


def _lagged(spectra: NDArray[np.complex128], n: int, size: int) -> FloatArray:
    """(2n - 1, ...) the cross-correlations whose (size // 2 + 1, ...) spectra are given, lags -(n - 1)..n - 1."""
    out = np.fft.irfft(spectra, size, axis=0)
    return np.concatenate([out[size - (n - 1) :], out[:n]])


def lag_scores(
    first: FloatArray,
    first_known: NDArray[np.bool_],
    second: FloatArray,
    second_known: NDArray[np.bool_],
    markers: NDArray[np.int64],
) -> tuple[FloatArray, FloatArray]:
    """How well each lag L lines up two cameras' bearings on one time grid: (2n - 1,) the linear essential
    matrix's mean squared residual of the pairs (first at t, second at t + L), and (2n - 1,) how many pairs.

    The design matrix of the pairs at lag L, sum a a^T with a = vec(m1 m0^T), holds the sums of m1_a m1_b m0_c
    m0_d: the cross-correlations of the first camera's products m0_c m0_d with the second's m1_a m1_b, summed
    over the ``markers`` in the frequency domain (36 correlations for every lag at once).

    Args:
        first, second: (n, K, 3) each camera's bearings of the wand's markers on the grid.
        first_known, second_known: (n,) where they are known.
        markers: the markers scanned.
    """
    n = first.shape[0]
    size = 1 << (2 * n - 1).bit_length()
    spectra: NDArray[np.complex128] | float = 0.0
    for k in markers:
        f0 = np.conj(np.fft.rfft(_products(first[:, k], first_known), size, axis=0))
        f1 = np.fft.rfft(_products(second[:, k], second_known), size, axis=0)
        spectra = spectra + f0[:, :, None] * f1[:, None, :]  # [frequency, cd, ab]
    sums = _lagged(np.asarray(spectra), n, size)
    count = np.round(
        _lagged(
            np.conj(np.fft.rfft(first_known.astype(np.float64), size))
            * np.fft.rfft(second_known.astype(np.float64), size),
            n,
            size,
        )
    )
    # [(a, c), (b, d)] = sums[cd, ab]
    design = sums[:, _SYMMETRIC[:, None, :, None], _SYMMETRIC[None, :, None, :]]  # [L, c, a, d, b]
    design = design.transpose(0, 2, 1, 4, 3).reshape(-1, 9, 9)
    smallest = np.asarray(np.linalg.eigvalsh(design)[:, 0], dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(count > 0, np.maximum(smallest, 0.0) / count, np.inf), count


#: Correspondences the direct score of one lag uses at most (spread over the views).
DIRECT_VIEWS = 2000


def _essential_fit(first: FloatArray, second: FloatArray) -> tuple[float, FloatArray]:
    """The linear essential matrix of (n, 3) corresponding bearings: its mean squared residual and the matrix."""
    a = (second[:, :, None] * first[:, None, :]).reshape(-1, 9)
    a = a[np.all(np.isfinite(a), axis=1)]
    if a.shape[0] < 9:
        return np.inf, np.zeros((3, 3))
    values, vectors = np.linalg.eigh(a.T @ a)
    return float(max(values[0], 0.0) / a.shape[0]), vectors[:, 0].reshape(3, 3)


def _direct_score(first: FloatArray, second: FloatArray) -> float:
    """The linear essential matrix's mean squared residual of (n, K, 3) corresponding bearings, each view of the
    second camera taken with its wand's labels as they are or reversed (A and C exchanged), whichever the
    essential matrix of the reversal-invariant markers fits better: a detector's labels may be exchanged on a
    stretch of one camera's views until the cameras are compared."""
    if first.shape[0] > DIRECT_VIEWS:
        spread = np.linspace(0, first.shape[0] - 1, DIRECT_VIEWS).astype(np.int64)
        first, second = first[spread], second[spread]
    markers = first.shape[1]
    middle = _invariant(markers)
    _, essential = _essential_fit(first[:, middle].reshape(-1, 3), second[:, middle].reshape(-1, 3))
    reversed_second = second[:, ::-1]
    as_is = np.nansum(np.einsum("nki,ij,nkj->nk", second, essential, first) ** 2, axis=1)
    swapped = np.nansum(np.einsum("nki,ij,nkj->nk", reversed_second, essential, first) ** 2, axis=1)
    chosen = np.where((swapped < as_is)[:, None, None], reversed_second, second)
    return _essential_fit(first.reshape(-1, 3), chosen.reshape(-1, 3))[0]


def _invariant(markers: int) -> NDArray[np.int64]:
    """The markers a reversal of the wand's labels leaves in place: the middle one of an odd number (every marker
    of an even number: none is)."""
    return np.array([markers // 2]) if markers % 2 else np.arange(markers)


def score_at(tracks: tuple[Track, Track], models: tuple[CameraModel, CameraModel], lag: float) -> tuple[float, int]:
    """How well the lag ``lag`` lines up two cameras: the first camera's own views against the second's track at
    their times plus the lag; the linear essential matrix's mean squared residual (:func:`_direct_score`), and
    how many pairs of views."""
    points, known = tracks[1].at(tracks[0].times + lag)
    pairs = int(known.sum())
    if pairs < 9:
        return np.inf, pairs
    return _direct_score(unproject(models[0], tracks[0].points[known]), unproject(models[1], points[known])), pairs


@dataclass(frozen=True)
class PairOffset:
    """The lag between two cameras' clocks found from their views.

    Attributes:
        first, second: the cameras' indices.
        offset: the second camera's clock offset minus the first's, in the unit (its views at t + offset show
            what the first camera's show at t).
        overlap: the pairs of views scored at that lag.
        distinct: how many times worse the best lag at least DISTINCT_FRAMES periods away fits.
        at_zero: how many times worse lag zero fits (inf: too little overlap there).
        rival: that other lag.
        zero_overlap: the pairs of views scored at lag zero (the frames as they are).
        period: the slower camera's frame period in the unit.
        apart: one of the cameras is known to keep another clock (a live camera whose stamps stand seconds from
            the others' as they arrive): a decided lag more than SHIFT_FRAMES frames from zero is taken as it is.
    """

    first: int
    second: int
    offset: float
    overlap: int
    distinct: float
    at_zero: float
    rival: float
    zero_overlap: int
    period: float
    apart: bool = False

    @property
    def decided(self) -> bool:
        """Whether the best lag fits clearly better than any other."""
        return self.distinct >= DISTINCT

    @property
    def lined_up(self) -> bool:
        """Whether the views line up as they are: the decided lag is within SHIFT_FRAMES frames of zero."""
        return self.decided and abs(self.offset) <= SHIFT_FRAMES * self.period

    @property
    def off(self) -> bool:
        """Whether the views clearly do not line up as they are (lag zero scored, and fitting far worse; or one
        camera known to keep another clock, and the decided lag away from zero)."""
        if self.apart and self.decided and abs(self.offset) > SHIFT_FRAMES * self.period:
            return True
        return self.zero_overlap >= MIN_OVERLAP_FRAMES and self.at_zero >= MISALIGNED


#: The coarse scan's grid has at most this many steps (a long take is scanned at a few frames a step, then
#: refined frame by frame).
MAX_GRID = 4096


def pair_offset(
    tracks: tuple[Track, Track], models: tuple[CameraModel, CameraModel], frames: bool, cameras: tuple[int, int]
) -> PairOffset | None:
    """The lag between two cameras' clocks (None: their views overlap too little at every lag).

    Both tracks go onto one grid at the slower camera's period (a whole number of them on a long take; frame
    by frame with frame ids) and are scored at every lag (:func:`lag_scores`) twice: on every marker, and on
    the markers a reversal of the wand's labels leaves in place (a detector's A and C may still be exchanged on
    some views). The best CANDIDATES lags of each scan are scored again on the first camera's own views against
    the second's track, labels exchanged where that fits (:func:`score_at`); the best is refined to a frame,
    then (seconds) between frames, a parabola through the scores of REFINE_STEPS steps a frame.
    """
    period = max(tracks[0].period, tracks[1].period)
    start = min(tracks[0].times[0], tracks[1].times[0])
    span = max(tracks[0].times[-1], tracks[1].times[-1]) - start
    step = period * max(1, int(np.ceil(span / period / MAX_GRID)))
    grid = start + step * np.arange(int(np.floor(span / step)) + 1)
    on_grid = [track.at(grid) for track in tracks]
    bearings = [unproject(model, points) for model, (points, _) in zip(models, on_grid, strict=True)]
    markers = bearings[0].shape[1]
    shorter = min(tracks[0].times.size * tracks[0].period, tracks[1].times.size * tracks[1].period)
    enough = max(MIN_OVERLAP_FRAMES * period, MIN_OVERLAP * shorter) / step
    lags = np.arange(-(grid.size - 1), grid.size) * step
    candidates: list[float] = []
    for scanned in {tuple(range(markers)), tuple(_invariant(markers))}:
        scores, count = lag_scores(bearings[0], on_grid[0][1], bearings[1], on_grid[1][1], np.array(scanned))
        candidates += _minima(lags, np.where(count >= enough, scores, np.inf), DISTINCT_FRAMES * period)
    if not candidates:
        return None
    coarse = [_refined(tracks, models, lag, step, period, True) for lag in candidates]
    fits = [score_at(tracks, models, lag)[0] for lag in coarse]
    best = int(np.argmin(fits))
    offset = _refined(tracks, models, coarse[best], period, period, frames)
    fit, overlap = score_at(tracks, models, offset)
    apart = [f for lag, f in zip(coarse, fits, strict=True) if abs(lag - coarse[best]) >= DISTINCT_FRAMES * period]
    rivals = [lag for lag in coarse if abs(lag - coarse[best]) >= DISTINCT_FRAMES * period]
    zero_fit, zero_overlap = score_at(tracks, models, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        distinct = float(min(apart) / fit) if apart else np.inf
        at_zero = float(zero_fit / fit)
    rival = rivals[int(np.argmin(apart))] if apart else offset
    return PairOffset(*cameras, offset, overlap, distinct, at_zero, float(rival), zero_overlap, period)


def _minima(lags: FloatArray, scores: FloatArray, apart: float) -> list[float]:
    """The lags of the CANDIDATES lowest finite scores at least ``apart`` from each other."""
    found: list[float] = []
    for index in np.argsort(scores):
        if not np.isfinite(scores[index]) or len(found) == CANDIDATES:
            break
        if all(abs(lags[index] - lag) >= apart for lag in found):
            found.append(float(lags[index]))
    return found


def _refined(
    tracks: tuple[Track, Track],
    models: tuple[CameraModel, CameraModel],
    offset: float,
    step: float,
    period: float,
    frames: bool,
) -> float:
    """``offset`` refined within a grid ``step`` of it: frame by frame, then (``frames`` false) between frames."""
    if step > period:
        lags = offset + period * np.arange(-round(step / period), round(step / period) + 1)
        offset = float(lags[int(np.argmin([score_at(tracks, models, lag)[0] for lag in lags]))])
    if frames:
        return offset
    lags = offset + period / REFINE_STEPS * np.arange(-REFINE_STEPS, REFINE_STEPS + 1)
    logs = np.log(np.maximum([score_at(tracks, models, lag)[0] for lag in lags], 1e-300))
    best = int(np.argmin(logs))
    if not 0 < best < lags.size - 1 or not np.all(np.isfinite(logs[best - 1 : best + 2])):
        return float(lags[best])
    y0, y1, y2 = logs[best - 1 : best + 2]
    curvature = y0 - 2.0 * y1 + y2
    shift = 0.5 * (y0 - y2) / curvature if curvature > 0 else 0.0
    return float(lags[best] + shift * period / REFINE_STEPS)


@dataclass(frozen=True)
class ClockAlignment:
    """The cameras' clocks as the wand's motion lines them up.

    Attributes:
        offsets: (C,) each camera's clock offset against the anchor's (exposure = stamp - offset), in the
            observations' unit; zero for the cameras left as they were.
        moved: (C,) the cameras whose stamps (or frame ids) were moved by their offset.
        unit: "s" or "frames".
        lines: what was found, in words (one line per moved camera).
        unchecked: the cameras whose clocks the wand's motion could not check, and why, in words (said only should
            the calibration fail).
    """

    offsets: FloatArray
    moved: NDArray[np.bool_]
    unit: str
    lines: tuple[str, ...] = ()
    unchecked: tuple[str, ...] = ()

    def relative_to(self, reference: int) -> FloatArray:
        """(C,) the moved cameras' offsets against the ``reference`` camera's (zero for the others)."""
        moved = np.where(self.moved, self.offsets, 0.0)
        return moved - moved[reference]


def _models(rig: RigSpec) -> tuple[CameraModel, ...]:
    """The cameras' nominal lenses (the data sheet's), or their given intrinsics."""
    return tuple(spec.intrinsics if spec.intrinsics is not None else nominal_model(spec) for spec in rig.cameras)


def _describe(offset: float, unit: str) -> str:
    """An offset in words: "2.300 s ahead of", "69 frames behind"."""
    amount = f"{abs(offset):.3f} s" if unit == "s" else f"{abs(offset):.0f} frames"
    return f"{amount} {'ahead of' if offset > 0 else 'behind'}"


def align_clocks(
    rig: RigSpec, observations: WandObservations, found: ClockAlignment | None = None
) -> tuple[WandObservations, ClockAlignment]:
    """The observations with every camera's clock lined up on the others' from the wand's motion, and the
    offsets found (:func:`find_clock_offsets`; ``found``: as already found from the same views). Observations
    whose clocks agree within SHIFT_FRAMES frames are returned as they are.

    Raises:
        TimingError: as :func:`find_clock_offsets`.
    """
    frames = observations.stamps is None
    if found is None or found.unit != ("frames" if frames else "s"):
        found = find_clock_offsets(rig, camera_tracks(observations), frames)
    if not found.moved.any():
        return observations, found
    return shifted(observations, np.where(found.moved, found.offsets, 0.0)), found


def find_clock_offsets(
    rig: RigSpec, tracks: tuple[Track, ...], frames: bool, apart: frozenset[int] = frozenset()
) -> ClockAlignment:
    """Each camera's clock offset from the wand's motion, where the cameras' views do not line up as they are
    (see the module docstring).

    Args:
        rig: the rig (its cameras' nominal lenses).
        tracks: each camera's track (:func:`camera_tracks`), in rig order.
        frames: the tracks' times are frame ids (else seconds).
        apart: cameras known to keep clocks of their own (their stamps against their arrival, live).

    Raises:
        TimingError: a camera whose views do not line up with another's as they are, and whose offset the
            wand's motion cannot decide (a motion so regular that two offsets fit alike), naming it and what to do.
    """
    unit = "frames" if frames else "s"
    names = rig.camera_names
    usable = [c for c, track in enumerate(tracks) if track.times.size >= MIN_OVERLAP_FRAMES and _continuous(track)]
    short = tuple(
        f"{names[c]}: its views of the whole wand span {_span(track, unit)}, too few to line its clock up from the "
        f"wand's motion (at least {MIN_OVERLAP_FRAMES} frames): if its clock is not the others', wave longer"
        for c, track in enumerate(tracks)
        if 1 < track.times.size < MIN_OVERLAP_FRAMES
    )
    nothing = ClockAlignment(np.zeros(len(names)), np.zeros(len(names), dtype=bool), unit, (), short)
    if rig.wand.n_points < 3 or len(usable) < 2:  # (a two-marker wand's labels may differ between cameras)
        return nothing
    models = _models(rig)
    scanned = _pairs_to_scan(tracks, models, usable)
    pairs = [
        found
        for i, j in scanned
        if (found := pair_offset((tracks[i], tracks[j]), (models[i], models[j]), frames, (i, j))) is not None
    ]
    pairs = [replace(p, apart=bool({p.first, p.second} & apart)) for p in pairs]
    alone = {c for pair in scanned for c in pair} - {c for p in pairs for c in (p.first, p.second)}
    nothing = replace(nothing, unchecked=short + tuple(
        f"{names[c]}: no other camera saw the wand at the same time for {MIN_OVERLAP_FRAMES} frames at any offset of "
        "the clocks: wave it where this camera and another see it, for a few seconds"
        for c in sorted(alone)
    ))  # fmt: skip
    if not any(p.off and p.decided for p in pairs):  # (the views line up as they are, or nothing says otherwise)
        _check_undecided(names, pairs, set(), unit)
        return nothing
    period = max(tracks[c].period for c in usable)
    offsets, reached = _offsets(pairs, max(usable, key=lambda c: tracks[c].times.size), len(names))
    anchor = _anchor(offsets, reached, SHIFT_FRAMES * period)
    offsets = np.where(reached, offsets - offsets[anchor], 0.0)
    moved = reached & (np.abs(offsets) > SHIFT_FRAMES * period)
    _check_undecided(names, pairs, {int(c) for c in np.flatnonzero(reached)}, unit)
    lines = tuple(
        f"{names[c]}'s clock is {_describe(offsets[c], unit)} {names[anchor]}'s, found from the wand's motion"
        for c in np.flatnonzero(moved)
    )
    return ClockAlignment(offsets, moved, unit, lines, nothing.unchecked)


def _span(track: Track, unit: str) -> str:
    """How long a track lasts, in words."""
    span = float(track.times[-1] - track.times[0]) if track.times.size else 0.0
    return f"{span:.1f} s" if unit == "s" else f"{span:.0f} frames"


def _offsets(pairs: list[PairOffset], anchor: int, n_cameras: int) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(C,) each camera's offset against ``anchor`` and (C,) which cameras that reached, through the pairs whose
    views line up as they are (offset zero) and those clearly off whose lag is decided, the clearest first (a
    maximum spanning tree grown from the anchor)."""
    offsets, reached = np.zeros(n_cameras), np.zeros(n_cameras, dtype=bool)
    reached[anchor] = True
    edges = [(p.first, p.second, 0.0, p.distinct) for p in pairs if p.lined_up]
    edges += [(p.first, p.second, p.offset, p.distinct) for p in pairs if p.off and p.decided]
    edges.sort(key=lambda edge: -edge[3])
    grown = True
    while grown:
        grown = False
        for first, second, offset, _ in edges:
            if reached[first] != reached[second]:
                if reached[first]:
                    offsets[second], reached[second] = offsets[first] + offset, True
                else:
                    offsets[first], reached[first] = offsets[second] - offset, True
                grown = True
                break
    return offsets, reached


def _continuous(track: Track) -> bool:
    """Whether a camera's track is a continuous motion: its views' centre moves between consecutive images by less
    than CONTINUOUS_STEP of how far it spreads (independent placements jump across the whole spread)."""
    centre = track.points.mean(axis=1)
    consecutive = np.diff(track.times) <= MAX_GAP_FRAMES * track.period
    if np.count_nonzero(consecutive) < MIN_OVERLAP_FRAMES // 2:
        return False
    steps = np.linalg.norm(np.diff(centre, axis=0), axis=1)[consecutive]
    spread = np.linalg.norm(centre - np.median(centre, axis=0), axis=1)
    return bool(np.median(steps) < CONTINUOUS_STEP * np.median(spread))


def _pairs_to_scan(
    tracks: tuple[Track, ...], models: tuple[CameraModel, ...], usable: list[int]
) -> list[tuple[int, int]]:
    """The camera pairs whose lags are scanned: none where the cameras' views line up as they are (every camera
    joined to the others through pairs that do, :func:`_lined_up_as_they_are`, tried longest tracks first, until
    they are); else the pairs between the groups that do, all of them for up to ALL_PAIRS cameras, at most
    CROSS_PAIRS of each two groups (those with the longest tracks) for more."""
    group = {c: c for c in usable}  # union-find of the cameras lined up as they are

    def root(c: int) -> int:
        while group[c] != c:
            c = group[c]
        return c

    by_length = sorted(usable, key=lambda c: -tracks[c].times.size)
    candidates = sorted(((i, j) for a, i in enumerate(by_length) for j in by_length[a + 1 :]),
                        key=lambda pair: -min(tracks[pair[0]].times.size, tracks[pair[1]].times.size))  # fmt: skip
    for i, j in candidates:
        if len({root(c) for c in usable}) == 1:
            return []
        if root(i) != root(j) and _lined_up_as_they_are((tracks[i], tracks[j]), (models[i], models[j])):
            group[root(i)] = root(j)
    members: dict[int, list[int]] = {}
    for c in by_length:
        members.setdefault(root(c), []).append(c)
    groups = list(members.values())
    if len(groups) == 1:
        return []
    limit = None if len(usable) <= ALL_PAIRS else CROSS_PAIRS
    return [
        (min(i, j), max(i, j))
        for a, first in enumerate(groups)
        for second in groups[a + 1 :]
        for i, j in [(i, j) for i in first for j in second][:limit]
    ]


#: Lags (frame periods) of the check that views line up as they are: near zero, and clearly away from it.
NEAR_FRAMES = np.arange(-2, 3)
FAR_FRAMES = np.array([-120, -60, -30, -15, 15, 30, 60, 120])
#: Views that check uses at most (spread over the track).
CHECK_VIEWS = 300


def _lined_up_as_they_are(tracks: tuple[Track, Track], models: tuple[CameraModel, CameraModel]) -> bool:
    """Whether two cameras' views line up as their clocks pair them: the best fit within two frames of lag zero,
    scored on enough views, is DISTINCT times better than at any of a few lags half a second to four seconds away
    (a few direct scores on CHECK_VIEWS views, instead of a scan of every lag)."""
    first = tracks[0]
    if first.times.size > CHECK_VIEWS:
        spread = np.linspace(0, first.times.size - 1, CHECK_VIEWS).astype(np.int64)
        first = Track(first.times[spread], first.points[spread], first.period)
    pair = (first, tracks[1])
    period = max(tracks[0].period, tracks[1].period)
    near = [score_at(pair, models, float(lag * period)) for lag in NEAR_FRAMES]
    best, count = min(near)
    if count < MIN_OVERLAP_FRAMES * first.times.size / max(tracks[0].times.size, 1) or not np.isfinite(best):
        return False
    far = [score for score, overlap in (score_at(pair, models, float(lag * period)) for lag in FAR_FRAMES)
           if overlap >= count // 2]  # fmt: skip
    return bool(far) and min(far) >= DISTINCT * best


def _anchor(offsets: FloatArray, reached: NDArray[np.bool_], within: float) -> int:
    """The camera the others are moved onto: the first of the largest group whose clocks agree ``within``."""
    cameras = np.flatnonzero(reached)
    agreeing = [int(np.count_nonzero(np.abs(offsets[cameras] - offsets[c]) <= within)) for c in cameras]
    return int(cameras[int(np.argmax(agreeing))])


def _check_undecided(names: tuple[str, ...], pairs: list[PairOffset], placed: set[int], unit: str) -> None:
    """Raise for a camera not ``placed`` whose views clearly do not line up with another's as they are, but whose
    offset the wand's motion cannot decide (it fits two lags alike), unless they line up with a third camera's."""
    lined = {c for p in pairs if p.lined_up for c in (p.first, p.second)}
    for pair in pairs:
        if not pair.off or pair.decided or {pair.first, pair.second} <= placed or {pair.first, pair.second} <= lined:
            continue
        first, second = names[pair.first], names[pair.second]
        raise TimingError(
            f"cameras '{second}' and '{first}': their views do not line up in time as their "
            f"{'stamps' if unit == 's' else 'frame ids'} pair them, and the wand's motion fits two clock offsets "
            f"alike ({pair.offset:+.3f} and {pair.rival:+.3f} {unit}): a motion so regular repeats itself; wave the "
            "wand less evenly (changing speed and direction) where both cameras see it, or synchronise their clocks"
        )


def shifted(observations: WandObservations, offsets: FloatArray) -> WandObservations:
    """The observations with each camera's views moved by its offset (stamps or frame ids minus it) and the
    frames formed again: with stamps, each moved view joins the frame nearest its new stamp (within half the
    rig's frame period, one view per camera) or starts one; with frame ids, whole frames."""
    moved = np.flatnonzero(offsets != 0)
    if moved.size == 0:
        return observations
    if observations.stamps is None:
        return _shifted_ids(observations, np.round(offsets).astype(np.int64))
    return _shifted_stamps(observations, offsets)


def _shifted_ids(observations: WandObservations, offsets: IntArray) -> WandObservations:
    """Frame ids moved per camera by whole frames, views regrouped by their new ids."""
    ids = observations.frames[:, None] - offsets[None, :]  # (F, C) each view's new frame id
    seen = np.any(np.isfinite(observations.uv), axis=(2, 3))
    frames = np.unique(ids[seen])
    row = np.searchsorted(frames, ids)
    uv = np.full((frames.size, *observations.uv.shape[1:]), np.nan)
    frame_index, camera = np.nonzero(seen)
    uv[row[frame_index, camera], camera] = observations.uv[frame_index, camera]
    saturated = _placed(observations.saturated, uv.shape[:3], row[frame_index, camera], frame_index, camera, False)
    brightness = _placed(observations.brightness, uv.shape[:3], row[frame_index, camera], frame_index, camera, np.nan)
    return WandObservations(frames.astype(np.int64), observations.camera_names, uv, None, saturated, brightness)


def _placed(
    values: NDArray[Any] | None,
    shape: tuple[int, ...],
    rows: IntArray,
    frame_index: IntArray,
    camera: IntArray,
    fill: Any,
) -> NDArray[Any] | None:
    """(F', C, K) the views' per-point ``values`` (F, C, K) at their new ``rows`` (``fill`` elsewhere; None: none)."""
    if values is None:
        return None
    out = np.full(shape, fill, dtype=values.dtype)
    out[rows, camera] = values[frame_index, camera]
    return out


def _shifted_stamps(observations: WandObservations, offsets: FloatArray) -> WandObservations:
    """Stamps moved per camera, the moved cameras' views joined to the nearest frames of the others."""
    assert observations.stamps is not None
    stamps = observations.stamps - offsets[None, :]
    seen = np.isfinite(stamps) & np.any(np.isfinite(observations.uv), axis=(2, 3))
    periods = [frame_period(stamps[seen[:, c], c]) for c in range(stamps.shape[1])]
    tolerance = 0.5 * float(np.nanmax(periods)) if np.any(np.isfinite(periods)) else 0.0
    kept = offsets == 0
    members = seen[:, kept].sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        times = np.where(seen[:, kept], stamps[:, kept], 0.0).sum(axis=1) / members  # (NaN: no kept view)
    slot = np.full(stamps.shape, -1, dtype=np.int64)  # each view's new frame (an index into ``times``)
    slot[:, kept] = np.where(seen[:, kept], np.arange(stamps.shape[0])[:, None], -1)
    for c in np.flatnonzero(~kept):
        views = np.flatnonzero(seen[:, c])
        joined = _nearest_frames(times, stamps[views, c], tolerance)
        alone = joined < 0
        joined[alone] = times.size + np.arange(int(alone.sum()))
        times = np.concatenate([times, stamps[views[alone], c]])
        slot[views, c] = joined
    return _regrouped(observations, stamps, seen, slot, times)


def _nearest_frames(times: FloatArray, stamps: FloatArray, tolerance: float) -> IntArray:
    """(V,) the frame (index into ``times``, NaN for none) each of one camera's (V,) stamps joins: the nearest
    within ``tolerance``, one view per frame (the nearest of those that would share one); -1: none."""
    known = np.flatnonzero(np.isfinite(times))
    if known.size == 0:
        return np.full(stamps.size, -1, dtype=np.int64)
    order = known[np.argsort(times[known], kind="stable")]
    sorted_times = times[order]
    after = np.searchsorted(sorted_times, stamps).clip(1, max(sorted_times.size - 1, 1))
    before = after - 1
    if sorted_times.size == 1:
        after = before = np.zeros(stamps.size, dtype=np.int64)
    nearer = np.where(np.abs(sorted_times[after] - stamps) < np.abs(sorted_times[before] - stamps), after, before)
    gaps = np.abs(sorted_times[nearer] - stamps)
    frame = np.where(gaps <= tolerance, order[nearer], -1)
    by_gap = np.lexsort((gaps, frame))  # per frame, its nearest view first
    first = np.ones(frame.size, dtype=bool)
    first[by_gap[1:]] = frame[by_gap[1:]] != frame[by_gap[:-1]]
    frame[by_gap[~first]] = -1
    return frame.astype(np.int64)


def _regrouped(
    observations: WandObservations, stamps: FloatArray, seen: NDArray[np.bool_], slot: IntArray, times: FloatArray
) -> WandObservations:
    """The views placed in their new frames (``slot`` (F, C): -1 for none), frames in time order, ids counted."""
    order = np.argsort(times, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    uv = np.full((times.size, *observations.uv.shape[1:]), np.nan)
    new_stamps = np.full((times.size, stamps.shape[1]), np.nan)
    frame_index, camera = np.nonzero(seen & (slot >= 0))
    rows = rank[slot[frame_index, camera]]
    uv[rows, camera] = observations.uv[frame_index, camera]
    new_stamps[rows, camera] = stamps[frame_index, camera]
    saturated = _placed(observations.saturated, uv.shape[:3], rows, frame_index, camera, False)
    brightness = _placed(observations.brightness, uv.shape[:3], rows, frame_index, camera, np.nan)
    keep = np.any(np.isfinite(uv), axis=(1, 2, 3))
    return replace(
        observations,
        frames=np.arange(int(keep.sum()), dtype=np.int64),
        uv=uv[keep],
        stamps=new_stamps[keep],
        saturated=None if saturated is None else saturated[keep],
        brightness=None if brightness is None else brightness[keep],
    )
