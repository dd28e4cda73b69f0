"""Wand calibration against the checkerboard baseline, in the style of the paper's Tables 1-4.

For a simulated rig both methods see the same cameras with the same pixel
noise; errors are measured against the truth and the wand-length error D_RMS
on the same held-out wand placements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wand_calib_ros.core.judge.metrics import camera_errors, heldout_wand_rms, rereference
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.checkerboard import calibrate_checkerboard
from wand_calib_ros.sim.scenarios import SCENARIOS, Scenario, simulate

#: The paper's Tables 1-4: two conventional, two fisheye, mixed pair, three cameras.
TABLE_SCENARIOS = ("conventional", "paper", "mixed", "paper3")


@dataclass(frozen=True, eq=False)
class MethodResult:
    """One method's cameras (poses relative to camera 0) and the held-out wand-length error."""

    method: str
    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    rms_px: tuple[float, ...]
    d_rms_mm: float


@dataclass(frozen=True, eq=False)
class Comparison:
    """Both methods on one simulated rig."""

    scenario: Scenario
    noise_px: float
    methods: tuple[MethodResult, ...]


def compare(name: str, seed: int, noise_px: float = 1.0, *, board_views: int = 15) -> Comparison:
    """Calibrate one simulated rig with the wand and with the checkerboard baseline."""
    scenario = SCENARIOS[name]()
    rng = np.random.default_rng(seed)
    data = simulate(scenario, noise_px, rng)
    held = simulate(scenario, noise_px, rng, n=100).observations.uv
    names = [c.spec.name for c in scenario.cameras]
    result = calibrate(scenario.rig, data.observations)
    poses = rereference({n: result.camera(n).pose for n in names}, names[0])
    wand_models = tuple(result.camera(n).model for n in names)
    wand_poses = tuple(poses[n] for n in names)
    wand = MethodResult(
        "wand (proposed)",
        wand_models,
        wand_poses,
        tuple(result.camera(n).rms_reprojection_px for n in names),
        heldout_wand_rms(wand_models, wand_poses, held, scenario.wand),
    )
    board = calibrate_checkerboard(scenario, noise_px, rng, intrinsic=board_views, stereo=board_views)
    checker = MethodResult(
        "checkerboard (OpenCV fisheye)",
        board.models,
        board.poses,
        board.rms_px,
        heldout_wand_rms(board.models, board.poses, held, scenario.wand),
    )
    return Comparison(scenario, noise_px, (wand, checker))


def _vector(values: np.ndarray, digits: int = 4) -> str:
    return "[" + ", ".join(f"{v:.{digits}g}" for v in values) + "]"


def markdown_table(comparison: Comparison) -> str:
    """A table like the paper's: parameters per camera for the truth and each method, then E_RMS and D_RMS."""
    scenario = comparison.scenario
    methods = comparison.methods
    head = "| | " + " | ".join(["truth", *[m.method for m in methods]]) + " |"
    lines = [head, "|" + "---|" * (len(methods) + 2)]
    for c, camera in enumerate(scenario.cameras):
        name = camera.spec.name
        rows = {
            f"{name} k1 (mm)": [camera.model.k[0], *[m.models[c].k[0] for m in methods]],
            f"{name} k2 (mm)": [camera.model.k[1], *[m.models[c].k[1] for m in methods]],
            f"{name} u0 (px)": [camera.model.principal_point[0], *[m.models[c].principal_point[0] for m in methods]],
            f"{name} v0 (px)": [camera.model.principal_point[1], *[m.models[c].principal_point[1] for m in methods]],
        }
        for label, values in rows.items():
            lines.append(f"| {label} | " + " | ".join(f"{v:.4f}" for v in values) + " |")
        if c > 0:
            lines.append(
                f"| {name} R (rotvec) | "
                + " | ".join(_vector(p.rotvec) for p in [camera.pose, *[m.poses[c] for m in methods]])
                + " |"
            )
            lines.append(
                f"| {name} T (mm) | "
                + " | ".join(_vector(p.translation, 6) for p in [camera.pose, *[m.poses[c] for m in methods]])
                + " |"
            )
        lines.append(f"| {name} E_RMS (px) | - | " + " | ".join(f"{m.rms_px[c]:.3f}" for m in methods) + " |")
    lines.append("| D_RMS held-out (mm) | - | " + " | ".join(f"{m.d_rms_mm:.3f}" for m in methods) + " |")
    return "\n".join(lines)


def error_summary(comparisons: list[Comparison]) -> dict[str, dict[str, float]]:
    """Per method RMS over runs and cameras of focal (px), principal point (px), E_r (deg), E_t, D_RMS (mm)."""
    sums: dict[str, dict[str, list[float]]] = {}
    for comparison in comparisons:
        for method in comparison.methods:
            acc = sums.setdefault(method.method, {k: [] for k in ("focal", "pp", "E_r", "E_t", "D_RMS")})
            for c, camera in enumerate(comparison.scenario.cameras):
                e = camera_errors(method.models[c], method.poses[c], camera.model, camera.pose)
                acc["focal"].append(e.focal_px)
                acc["pp"].append(e.principal_point_px)
                if c > 0:
                    acc["E_r"].append(e.rotation_deg)
                    acc["E_t"].append(e.translation)
            acc["D_RMS"].append(method.d_rms_mm)
    return {m: {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in acc.items()} for m, acc in sums.items()}
