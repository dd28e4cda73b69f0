"""What a calibration report shows, computed from the result, the rig and the observations.

The residuals are those of the result's cameras: every placement is
triangulated and its wand parameters are fitted with the cameras held fixed,
so the report can be made for any result file, also one from another run.
With the result's time offsets and readout times, each view is carried to its
camera's instant along the wand's motion (as the calibration did); the timing
figure compares those residuals with the ones of simultaneous views.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS, BundleProblem, BundleState, PlacementTiming
from wand_calib_ros.core.adjust.gating import VIEW_GATE_SIGMAS, rejected_views
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.adjust.timing import Timeline, align_views, smooth_motion, timeline
from wand_calib_ros.core.errors import CoreError
from wand_calib_ros.core.initialise.vision_graph import VisionGraph, build_vision_graph, covisibility
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose, wand_directions
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.result_yaml import result_document, result_geometry
from wand_calib_ros.io.session_csv import (
    ESTIMATES_FILE,
    EVENTS_FILE,
    EstimateHistory,
    SessionEvent,
    read_estimates,
    read_events,
)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class CameraResiduals:
    """One camera's observations and reprojection residuals.

    Attributes:
        uv: (N, 2) observed pixels.
        residuals: (N, 2) projected minus observed, px.
        theta: (N,) off-axis angle of each observed point, rad.
        rejected: (N,) points of views the calibration's view gate rejects (a point beyond
            VIEW_GATE_SIGMAS times the result's pixel noise): outliers the result does not use.
    """

    uv: FloatArray
    residuals: FloatArray
    theta: FloatArray
    rejected: NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class TimingResiduals:
    """One camera's residuals against its image velocity, without and with the result's timing.

    Attributes:
        speed: (N,) image speed of each observed point, px per frame.
        along_static: (N,) residual component along the image velocity, views taken as simultaneous, px.
        along_timed: (N,) the same with the result's time offset and readout time, px.
    """

    speed: FloatArray
    along_static: FloatArray
    along_timed: FloatArray


@dataclass(frozen=True, eq=False)
class ReportData:
    """Everything the report draws.

    Attributes:
        rig: the rig description.
        names: camera names (rig order).
        models, poses: the result's cameras (poses in the result's reference frame).
        reference: the reference camera.
        document: the result YAML as parsed (metrics, std, warnings, ...).
        cameras: per camera residuals.
        wand_points: (P, 3, 3) fitted A, B, C per placement, reference frame, mm.
        ac_lengths: (P,) |AC| of the linearly triangulated placements, mm.
        shared: (C, C) placements seen completely by both cameras.
        graph: the vision graph from the reference (None if the cameras are not connected).
        timing: per camera residuals against image velocity (None when the result has no timing or
            the frames show no continuous motion).
        estimates: the live session's running-estimate rounds (``estimates.csv`` next to the result;
            None without one).
        events: the live session's events (``events.csv`` next to the result: cameras judged moved,
            calibrations, repairs).
    """

    rig: RigSpec
    names: tuple[str, ...]
    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    reference: str
    document: dict[str, Any]
    cameras: tuple[CameraResiduals, ...]
    wand_points: FloatArray
    ac_lengths: FloatArray
    shared: NDArray[np.int64]
    graph: VisionGraph | None
    timing: tuple[TimingResiduals, ...] | None = None
    estimates: EstimateHistory | None = None
    events: tuple[SessionEvent, ...] = ()


def session_history(folder: Path) -> tuple[EstimateHistory | None, tuple[SessionEvent, ...]]:
    """The live session's history files in ``folder`` (the collector's output_dir), where present."""
    estimates = folder / ESTIMATES_FILE
    events = folder / EVENTS_FILE
    return (
        read_estimates(estimates) if estimates.exists() else None,
        read_events(events) if events.exists() else (),
    )


#: A result whose camera reprojects the observations (their median residual: outliers aside) worse than
#: this many times the RMS it reports (and MISFIT_PX) is not a result of these observations.
MISFIT_FACTOR = 10.0
MISFIT_PX = 5.0


def _require_fit(
    path: Path, document: dict[str, Any], names: tuple[str, ...], problem: BundleProblem, res: FloatArray
) -> None:
    """The result must describe the cameras that took these observations (not another rig's of the same names).

    Raises:
        FormatError: naming the camera that reprojects them worst and what the result says of it.
    """
    for c, name in enumerate(names):
        mine = res[problem.camera == c]
        if mine.size == 0:
            continue
        typical = float(np.nanmedian(np.linalg.norm(mine, axis=1))) / np.sqrt(2 * np.log(2))  # per coordinate,
        stated = float(document["cameras"][name].get("rms_reprojection_px", np.nan))  # outliers aside
        if not np.isfinite(typical) or typical > max(MISFIT_FACTOR * stated, MISFIT_PX):
            raise FormatError(
                path, f"does not fit these observations: camera '{name}' reprojects them {typical:.1f} px (typical, "
                f"per coordinate) where the result says {stated:.2f} px RMS (a result of another rig or take?)"
            )  # fmt: skip


def prepare(
    rig: RigSpec, observations: WandObservations, result_path: Path, document: dict[str, Any] | None = None
) -> ReportData:
    """Recompute residuals and statistics of a result file for the report.

    Args:
        document: the result as it was written (:func:`~wand_calib_ros.io.result_yaml.result_to_dict`), when a
            later calibration may replace ``result_path`` while the report is drawn; None: read ``result_path``.

    Raises:
        FormatError: the result does not describe the rig's cameras.
    """
    document = result_document(result_path) if document is None else document
    reference, geometry = result_geometry(document, result_path)
    names = rig.camera_names
    missing = [n for n in names if n not in geometry]
    if missing:
        raise FormatError(result_path, f"no result for camera(s) {', '.join(missing)} of the rig")
    models = tuple(geometry[n].model for n in names)
    poses = tuple(geometry[n].pose for n in names)
    obs = observations.select_cameras(names)
    complete = obs.complete
    rows = np.flatnonzero(complete.sum(axis=1) >= 2)
    uv = obs.uv[rows]
    line = timeline(obs).subset(rows)
    points = triangulate_placements(models, poses, align_views(uv, line))
    lengths = np.linalg.norm(points[:, -1] - points[:, 0], axis=-1)
    ok = np.all(np.isfinite(points), axis=(1, 2)) & (lengths > 0)
    camera_timing = np.array([[geometry[n].time_offset, geometry[n].readout] for n in names])
    timing = None
    if np.any(camera_timing) or not line.simultaneous:
        motion = smooth_motion(line.placement_times, points, line.period)
        if motion.continuous:
            ok &= motion.known
            heights = np.array([spec.image_size[1] for spec in rig.cameras], dtype=np.float64)
            timing = PlacementTiming(line.view_times, heights, motion.velocity, motion.acceleration, motion.jerk)
    uv, points, lengths, line = uv[ok], points[ok], lengths[ok], line.subset(ok)
    state = BundleState(models, poses, points[:, 0], wand_directions(points[:, 0], points[:, -1]), camera_timing)
    problem = BundleProblem.from_dense(rig.wand, uv, None if timing is None else timing.subset(ok))
    timed = _fit(state, problem)
    wand_points, res = timed.state.points(rig.wand), timed.residuals
    _require_fit(result_path, document, names, problem, res)
    world = wand_points[problem.placement, problem.point]
    sigma = float(document.get("metrics", {}).get("sigma_px", np.nan))
    off = rejected_views(uv, np.nan_to_num(res, nan=np.inf), VIEW_GATE_SIGMAS * sigma)
    rejected = off[problem.placement, problem.camera] if np.isfinite(sigma) else np.zeros(len(res), bool)
    cameras = []
    for c, pose in enumerate(poses):
        mine = problem.camera == c
        in_cam = pose.apply(world[mine])
        theta = np.arctan2(np.hypot(in_cam[:, 0], in_cam[:, 1]), in_cam[:, 2])
        cameras.append(CameraResiduals(problem.uv[mine], res[mine], theta, rejected[mine]))
    against = None
    if problem.timing is not None:
        static = _fit(replace(state, timing=None), replace(problem, timing=None)).residuals
        against = tuple(_against_velocity(uv, line, problem, c, static, res) for c in range(len(names)))
    shared = covisibility(complete)
    try:
        graph: VisionGraph | None = build_vision_graph(names, complete, reference=reference)
    except CoreError:
        graph = None
    estimates, events = session_history(result_path.parent)
    return ReportData(
        rig,
        names,
        models,
        poses,
        reference,
        document,
        tuple(cameras),
        wand_points,
        lengths,
        shared,
        graph,
        against,
        estimates,
        events,
    )


def _fit(state: BundleState, problem: BundleProblem) -> BundleResult:
    """The placements fitted with the cameras (and their timing) held fixed; NaN residuals if that fails."""
    try:
        return bundle_adjust(
            state, problem, np.zeros((len(state.models), N_CAMERA_PARAMS), dtype=bool), max_iterations=20
        )
    except CoreError:
        nan = np.full((problem.n_observations, 2), np.nan)
        return BundleResult(state, nan, 0, False, np.zeros((0, 0)), np.zeros((0, 0)), float("nan"), (0, 0))


def _against_velocity(
    uv: FloatArray, line: Timeline, problem: BundleProblem, camera: int, static: FloatArray, timed: FloatArray
) -> TimingResiduals:
    """One camera's residuals along its image velocity (from its own image track), px per frame."""
    seen = np.all(np.isfinite(uv[:, camera]), axis=(1, 2))
    velocity = np.full((uv.shape[0], 3, 2), np.nan)
    track = smooth_motion(line.placement_times[seen] + line.view_times[seen, camera], uv[seen, camera], line.period)
    velocity[seen] = np.where(track.known[:, None, None], track.velocity * line.period, np.nan)
    mine = problem.camera == camera
    v = velocity[problem.placement[mine], problem.point[mine]]
    speed = np.linalg.norm(v, axis=1)
    direction = v / np.where(speed > 0, speed, np.nan)[:, None]
    return TimingResiduals(speed, np.sum(static[mine] * direction, axis=1), np.sum(timed[mine] * direction, axis=1))
