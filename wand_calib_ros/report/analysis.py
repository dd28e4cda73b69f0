"""What a calibration report shows, computed from the result, the rig and the observations.

The residuals are those of the result's cameras: every placement is
triangulated and its wand parameters are fitted with the cameras held fixed,
so the report can be made for any result file, also one from another run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from wand_calib_ros.core.bundle_adjustment import N_CAMERA_PARAMS, BundleProblem, BundleState, bundle_adjust
from wand_calib_ros.core.camera_model import CameraModel
from wand_calib_ros.core.errors import CoreError
from wand_calib_ros.core.geometry import Pose, wand_directions
from wand_calib_ros.core.refine import triangulate_placements
from wand_calib_ros.core.rig import RigSpec, WandObservations
from wand_calib_ros.core.vision_graph import VisionGraph, build_vision_graph, covisibility
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.result_yaml import read_result

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class CameraResiduals:
    """One camera's observations and reprojection residuals.

    Attributes:
        uv: (N, 2) observed pixels.
        residuals: (N, 2) projected minus observed, px.
        theta: (N,) off-axis angle of each observed point, rad.
    """

    uv: FloatArray
    residuals: FloatArray
    theta: FloatArray


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


def prepare(rig: RigSpec, observations: WandObservations, result_path: Path) -> ReportData:
    """Recompute residuals and statistics of a result file for the report.

    Raises:
        FormatError: the result does not describe the rig's cameras.
    """
    reference, geometry = read_result(result_path)
    document = yaml.safe_load(Path(result_path).read_text())
    names = rig.camera_names
    missing = [n for n in names if n not in geometry]
    if missing:
        raise FormatError(result_path, f"no result for camera(s) {', '.join(missing)} of the rig")
    models = tuple(geometry[n].model for n in names)
    poses = tuple(geometry[n].pose for n in names)
    obs = observations.select_cameras(names)
    complete = obs.complete
    uv = obs.uv[complete.sum(axis=1) >= 2]
    points = triangulate_placements(models, poses, uv)
    lengths = np.linalg.norm(points[:, 2] - points[:, 0], axis=-1)
    ok = np.all(np.isfinite(points), axis=(1, 2)) & (lengths > 0)
    uv, points, lengths = uv[ok], points[ok], lengths[ok]
    state = BundleState(models, poses, points[:, 0], wand_directions(points[:, 0], points[:, 2]))
    problem = BundleProblem.from_dense(rig.wand, uv)
    try:
        fitted = bundle_adjust(state, problem, np.zeros((len(names), N_CAMERA_PARAMS), dtype=bool), max_iterations=20)
        wand_points, res = fitted.state.points(rig.wand), fitted.residuals
    except CoreError:
        wand_points = state.points(rig.wand)
        res = np.full((problem.n_observations, 2), np.nan)
    world = wand_points[problem.placement, problem.point]
    cameras = []
    for c, pose in enumerate(poses):
        mine = problem.camera == c
        in_cam = pose.apply(world[mine])
        theta = np.arctan2(np.hypot(in_cam[:, 0], in_cam[:, 1]), in_cam[:, 2])
        cameras.append(CameraResiduals(problem.uv[mine], res[mine], theta))
    shared = covisibility(complete)
    try:
        graph: VisionGraph | None = build_vision_graph(names, complete, reference=reference)
    except CoreError:
        graph = None
    return ReportData(
        rig, names, models, poses, reference, document, tuple(cameras), wand_points, lengths, shared, graph
    )
