"""The calibration entry point: rig description + observations -> CalibrationResult."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.narrow_field import narrow_fields
from wand_calib_ros.core.adjust.timing import (
    TimingInput,
    align_views,
    offset_warnings,
    rate_warnings,
    timing_input,
)
from wand_calib_ros.core.after.world_frame import floor_of
from wand_calib_ros.core.errors import CalibrationFailedError, CoreError, DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.initialise.clock_alignment import ClockAlignment, align_clocks
from wand_calib_ros.core.initialise.incremental import place_cameras
from wand_calib_ros.core.initialise.lens_choice import model_starts, nominal_model
from wand_calib_ros.core.initialise.multi_camera import RigInitialisation, initialise_rig
from wand_calib_ros.core.initialise.pairwise import PairOptions
from wand_calib_ros.core.initialise.two_markers import consistent_labels, continuous_in_image
from wand_calib_ros.core.initialise.vision_graph import (
    DisconnectedRigError,
    VisionGraph,
    build_vision_graph,
    chained,
    covisibility,
    reference_index,
)
from wand_calib_ros.core.judge.diagnostics import clock_offsets, clock_warnings
from wand_calib_ros.core.judge.metrics import rereference
from wand_calib_ros.core.judge.plausibility import check_result, check_rig, check_views
from wand_calib_ros.core.judge.quality import judge, noise_wand_error
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.result import CalibrationResult, TimingSummary
from wand_calib_ros.core.model.rig import RigSpec, WandObservations, spread_subset
from wand_calib_ros.core.model.views import whole_views
from wand_calib_ros.core.refine import refine_calibration

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CalibrationOptions:
    """User-facing settings of :func:`calibrate`.

    Attributes:
        reference_camera: name of the camera whose frame is the reference (default: the one that
            shares the most placements with the others; the first on a tie).
        pair: settings of the pairwise initialisation (Steps 1-3).
        max_placements: use at most this many placements, spread evenly over the recording
            (consecutive frames of a slowly waved wand are redundant): a time budget.
        time_offsets: "auto" (estimated when they differ significantly from zero), "estimate" or
            "fixed" (synchronised cameras: zero).
        rolling_shutter: "auto" (per camera, estimated when significant), "estimate" or "fixed"
            (zero, or the rig description's ``readout_ms``).
        floor_frames: frames of the wand laid still on the floor: the world frame.
        floor_origin: the world's origin: the first lay's "A" or its "centre".
        start: a previous calibration of the same rig whose cameras replace the pairwise
            initialisation (a warm start: the running estimate's next round; None: Steps 1-3).
        clocks: the cameras' clock offsets already found from the wand's motion in these observations' views
            (``detect`` finds them to group its frames), used as found; None: searched here.
    """

    reference_camera: str | None = None
    pair: PairOptions = field(default_factory=PairOptions)
    max_placements: int | None = None
    time_offsets: str = "auto"
    rolling_shutter: str = "auto"
    floor_frames: tuple[int, ...] = ()
    floor_origin: str = "A"
    start: CalibrationResult | None = None
    clocks: ClockAlignment | None = None


def calibrate(
    rig: RigSpec, observations: WandObservations, options: CalibrationOptions = CalibrationOptions()
) -> CalibrationResult:
    """Calibrate intrinsics and extrinsics of the rig's cameras from wand observations.

    Two cameras follow Section III-A of the paper; more cameras are initialised
    through the vision graph (Section III-B) and refined by one global bundle
    adjustment. With every camera's intrinsics given, or where the graph's pairs do not
    chain every camera (a sparse take), the cameras are placed one by one instead
    (:mod:`~wand_calib_ros.core.initialise.incremental`). Placements must be seen completely (every
    marker of the wand) by at least two cameras; the initialisation uses complete views
    only, the bundle adjustment every point seen.

    Args:
        rig: wand and camera descriptions.
        observations: image points; cameras are matched by name.
        options: settings.

    Raises:
        WandCalibError subclasses with a message naming the problem.
    """
    obs, floor = _selected(rig, observations, options.floor_frames)
    check_rig(rig)
    obs, clocks = align_clocks(rig, obs, options.clocks)
    for line in clocks.lines:
        log.info(line)
    check_views(rig, obs)
    timing = timing_input(rig, obs, offsets=options.time_offsets, rolling_shutter=options.rolling_shutter)
    views = _views(rig, obs, timing, options)
    if options.start is not None:
        result, uv = _solve(rig, views, _warm(rig, views.reference, options.start))
    elif all(views.given) and not narrow_fields(rig).all():  # a pair needs only its relative pose (an essential
        # matrix hardly fixes it at a few degrees across: narrow rigs start from the paper's pairs and their wand fits)
        known = tuple(spec.intrinsics for spec in rig.cameras if spec.intrinsics is not None)
        result, uv = _solve(rig, views, _placed(rig, views.aligned, views.reference, options.pair, known))
    else:
        result, uv = _from_pairs_or_placed(rig, views, options, clocks.unchecked)
    if floor is not None:
        result = _with_floor(rig, result, floor, options.floor_origin)
    warnings = [*result.warnings, *rate_warnings(obs, timing.line), *offset_warnings(result)]
    result = replace(result, quality=judge(result, noise_wand_error(result, rig.camera_names, uv)))
    result = _with_clocks(result, clocks, rig.camera_names, timing.line.frame_period)
    if result.timing is not None and result.timing.time_offsets == "estimated":
        return replace(result, warnings=tuple(warnings))
    offsets = clock_offsets(result, obs)  # not modelled: say when the residuals show them
    return replace(result, clock_offsets=offsets, warnings=(*warnings, *clock_warnings(offsets)))


def _with_clocks(
    result: CalibrationResult, clocks: ClockAlignment, names: tuple[str, ...], frame_period: float
) -> CalibrationResult:
    """The result with the clock offsets the wand's motion lined up added to its cameras' time offsets (the
    calibration estimated what was left within a frame or two), and said in its timing."""
    if not clocks.moved.any():
        return result
    coarse = dict(zip(names, clocks.relative_to(names.index(result.reference_camera)), strict=True))
    cameras = tuple(replace(c, time_offset=c.time_offset + float(coarse[c.name])) for c in result.cameras)
    timing = result.timing or TimingSummary(clocks.unit, "fixed", {c.name: "fixed" for c in cameras}, frame_period)
    return replace(result, cameras=cameras, timing=replace(timing, clocks=clocks.lines))


def _selected(
    rig: RigSpec, observations: WandObservations, floor_frames: tuple[int, ...]
) -> tuple[WandObservations, WandObservations | None]:
    """The rig's cameras' observations, in the rig's order, and the floor's frames apart from them (None: none).

    Raises:
        InsufficientDataError: fewer than two cameras, a camera without observations, or another wand.
    """
    names = rig.camera_names
    if len(names) < 2:
        raise InsufficientDataError(f"a wand calibration needs at least two cameras; the rig has {len(names)}")
    for name in names:
        if name not in observations.camera_names:
            raise InsufficientDataError(f"camera '{name}' has no observations")
    obs = observations.select_cameras(names)
    if obs.uv.shape[2] != rig.wand.n_points:
        raise InsufficientDataError(
            f"the observations have {obs.uv.shape[2]} points per view, the rig's wand {rig.wand.n_points} markers"
        )
    return _split_floor(obs, floor_frames)


@dataclass(frozen=True, eq=False)
class _Views:
    """The views a calibration starts from and refines on.

    Attributes:
        uv: (P, C, K, 2) the usable placements' views, partial ones included (a two-marker wand's labels
            followed per camera).
        aligned: (P, C, K, 2) those moved to their placement's time (free-running cameras), for the starts.
        saturated: (P, C, K) which points the detector measured on saturated spots (None: not known).
        brightness: (P, C, K) how bright each point's spot was, stops over full scale (None: not known).
        reference: the reference camera's index.
        timing: the timing input of the usable placements.
        given: (C,) which cameras' intrinsics the rig gives.
    """

    uv: NDArray[np.float64]
    aligned: NDArray[np.float64]
    saturated: NDArray[np.bool_] | None
    reference: int
    timing: TimingInput
    given: tuple[bool, ...]
    brightness: NDArray[np.float64] | None = None


def _views(rig: RigSpec, obs: WandObservations, timing: TimingInput, options: CalibrationOptions) -> _Views:
    """The placements seen whole by two cameras at least (at most ``max_placements`` of them, spread), with every
    point seen of them, and the reference camera they share the most with."""
    names, complete = rig.camera_names, obs.complete
    _require_whole_views(names, complete)
    usable = np.flatnonzero(complete.sum(axis=1) >= 2)  # a placement seen by one camera only constrains nothing
    if options.max_placements is not None and usable.size > options.max_placements:
        log.info("using %d of %d placements (max_placements)", options.max_placements, usable.size)
        usable = usable[spread_subset(usable.size, options.max_placements)]
    # partial views stay: the bundle adjustment uses every point seen (every frame usable: no copy of the views)
    uv = obs.uv if usable.size == complete.shape[0] else obs.uv[usable]
    # (a two-marker wand's views are relabelled below: their flags would not follow)
    saturated = None if obs.saturated is None or rig.wand.n_points == 2 else obs.saturated[usable]
    brightness = None if obs.brightness is None or rig.wand.n_points == 2 else obs.brightness[usable]
    log.info("%d of %d frames show the whole wand to at least two cameras", usable.size, complete.shape[0])
    reference = reference_index(names, covisibility(complete[usable]), options.reference_camera)
    line = timing.line.subset(usable)
    if rig.wand.n_points == 2:  # a two-marker wand's labels are the detector's: per camera, follow the marker
        uv = continuous_in_image(uv)
    aligned = align_views(uv, line)  # free-running views moved to their placement's time, for the starts
    given = tuple(spec.intrinsics is not None for spec in rig.cameras)
    if any(given):
        log.info("intrinsics given for %s", ", ".join(n for n, g in zip(names, given, strict=True) if g))
    return _Views(uv, aligned, saturated, reference, replace(timing, line=line), given, brightness)


def _solve(rig: RigSpec, views: _Views, init: RigInitialisation) -> tuple[CalibrationResult, NDArray[np.float64]]:
    """Step 4 from a start: the two-marker wand's labels settled, the refinement, its plausibility. Returns the
    result and the views it refined (relabelled for a two-marker wand)."""
    init = replace(init, models=model_starts(rig, init.models))
    uv, start_uv = views.uv, views.aligned
    if rig.wand.n_points == 2:  # one label per marker in every view and over time, from the started cameras
        uv = consistent_labels(init.models, init.poses, views.uv, narrow_fields(rig))
        start_uv = align_views(uv, views.timing.line)
    result, points = refine_calibration(
        rig,
        uv,
        init.models,
        init.poses,
        reference=views.reference,
        initial_projections=tuple("given" if g else p for g, p in zip(views.given, init.projections, strict=True)),
        lens_trials=init.trials,
        timing=views.timing,
        start_uv=start_uv,
        saturated=views.saturated,
        brightness=views.brightness,
    )
    return replace(result, warnings=(*result.warnings, *check_result(rig, result, uv, points))), uv


def _from_pairs_or_placed(
    rig: RigSpec, views: _Views, options: CalibrationOptions, unchecked: tuple[str, ...] = ()
) -> tuple[CalibrationResult, NDArray[np.float64]]:
    """The calibration from the paper's pairwise start; where that fails and the cameras can be placed one by one
    from their given or nominal intrinsics, from those (the paper's error raised should that fail too). A start
    that fails says too which cameras' clocks the wand's motion could not check (``unchecked``): views of different
    instants look like a rig no geometry fits."""
    try:
        return _solve(rig, views, _paper(rig, views.aligned, options))
    except DegenerateDataError as error:
        if not unchecked:
            raise
        raise type(error)(f"{error}; and the clocks could not be checked: {'; '.join(unchecked)}") from None
    except (DisconnectedRigError, CalibrationFailedError, InsufficientDataError) as error:
        reason = _unplaceable(rig, views.aligned, options)
        if reason is not None:
            if isinstance(error, DisconnectedRigError):
                raise DisconnectedRigError(f"{reason}; and the paper's pairwise start: {error}") from None
            raise
        log.info("%s: the cameras are placed one by one from their given or nominal intrinsics instead", error)
        starts = tuple(spec.intrinsics or nominal_model(spec) for spec in rig.cameras)
        try:
            return _solve(rig, views, _placed(rig, views.aligned, views.reference, options.pair, starts, nominal=True))
        except CoreError as placed_error:
            log.info("placing the cameras one by one failed too: %s", placed_error)
            raise error from None


def _initialise(rig: RigSpec, uv: NDArray[np.float64], graph: VisionGraph, options: PairOptions) -> RigInitialisation:
    """Steps 1-3 and the chaining of Section III-B, made for the three-marker wand: on a longer wand
    they use the first, the middle and the last marker (:meth:`WandSpec.three_points`; the bundle
    adjustment then uses every marker), on a two-marker wand both (Step 3 matches their distance)."""
    if rig.wand.n_points <= 3:  # two markers: Steps 2-3 on both (their labels matched per pair)
        return initialise_rig(rig, uv, graph, options)
    three = replace(rig, wand=rig.wand.three_point_wand())
    return initialise_rig(three, uv[:, :, list(rig.wand.three_points())], graph, options)


def _paper(rig: RigSpec, uv: NDArray[np.float64], options: CalibrationOptions) -> RigInitialisation:
    """The paper's initialisation through the vision graph (pairs of at least ``min_placements`` views)."""
    names = rig.camera_names
    complete = whole_views(uv)
    graph = build_vision_graph(
        names, complete, reference=options.reference_camera, min_shared=options.pair.min_placements
    )
    log.info(
        "reference camera %s; pairs calibrated: %s",
        names[graph.reference],
        ", ".join(f"{names[a]}-{names[b]}" for a, b in graph.edges),
    )
    return _initialise(rig, uv, graph, options.pair)


def _unplaceable(rig: RigSpec, uv: NDArray[np.float64], options: CalibrationOptions) -> str | None:
    """Why the cameras cannot be placed one by one instead of through the paper's pairs (None: they can):
    every camera whose intrinsics are estimated needs ``min_placements`` views of the whole wand that
    another camera shares, and the cameras must share views at all."""
    complete = whole_views(uv)
    if not chained(covisibility(complete) > 0):
        return "no camera shares a view of the whole wand with the others"
    views = (complete & (complete.sum(axis=1, keepdims=True) >= 2)).sum(axis=0)
    few = [(spec.name, int(views[c])) for c, spec in enumerate(rig.cameras) if spec.intrinsics is None]
    few = [(name, count) for name, count in few if count < options.pair.min_placements]
    if not few:
        return None
    counts = ", ".join(f"'{name}' has {count}" for name, count in few)
    return (
        f"estimating a camera's intrinsics takes at least {options.pair.min_placements} views of the whole wand "
        f"that another camera shares ({counts}): wave the wand longer, or give its intrinsics (intrinsics in "
        "cameras.yaml: then a camera needs only the views its pose needs)"
    )


#: The placing's inlier threshold over the pairs' RANSAC threshold when the intrinsics are the nominal
#: lens's (a conventional lens's barrel moves the image corners by tens of pixels from it).
NOMINAL_SLACK = 6.0


def _placed(
    rig: RigSpec,
    uv: NDArray[np.float64],
    reference: int,
    options: PairOptions,
    models: tuple[CameraModel, ...],
    *,
    nominal: bool = False,
) -> RigInitialisation:
    """The cameras placed one by one from known intrinsics (:mod:`~wand_calib_ros.core.initialise.incremental`)."""
    focal_px = min(float(np.min(model.focal_px)) for model in models)
    threshold = options.ransac_threshold_px / focal_px * (NOMINAL_SLACK if nominal else 1.0)
    poses = place_cameras(rig, uv, models, reference, threshold_rad=threshold, seed=options.seed)
    projections = tuple("given" if spec.intrinsics is not None else "nominal" for spec in rig.cameras)
    return RigInitialisation(models, poses, projections, ())


def _warm(rig: RigSpec, reference: int, start: CalibrationResult) -> RigInitialisation:
    """A previous calibration's cameras as the start, its poses re-expressed in the reference camera's frame."""
    names = rig.camera_names
    missing = [n for n in names if n not in {c.name for c in start.cameras}]
    if missing:
        raise InsufficientDataError(f"the warm start has no camera {', '.join(missing)}")
    poses = rereference({n: start.camera(n).pose for n in names}, names[reference])
    return RigInitialisation(
        tuple(start.camera(n).model for n in names),
        tuple(poses[n] for n in names),
        tuple(start.camera(n).initial_projection for n in names),
        start.lens_trials,
    )


def _require_whole_views(names: tuple[str, ...], complete: NDArray[np.bool_]) -> None:
    """Every camera must see the whole wand (every marker) in a frame another camera sees it in too.

    Raises:
        InsufficientDataError: naming the cameras that never see the whole wand, or that see it
            only in frames no other camera sees it in.
    """
    never = [name for name, seen in zip(names, np.any(complete, axis=0).tolist(), strict=True) if not seen]
    if never:
        raise InsufficientDataError(f"camera(s) {', '.join(never)} never see the whole wand")
    shared = complete & (complete.sum(axis=1, keepdims=True) >= 2)
    alone = [name for name, seen in zip(names, np.any(shared, axis=0).tolist(), strict=True) if not seen]
    if alone:
        counts = ", ".join(f"{n} in {int(complete[:, names.index(n)].sum())} frames" for n in alone)
        raise InsufficientDataError(
            f"camera(s) {', '.join(alone)} see the whole wand ({counts}) but never in a frame another camera "
            "sees it in too: wave it where they overlap"
        )


def _with_floor(rig: RigSpec, result: CalibrationResult, floor: WandObservations, origin: str) -> CalibrationResult:
    """The result with the world frame of the floor frames, its cameras adjusted with the floor."""
    names = rig.camera_names
    assert result.camera_covariance is not None  # every calibration assembles its adjustment's covariance
    floor_fit = floor_of(
        tuple(result.camera(n).model for n in names),
        tuple(result.camera(n).pose for n in names),
        floor.uv,
        result.camera_covariance,
        result.sigma_px,
        positions_mm=rig.wand.positions_mm,
        origin=origin,
        tool_mm=None if rig.floor_tool is None else np.asarray(rig.floor_tool, dtype=float),
    )
    moved = {n: (floor_fit.models[c], floor_fit.poses[c]) for c, n in enumerate(names)}
    cameras = tuple(replace(c, model=moved[c.name][0], pose=moved[c.name][1]) for c in result.cameras)
    return replace(result, cameras=cameras, world=floor_fit.world)


def _split_floor(
    observations: WandObservations, floor_frames: tuple[int, ...]
) -> tuple[WandObservations, WandObservations | None]:
    """(the frames to calibrate from, the floor frames or None): the wand laid still is not waved."""
    if not floor_frames:
        return observations, None
    on_floor = np.isin(observations.frames, np.asarray(floor_frames, dtype=np.int64))
    if not on_floor.any():
        raise InsufficientDataError(
            f"floor frames {floor_frames[0]}..{floor_frames[-1]}: none of them is in the observations"
        )
    return observations.select_frames(~on_floor), observations.select_frames(on_floor)
