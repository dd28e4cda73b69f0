"""Timing of free-running cameras: when each view was seen, and how the wand moved meanwhile.

Cameras that are not hardware-triggered expose at their own phase, and their drivers
stamp images with a latency of their own. The contract is **exposure = stamp -
time_offset** (+ readout x v / H for a rolling shutter, v the row of the point and H
the image height), offsets relative to the reference camera. Observations carry either
stamps (seconds) or only frame ids, which are then consecutive frames of one recording
at a constant rate (time unit: frames).

The wand is a smooth trajectory through the placements: each placement's points are
known at the placement's time, and a local polynomial fit over its neighbours in time
gives their velocity, acceleration and jerk, with which the bundle adjustment carries the
points to each camera's own instant (see :mod:`wand_calib_ros.core.adjust.bundle_adjustment`).
Whether offsets and readout times are estimated is decided like the distortion model's
order: by significance tests on a fit that estimates them (``auto``), or by the user
(``estimate``, ``fixed``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, CameraSystem
from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS, READOUT, TIME_OFFSET, TIMING, PlacementTiming
from wand_calib_ros.core.adjust.chi_square import chi_square_quantile
from wand_calib_ros.core.errors import TimingError
from wand_calib_ros.core.model.result import TIMING_MODES, CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: Neighbours on each side of a placement that its motion is fitted to, and the local polynomial's degree.
MOTION_NEIGHBOURS = 5
MOTION_DEGREE = 3
#: The (neighbours, degree) windows :func:`smooth_motion` chooses from: narrow ones follow a fast wave,
#: wide ones average the noise of a slow one.
MOTION_WINDOWS = ((3, 3), (4, 3), (5, 3), (4, 4), (5, 4), (6, 4), (8, 4))
#: A window is chosen on this many stretches of that many consecutive placements (when longer).
WINDOW_CHOICE_BLOCKS = (20, 100)
#: The window of the one-sided fits at the ends of stretches.
END_WINDOW = (4, 2)
#: A recording is a continuous motion when the local fits leave less than this fraction of the points'
#: spread within each fit (independent placements leave about all of it).
CONTINUITY_FRACTION = 0.3
#: A sample of a recording's placements whose fits leave more than this multiple of CONTINUITY_FRACTION of the
#: spread shows that the recording is no continuous motion (:func:`clearly_independent`).
CLEARLY_INDEPENDENT = 2.0
#: frame_period: a period is at least this fraction of the spacings' lower quartile (most images lost), ...
MAX_MULTIPLE = 5
#: ... this fraction of the spacings (at least two) are single periods, ...
SINGLE_SUPPORT = 0.05
#: ... and each spacing up to the quartile is a whole number n of periods within this fraction of n periods.
MULTIPLE_TOLERANCE = 0.1
#: ``auto`` keeps the time offsets (the readout times) when they differ from zero at this level
#: (chi-square test over the cameras).
SIGNIFICANCE_LEVEL = 0.99
#: Tentative timing parameters whose linearised statistics stay below this fraction of their quantiles are left
#: out without adjusting them (:func:`clearly_synchronised`).
CLEARLY_SYNCHRONISED = 0.5
#: Frame periods (seconds) outside this range mean stamps in another unit.
PERIOD_RANGE_S = (1e-4, 10.0)
#: A camera's frame period that changes by more than this fraction within a recording is reported.
RATE_DRIFT = 0.02


@dataclass(frozen=True, eq=False)
class Timeline:
    """When each view of a recording was captured.

    Attributes:
        unit: "s" (the observations carry stamps) or "frames" (frame ids only).
        placement_times: (F,) each frame's time: the mean stamp of its views minus ``origin`` (s),
            or its frame id (frames).
        view_times: (F, C) each view's stamp minus its frame's time (0 without stamps and where unseen).
        periods: (C,) each camera's frame period in the unit (NaN: too few images to tell).
        origin: the stamp subtracted from every time, s (0 for frames).
    """

    unit: str
    placement_times: FloatArray
    view_times: FloatArray
    periods: FloatArray
    origin: float = 0.0

    @property
    def period(self) -> float:
        """The spacing of consecutive placements (median), in the unit: the time scale of the motion fits,
        longer than a frame where frames were lost or showed no wand."""
        steps = np.diff(np.sort(self.placement_times))
        steps = steps[steps > 0]
        return float(np.median(steps)) if steps.size else 1.0

    @property
    def frame_period(self) -> float:
        """The rig's frame period in the unit: the slowest camera's (frames come at the anchor's rate),
        or :attr:`period` where no camera's is known."""
        return float(np.nanmax(self.periods)) if np.any(np.isfinite(self.periods)) else self.period

    @property
    def simultaneous(self) -> bool:
        """Whether every frame's views were captured at one instant (as far as the stamps tell)."""
        return not np.any(self.view_times)

    def subset(self, index: NDArray[np.int64] | NDArray[np.bool_]) -> Timeline:
        """The timeline of some frames (an index or mask over axis 0)."""
        return Timeline(self.unit, self.placement_times[index], self.view_times[index], self.periods, self.origin)


def timeline(observations: WandObservations) -> Timeline:
    """The timeline of a recording: from its stamps, or from its frame ids (consecutive frames).

    Raises:
        TimingError: stamps that cannot be seconds (a frame period outside 0.1 ms .. 10 s), naming the camera.
    """
    n_frames, n_cameras = observations.uv.shape[:2]
    if observations.stamps is None:
        return Timeline(
            "frames", observations.frames.astype(np.float64), np.zeros((n_frames, n_cameras)), np.ones(n_cameras)
        )
    stamps = observations.stamps
    seen = np.isfinite(stamps)
    origin = float(np.nanmin(stamps)) if seen.any() else 0.0
    relative = stamps - origin
    with np.errstate(invalid="ignore"):
        times = np.where(seen.any(axis=1), np.nanmean(np.where(seen, relative, np.nan), axis=1), 0.0)
    view_times = np.where(seen, relative - times[:, None], 0.0)
    periods = np.array([frame_period(stamps[seen[:, c], c]) for c in range(n_cameras)])
    low, high = PERIOD_RANGE_S
    for name, period in zip(observations.camera_names, periods, strict=True):
        if np.isfinite(period) and not low <= period <= high:
            raise TimingError(
                f"camera '{name}': its images are {period:.6g} apart, which cannot be seconds; stamps must be in "
                "seconds (not milliseconds or nanoseconds)"
            )
    return Timeline("s", times, view_times, periods, origin)


def frame_period(stamps: FloatArray) -> float:
    """A camera's frame period from its stamps (any unit; NaN with fewer than three).

    Images that were dropped or show no wand make some spacings of consecutive stamps two or
    more periods long, bursts of a driver a few much shorter. The period is the shortest
    spacing from a MAX_MULTIPLE-th of their lower quartile on, refined as the median of every
    spacing divided by the whole number of it that spacing is, when each spacing up to the
    quartile is such a whole number and SINGLE_SUPPORT of them (at least two) are one; else the
    lower quartile itself.
    """
    steps = np.diff(np.sort(np.asarray(stamps, dtype=np.float64)))
    steps = steps[steps > 0]
    if steps.size < 2:
        return float("nan")
    quartile = float(np.percentile(steps, 25))
    shortest = float(np.min(steps[steps >= quartile / MAX_MULTIPLE]))
    multiples = np.round(steps / shortest)
    whole = (multiples >= 1) & (np.abs(steps - multiples * shortest) < MULTIPLE_TOLERANCE * multiples * shortest)
    explained = np.all(whole[(steps >= shortest) & (steps <= quartile)])
    singles = np.count_nonzero(whole & (multiples == 1))
    if explained and singles >= max(2, SINGLE_SUPPORT * steps.size):
        return float(np.median(steps[whole] / multiples[whole]))
    return quartile


def rate_warnings(observations: WandObservations, line: Timeline) -> list[str]:
    """Cameras whose frame period changes within the recording (auto exposure lowering the rate, a
    clock that drifts): their stamps are used as they are, but their time offset may change too."""
    if observations.stamps is None:
        return []
    out = []
    for c, name in enumerate(observations.camera_names):
        stamps = np.sort(observations.stamps[:, c][np.isfinite(observations.stamps[:, c])])
        half = stamps.size // 2
        first, second = frame_period(stamps[: half + 1]), frame_period(stamps[half:])
        if np.isfinite(first) and np.isfinite(second) and abs(second / first - 1) > RATE_DRIFT:
            out.append(
                f"{name}: its frame period changed from {1000 * first:.2f} ms to {1000 * second:.2f} ms during the "
                "recording (auto exposure? a clock that drifts?); its time offset is assumed constant"
            )
    return out


@dataclass(frozen=True, eq=False)
class Motion:
    """Velocity, acceleration and jerk of the wand's points at each placement's time.

    Attributes:
        velocity: (P, 3, 3) of A, B, C, reference frame, mm per time unit (0 where unknown).
        acceleration: (P, 3, 3) mm per time unit squared (0 where unknown).
        jerk: (P, 3, 3) mm per time unit cubed (0 where unknown or not fitted).
        known: (P,) True where neighbours on both sides determined the motion.
        residual: (P,) RMS (mm) of the placement's points about its neighbours' fit (NaN where unknown).
        spread: (P,) RMS (mm) of the fitted points about their mean (NaN where unknown).
        window: (neighbours on each side, polynomial degree) of the fits.
    """

    velocity: FloatArray
    acceleration: FloatArray
    jerk: FloatArray
    known: NDArray[np.bool_]
    residual: FloatArray
    spread: FloatArray
    window: tuple[int, int] = (MOTION_NEIGHBOURS, MOTION_DEGREE)

    @property
    def continuous(self) -> bool:
        """Whether the placements follow one smooth path (the fits explain the points' spread)."""
        fitted = self.known & np.isfinite(self.residual) & np.isfinite(self.spread)
        if np.count_nonzero(fitted) < max(10, self.known.size // 2):
            return False
        return bool(np.median(self.residual[fitted]) < CONTINUITY_FRACTION * np.median(self.spread[fitted]))


def fit_motion(
    times: FloatArray,
    points: FloatArray,
    period: float,
    *,
    neighbours: int = MOTION_NEIGHBOURS,
    degree: int = MOTION_DEGREE,
    one_sided: bool = False,
) -> Motion:
    """Velocity, acceleration and jerk of every placement from a local polynomial fit over its neighbours.

    Args:
        times: (P,) placement times, in the time unit (any order).
        points: (P, ...) what moves, e.g. (P, 3, 3) A, B, C in mm or (P, 3, 2) pixels (NaN where unknown).
        period: frame period in the time unit (1 for frame ids).
        neighbours: placements on each side (in time) in each fit, the placement itself left out (its
            noise must not reach the motion that carries its own views); those more than
            ``neighbours + 1.5`` periods away are left out too (a gap in the recording).
        degree: polynomial degree (2 or 3; the jerk is zero below 3).
        one_sided: also fit placements with neighbours on one side only (extrapolating).

    Returns:
        The motion per placement, in the input order (derivatives shaped like ``points``).
    """
    points = np.asarray(points, dtype=np.float64)
    n, shape = times.shape[0], points.shape[1:]
    order = np.argsort(times, kind="stable")
    t = np.asarray(times, dtype=np.float64)[order] / period  # in frames: a well-conditioned design
    values = points[order].reshape(n, -1)
    finite = np.all(np.isfinite(values), axis=1)
    offsets = np.arange(-neighbours, neighbours + 1)
    index = np.arange(n)[:, None] + offsets[None, :]  # (P, W)
    inside = (index >= 0) & (index < n)
    index = np.clip(index, 0, n - 1)
    dt = t[index] - t[:, None]
    use = inside & (offsets != 0)[None, :] & finite[index] & finite[:, None] & (np.abs(dt) <= neighbours + 1.5)
    weight = use.astype(np.float64)
    design = np.empty((*dt.shape, degree + 1))  # (P, W, D): dt^k / k!, position, velocity, acceleration, ...
    design[..., 0] = 1.0
    for k in range(1, degree + 1):
        design[..., k] = design[..., k - 1] * dt / k
    window = np.nan_to_num(values[index])  # (P, W, K)
    weighted = (design * weight[..., None]).transpose(0, 2, 1)  # (P, D, W)
    normal, rhs = weighted @ design, weighted @ window  # batched BLAS
    count = use.sum(axis=1)
    sides = np.minimum((use & (dt < 0)).sum(axis=1), (use & (dt > 0)).sum(axis=1))
    known = finite & (count >= degree + 2) & ((sides >= 2) | one_sided)
    normal[~known] = np.eye(degree + 1)
    rhs[~known] = 0.0
    coefficients = np.linalg.solve(normal, rhs)  # (P, D, K)
    mean = np.sum(window * weight[..., None], axis=1) / np.maximum(count, 1)[:, None]
    scatter = np.sum(weight[..., None] * (window - mean[:, None]) ** 2, axis=(1, 2)) / np.maximum(count, 1)
    columns = {
        "velocity": coefficients[:, 1] / period,
        "acceleration": coefficients[:, 2] / period**2 if degree >= 2 else np.zeros_like(values),
        "jerk": coefficients[:, 3] / period**3 if degree >= 3 else np.zeros_like(values),
        "residual": np.sqrt(np.mean((coefficients[:, 0] - np.nan_to_num(values)) ** 2, axis=1)),
        "spread": np.sqrt(scatter / values.shape[1]),
    }
    out: dict[str, FloatArray] = {}
    for name, column in columns.items():
        unknown = 0.0 if column.ndim > 1 else np.nan
        unordered = np.empty_like(column)
        unordered[order] = np.where(known.reshape(-1, *([1] * (column.ndim - 1))), column, unknown)
        out[name] = unordered.reshape(n, *shape) if column.ndim > 1 else unordered
    known_out = np.empty(n, dtype=bool)
    known_out[order] = known
    return Motion(
        out["velocity"],
        out["acceleration"],
        out["jerk"],
        known_out,
        out["residual"],
        out["spread"],
        (neighbours, degree),
    )


def smooth_motion(
    times: FloatArray, points: FloatArray, period: float, window: tuple[int, int] | None = None
) -> Motion:
    """:func:`fit_motion` with the window :func:`choose_window` picks (or one chosen before); the ends of
    stretches get one-sided quadratic fits.

    How far apart in time a window may reach depends on how fast the wand moved and how noisy its
    points are: the recording itself decides.
    """
    if window is None:
        window = choose_window(times, points, period)
    best = fit_motion(times, points, period, neighbours=window[0], degree=window[1])
    # Where a stretch of placements ends (the wand leaves a camera's view: often at the widest angles),
    # a quadratic from one side.
    ends = fit_motion(times, points, period, neighbours=END_WINDOW[0], degree=END_WINDOW[1], one_sided=True)
    fill = ends.known & ~best.known
    if not fill.any():
        return best
    shape = (-1, *([1] * (best.velocity.ndim - 1)))
    merged = {
        name: np.where(fill.reshape(shape), getattr(ends, name), getattr(best, name))
        for name in ("velocity", "acceleration", "jerk")
    }
    return replace(best, **merged, known=best.known | fill)


def choose_window(times: FloatArray, points: FloatArray, period: float) -> tuple[int, int]:
    """The (neighbours, degree) of MOTION_WINDOWS whose fits predict the placements best from their
    neighbours (mean square leave-one-out residual over the placements every window determines).

    A long recording is scored on WINDOW_CHOICE_BLOCKS stretches of consecutive placements spread over
    it: the choice needs a representative sample of the motion, not every placement.
    """
    order = _sample_stretches(times)
    fits = [fit_motion(times[order], points[order], period, neighbours=n, degree=d) for n, d in MOTION_WINDOWS]
    common = np.all([fit.known for fit in fits], axis=0)
    if not common.any():
        return (MOTION_NEIGHBOURS, MOTION_DEGREE)
    scores = [float(np.mean(fit.residual[common] ** 2)) for fit in fits]
    return MOTION_WINDOWS[int(np.argmin(scores))]


def _sample_stretches(times: FloatArray) -> NDArray[np.int64]:
    """Indices of the WINDOW_CHOICE_BLOCKS stretches of consecutive placements (in time order) spread over a long
    recording; of every placement, in time order, in a shorter one."""
    order = np.argsort(times, kind="stable")
    n_blocks, length = WINDOW_CHOICE_BLOCKS
    if order.size <= n_blocks * length * 2:
        return order
    starts = np.linspace(0, order.size - length, n_blocks).astype(np.int64)
    return order[(starts[:, None] + np.arange(length)).ravel()]


def clearly_independent(times: FloatArray, points: FloatArray, period: float) -> bool:
    """Whether a long recording's WINDOW_CHOICE_BLOCKS stretches already show that its placements follow no
    continuous motion, so that the fits of every placement (:func:`smooth_motion`) need not be made to find that.

    The stretches' local fits leave more than CLEARLY_INDEPENDENT times the fraction of the points' spread that
    :attr:`Motion.continuous` allows (independent placements leave about all of it, a wand waved through the
    volume a few percent). False for a recording no longer than the sample, and wherever the sample is not clear.

    Args:
        times: (P,) placement times, in the time unit.
        points: (P, 3, 3) the placements' markers (NaN where unknown).
        period: frame period in the time unit.
    """
    sample = _sample_stretches(times)
    if sample.size == times.size:
        return False
    fit = fit_motion(times[sample], points[sample], period)
    fitted = fit.known & np.isfinite(fit.residual) & np.isfinite(fit.spread)
    if np.count_nonzero(fitted) < max(10, sample.size // 2):
        return False
    left = float(np.median(fit.residual[fitted]))
    return left > CLEARLY_INDEPENDENT * CONTINUITY_FRACTION * float(np.median(fit.spread[fitted]))


def align_views(
    uv: FloatArray, line: Timeline, camera_timing: FloatArray | None = None, heights: FloatArray | None = None
) -> FloatArray:
    """(P, C, K, 2) each complete view of a K-marker wand moved along its camera's own image track to its
    placement's time.

    Each camera's pixels of consecutive frames give its image velocity; a point seen ``tau`` after its
    placement's time is moved back by that motion (to third order). Before any calibration ``tau`` is
    the stamps' difference (the offsets are unknown then): the initialisation (essential matrices,
    wand lengths) and the wand-length gate see nearly simultaneous views. With the cameras' timing
    (C, 2) (offsets, readout times; rows of H = ``heights`` px) ``tau`` is each point's own instant:
    the views triangulate to where the wand was at the placement's time.
    """
    if line.simultaneous and (camera_timing is None or not np.any(camera_timing)):
        return uv
    out = np.array(uv, dtype=np.float64)
    for c in range(uv.shape[1]):
        seen = np.flatnonzero(np.all(np.isfinite(uv[:, c]), axis=(1, 2)))
        tau = np.repeat(line.view_times[seen, c][:, None], uv.shape[2], axis=1)  # (N, K)
        track = fit_motion(line.placement_times[seen] + tau[:, 0], uv[seen, c], line.period)  # the views' own times
        if camera_timing is not None and heights is not None:
            tau = tau - camera_timing[c, 0] + camera_timing[c, 1] * uv[seen, c, :, 1] / heights[c]
        tau = tau[..., None]
        moved = uv[seen, c] - tau * (track.velocity - tau / 2 * (track.acceleration - tau / 3 * track.jerk))
        out[seen, c] = np.where(track.known[:, None, None], moved, uv[seen, c])
    return out


@dataclass(frozen=True, eq=False)
class TimingInput:
    """What the bundle adjustment needs to model when each camera saw the wand.

    Attributes:
        line: the timeline of the placements being calibrated (in their order).
        offsets: "auto", "estimate" or "fixed" (held at zero).
        rolling_shutter: "auto", "estimate" or "fixed" (held at the given readout time, else zero).
        readouts: (C,) readout times given per camera in the time unit (NaN: not given).
    """

    line: Timeline
    offsets: str = "auto"
    rolling_shutter: str = "auto"
    readouts: FloatArray | None = None

    def __post_init__(self) -> None:
        for name in ("offsets", "rolling_shutter"):
            if getattr(self, name) not in TIMING_MODES:
                raise TimingError(f"{name} must be one of {', '.join(TIMING_MODES)}, got {getattr(self, name)!r}")

    def given_readouts(self, n_cameras: int) -> FloatArray:
        """(C,) readout times held fixed by the rig description (NaN: free to estimate)."""
        return np.full(n_cameras, np.nan) if self.readouts is None else self.readouts


def timing_input(
    rig: RigSpec, observations: WandObservations, *, offsets: str = "auto", rolling_shutter: str = "auto"
) -> TimingInput:
    """The timing input of a calibration: its timeline and the readout times the rig description gives.

    Raises:
        TimingError: readout_ms given for observations without stamps (a readout time needs seconds).
    """
    line = timeline(observations)
    given = np.array([np.nan if c.readout_ms is None else c.readout_ms / 1000.0 for c in rig.cameras])
    if line.unit != "s" and np.any(np.isfinite(given)):
        name = rig.cameras[int(np.flatnonzero(np.isfinite(given))[0])].name
        raise TimingError(
            f"camera '{name}': readout_ms needs stamps in the observations (a stamp column, in seconds) to say when "
            "each row was read"
        )
    return TimingInput(line, offsets, rolling_shutter, given)


def significant(
    values: FloatArray, covariance: FloatArray, level: float = SIGNIFICANCE_LEVEL, fraction: float = 1.0
) -> bool:
    """Whether estimates (k,) with covariance (k, k) differ from zero jointly (chi-square test at ``level``; with
    ``fraction``, whether their statistic exceeds that fraction of the test's quantile)."""
    if values.size == 0:
        return False
    statistic = float(values @ np.linalg.pinv(covariance, hermitian=True) @ values)
    return statistic > fraction * chi_square_quantile(level, values.size)


def with_timing(free: NDArray[np.bool_], timing: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """(C, N_CAMERA_PARAMS) the camera parameters ``free`` with the timing parameters ``timing`` (C, 2) estimated
    (a copy)."""
    out = free.copy()
    out[:, TIMING] = timing
    return out


def clearly_synchronised(clocks: ClockModel, system: CameraSystem, sigma: float, free: NDArray[np.bool_]) -> bool:
    """Whether the tentative timing parameters clearly stay out, judged without adjusting them: on the cameras'
    system at the synchronised solution with them carried (one linearisation).

    The Gauss-Newton step from there estimates them (and moves the rest along); :func:`reduce_timing`'s tests, in
    its order (the readout times jointly with every tentative parameter free, then the offsets with the readout
    times held), then find each statistic below CLEARLY_SYNCHRONISED of its quantile. Where they do not, the
    timing is tested by adjusting it (:func:`wand_calib_ros.core.refine`), as the statistic of an adjusted
    solution may differ from the linearised one near the quantile.

    Args:
        clocks: the tentative model (``clocks.free`` the parameters tested, the ``auto`` ones).
        system: the cameras' normal equations at the synchronised solution, the timing parameters carried.
        sigma: the pixel noise of that linearisation (its robust one).
        free: (C, N_CAMERA_PARAMS) the other camera parameters estimated.
    """
    tested = with_timing(free, clocks.free)
    for column, parameter in ((1, READOUT), (0, TIME_OFFSET)):  # the finer term first, as reduce_timing
        cameras = np.flatnonzero(tested[:, parameter])
        if cameras.size == 0:
            continue
        values = clocks.start[cameras, column] + system.step(tested)[cameras, parameter]
        index = cameras * N_CAMERA_PARAMS + parameter
        covariance = system.covariance(tested, sigma)[np.ix_(index, index)]
        if significant(values, covariance, fraction=CLEARLY_SYNCHRONISED):
            return False
        tested[:, parameter] = False
    return True


@dataclass(frozen=True, eq=False)
class ClockModel:
    """The timing model of one refinement: which timing parameters are estimated, how the wand moved.

    Attributes:
        line: the placements' timeline (None without timing input).
        modes: (offsets, rolling_shutter) modes of the input.
        heights: (C,) image heights, px.
        free: (C, 2) whether each camera's time offset and readout time are estimated.
        start: (C, 2) their starting (or fixed) values, in the time unit.
        motion: the wand's motion at every placement (None: the timing is not modelled).
        notes: plain-language reasons why timing parameters were not estimated.
        tentative: whether the timing is modelled only to test it: ``auto`` on views the stamps (or
            frame ids) call simultaneous. The refinement then runs as for synchronised cameras unless
            the test finds offsets or readout times (:func:`wand_calib_ros.core.refine`).
    """

    line: Timeline | None
    modes: tuple[str, str]
    heights: FloatArray
    free: NDArray[np.bool_]
    start: FloatArray
    motion: Motion | None
    notes: tuple[str, ...] = ()
    tentative: bool = False

    @property
    def modelled(self) -> bool:
        """Whether the adjustments carry the views to their instants (else: simultaneous views)."""
        return self.line is not None and self.motion is not None

    def placements(self, index: NDArray[np.int64] | NDArray[np.bool_] | None = None) -> PlacementTiming | None:
        """The bundle adjustment's timing of all placements (or of ``index``); None when not modelled."""
        if self.line is None or self.motion is None:
            return None
        motion = self.motion
        timing = PlacementTiming(self.line.view_times, self.heights, motion.velocity, motion.acceleration, motion.jerk)
        return timing if index is None else timing.subset(index)

    def placeable(self, n_placements: int) -> NDArray[np.bool_]:
        """(P,) placements that can be put at each camera's instant: all without timing, else those whose
        motion the neighbours determined (the others' views would be misplaced by tau x velocity)."""
        return np.ones(n_placements, dtype=bool) if self.motion is None else self.motion.known

    def with_motion(self, motion: Motion) -> ClockModel:
        return replace(self, motion=motion)

    def without_timing(self, note: str) -> ClockModel:
        """The model of synchronised cameras (what a test of a tentative model found), saying why."""
        return replace(self, motion=None, free=np.zeros_like(self.free), tentative=False, notes=(*self.notes, note))


def start_clocks(rig: RigSpec, timing: TimingInput | None, points: FloatArray, reference: int) -> ClockModel:
    """The timing model before the bundle adjustment: the motion of the initial placements and what to estimate.

    Args:
        rig: the rig description (cameras in the order of the placements' views).
        timing: the user's timing input (None: the cameras are synchronised).
        points: (P, 3, 3) the placements triangulated with the initial cameras.
        reference: the reference camera, whose time offset is 0 by definition.

    Raises:
        TimingError: offsets or readout times to ``estimate`` from frames that show no continuous motion.
    """
    n = len(rig.cameras)
    heights = np.array([c.image_size[1] for c in rig.cameras], dtype=np.float64)
    free = np.zeros((n, 2), dtype=bool)
    start = np.zeros((n, 2))
    if timing is None:
        return ClockModel(None, ("fixed", "fixed"), heights, free, start, None)
    line = timing.line
    given = timing.given_readouts(n)
    start[:, 1] = np.nan_to_num(given)
    # (independent placements, e.g. a subsampled recording: a sample tells, the fits of them all need not be made)
    independent = clearly_independent(line.placement_times, points, line.period)
    motion = None if independent else smooth_motion(line.placement_times, points, line.period)
    continuous = motion is not None and motion.continuous
    notes = []
    # Stamps that put a frame's views at different instants come from free-running cameras, whose
    # drivers' latencies differ too: ``auto`` estimates their offsets without a test.
    offsets = "estimate" if timing.offsets == "auto" and not line.simultaneous else timing.offsets
    for column, mode, what in ((0, offsets, "time offsets"), (1, timing.rolling_shutter, "readout times")):
        if mode == "fixed":
            continue
        if not continuous:
            if mode == "estimate":
                raise TimingError(
                    f"{what} cannot be estimated: consecutive frames do not show one continuous motion of the wand "
                    "(independent placements, or frames out of time order); hold them fixed"
                )
            notes.append(f"{what} not estimated: consecutive frames do not show one continuous motion of the wand")
            continue
        free[:, column] = True
    free[reference, 0] = False
    free[np.isfinite(given), 1] = False
    if not continuous and not line.simultaneous:
        notes.append("the stamps put the cameras' views of a frame at different instants, but without a continuous "
                     "motion they are treated as simultaneous")  # fmt: skip
    modelled = continuous and (free.any() or not line.simultaneous or bool(np.any(start)))
    tentative = (
        modelled and line.simultaneous and not np.any(start) and "estimate" not in (offsets, timing.rolling_shutter)
    )
    return ClockModel(
        line, (offsets, timing.rolling_shutter), heights, free, start,
        motion if modelled else None, tuple(notes), tentative,
    )  # fmt: skip


def refresh_motion(clocks: ClockModel, points: FloatArray, *, choose: bool = False) -> ClockModel:
    """The motion refitted to the placements where an adjustment put them.

    Args:
        clocks: the timing model (unchanged when it models nothing).
        points: (P, 3, 3) every placement of the timeline: the adjusted ones where an adjustment
            placed them, the others where the starting triangulation did (NaN: unknown).
        choose: choose the motion's window again (else keep the one chosen before).
    """
    if clocks.line is None or clocks.motion is None:
        return clocks
    window = None if choose else clocks.motion.window
    return clocks.with_motion(smooth_motion(clocks.line.placement_times, points, clocks.line.period, window))


def reduce_timing(clocks: ClockModel, result: BundleResult, free: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The timing parameters ``auto`` keeps after an adjustment that estimated them.

    A readout time that came out negative (in any mode) is held at zero first: the physical bound
    (readout >= 0) is active there, and the others are adjusted again with it. Then, nested like the
    distortion model, the finer term first: the readout times stay when they differ from zero jointly
    (a rig's cameras are usually of one kind); once they are settled, the time offsets stay when they
    differ from zero jointly, tested without the readout times that went (the two correlate). Both
    are chi-square tests at SIGNIFICANCE_LEVEL.

    Args:
        clocks: the timing model (its modes).
        result: an adjustment with the timing parameters in ``free`` estimated.
        free: (C, 2) the timing parameters that adjustment estimated.

    Returns:
        (C, 2) those still to estimate.
    """
    kept = free.copy()
    values = result.state.camera_timing
    negative = free[:, 1] & (values[:, 1] < 0)
    if negative.any():  # a readout is never negative: the bound is active there, the readout held at zero
        log.info("readout times %s are negative: held at zero", np.array2string(values[negative, 1], precision=4))
        kept[negative, 1] = False
        return kept
    for column, parameter, mode, what in (
        (1, READOUT, clocks.modes[1], "readout times"),
        (0, TIME_OFFSET, clocks.modes[0], "time offsets"),
    ):
        cameras = np.flatnonzero(free[:, column])
        if mode != "auto" or cameras.size == 0:
            continue
        index = cameras * N_CAMERA_PARAMS + parameter
        if not significant(values[cameras, column], result.camera_covariance[np.ix_(index, index)]):
            log.info(
                "%s %s +- %s are not significant: held at zero",
                what,
                np.array2string(values[cameras, column], precision=4),
                np.array2string(result.camera_std[cameras, parameter], precision=4),
            )
            kept[:, column] = False
            return kept  # the finer term went: test the next one without it
    return kept


def offset_warnings(result: CalibrationResult) -> list[str]:
    """Cameras whose estimated time offset exceeds a frame period (their views were grouped with
    others' taken a frame apart, or their driver's stamps lag by more than a frame)."""
    timing = result.timing
    if timing is None or timing.time_offsets != "estimated":
        return []
    unit = "ms" if timing.unit == "s" else "frames"
    scale = 1000.0 if timing.unit == "s" else 1.0
    return [
        f"{c.name}: time offset {scale * c.time_offset:+.3g} {unit} against {result.reference_camera}, more than a "
        f"frame ({scale * timing.frame_period:.3g} {unit}): one of the two drivers stamps late (a queue?); frames "
        "are paired by stamp, so the motion had to carry its views over more than a frame"
        for c in result.cameras
        if abs(c.time_offset) > timing.frame_period
    ]
