"""The calibration entry point: rig description + observations -> CalibrationResult."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.diagnostics import clock_offsets, clock_warnings
from wand_calib_ros.core.errors import InsufficientDataError
from wand_calib_ros.core.metrics import rereference
from wand_calib_ros.core.multi_camera import RigInitialisation, initialise_rig
from wand_calib_ros.core.pairwise import PairOptions
from wand_calib_ros.core.plausibility import check_result, check_rig, check_views
from wand_calib_ros.core.quality import judge, noise_wand_error
from wand_calib_ros.core.refine import refine_calibration
from wand_calib_ros.core.result import CalibrationResult
from wand_calib_ros.core.rig import RigSpec, WandObservations, spread_subset
from wand_calib_ros.core.timing import align_views, offset_warnings, rate_warnings, timing_input
from wand_calib_ros.core.two_markers import consistent_labels, continuous_in_image
from wand_calib_ros.core.vision_graph import VisionGraph, build_vision_graph
from wand_calib_ros.core.world_frame import floor_of

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
    """

    reference_camera: str | None = None
    pair: PairOptions = field(default_factory=PairOptions)
    max_placements: int | None = None
    time_offsets: str = "auto"
    rolling_shutter: str = "auto"
    floor_frames: tuple[int, ...] = ()
    floor_origin: str = "A"
    start: CalibrationResult | None = None


def calibrate(
    rig: RigSpec, observations: WandObservations, options: CalibrationOptions = CalibrationOptions()
) -> CalibrationResult:
    """Calibrate intrinsics and extrinsics of the rig's cameras from wand observations.

    Two cameras follow Section III-A of the paper; more cameras are initialised
    through the vision graph (Section III-B) and refined by one global bundle
    adjustment. Placements must be seen completely (every marker of the wand) by at
    least two cameras; the initialisation uses complete views only, the bundle
    adjustment every point seen.

    Args:
        rig: wand and camera descriptions.
        observations: image points; cameras are matched by name.
        options: settings.

    Raises:
        WandCalibError subclasses with a message naming the problem.
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
    obs, floor = _split_floor(obs, options.floor_frames)
    check_rig(rig)
    check_views(rig, obs)
    timing = timing_input(rig, obs, offsets=options.time_offsets, rolling_shutter=options.rolling_shutter)
    complete = obs.complete
    _require_whole_views(names, complete)
    usable = np.flatnonzero(complete.sum(axis=1) >= 2)  # a placement seen by one camera only constrains nothing
    if options.max_placements is not None and usable.size > options.max_placements:
        log.info("using %d of %d placements (max_placements)", options.max_placements, usable.size)
        usable = usable[spread_subset(usable.size, options.max_placements)]
    uv = obs.uv[usable]  # partial views stay: the bundle adjustment uses every point seen
    log.info("%d of %d frames show the whole wand to at least two cameras", usable.size, complete.shape[0])
    graph = build_vision_graph(
        names, complete[usable], reference=options.reference_camera, min_shared=options.pair.min_placements
    )
    log.info(
        "reference camera %s; pairs calibrated: %s",
        names[graph.reference],
        ", ".join(f"{names[a]}-{names[b]}" for a, b in graph.edges),
    )
    line = timing.line.subset(usable)
    if rig.wand.n_points == 2:  # a two-marker wand's labels are the detector's: per camera, follow the marker
        uv = continuous_in_image(uv)
    aligned = align_views(uv, line)  # free-running views moved to their placement's time, for the starts
    init = _initialise(rig, aligned, graph, options.pair) if options.start is None else _warm(rig, graph, options.start)
    if rig.wand.n_points == 2:  # one label per marker in every view and over time, from the started cameras
        uv = consistent_labels(init.models, init.poses, uv)
        aligned = align_views(uv, line)
    given = [spec.intrinsics is not None for spec in rig.cameras]
    if any(given):
        log.info("intrinsics given for %s", ", ".join(n for n, g in zip(names, given, strict=True) if g))
    result = refine_calibration(
        rig,
        uv,
        tuple(spec.intrinsics or model for spec, model in zip(rig.cameras, init.models, strict=True)),
        init.poses,
        reference=graph.reference,
        initial_projections=tuple("given" if g else p for g, p in zip(given, init.projections, strict=True)),
        lens_trials=init.trials,
        timing=replace(timing, line=line),
        start_uv=aligned,
    )
    check_result(rig, result)
    if floor is not None:
        models = tuple(result.camera(n).model for n in names)
        poses = tuple(result.camera(n).pose for n in names)
        result = replace(result, world=floor_of(models, poses, floor.uv, origin=options.floor_origin))
    warnings = [*result.warnings, *rate_warnings(obs, timing.line), *offset_warnings(result)]
    result = replace(result, quality=judge(result, noise_wand_error(result, names, uv)))
    if result.timing is not None and result.timing.time_offsets == "estimated":
        return replace(result, warnings=tuple(warnings))
    offsets = clock_offsets(result, obs)  # not modelled: say when the residuals show them
    return replace(result, clock_offsets=offsets, warnings=(*warnings, *clock_warnings(offsets)))


def _initialise(rig: RigSpec, uv: NDArray[np.float64], graph: VisionGraph, options: PairOptions) -> RigInitialisation:
    """Steps 1-3 and the chaining of Section III-B, made for the three-marker wand: on a longer wand
    they use the first, the middle and the last marker (:meth:`WandSpec.three_points`; the bundle
    adjustment then uses every marker), on a two-marker wand both (Step 3 matches their distance)."""
    if rig.wand.n_points <= 3:  # two markers: Steps 2-3 on both (their labels matched per pair)
        return initialise_rig(rig, uv, graph, options)
    three = replace(rig, wand=rig.wand.three_point_wand())
    return initialise_rig(three, uv[:, :, list(rig.wand.three_points())], graph, options)


def _warm(rig: RigSpec, graph: VisionGraph, start: CalibrationResult) -> RigInitialisation:
    """A previous calibration's cameras as the start, its poses re-expressed in the graph's reference."""
    names = rig.camera_names
    missing = [n for n in names if n not in {c.name for c in start.cameras}]
    if missing:
        raise InsufficientDataError(f"the warm start has no camera {', '.join(missing)}")
    poses = rereference({n: start.camera(n).pose for n in names}, names[graph.reference])
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
