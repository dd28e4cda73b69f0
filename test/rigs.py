"""Synthetic rigs with known truth (seeded) and the bundle adjustment started from the truth."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import (
    CAMERA_PARAM_NAMES,
    INTRINSICS,
    BundleProblem,
    BundleState,
    default_free_mask,
)
from wand_calib_ros.core.adjust.model_order import zeroed
from wand_calib_ros.core.judge.metrics import camera_errors, heldout_wand_rms, rereference
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
from wand_calib_ros.sim.clocks import TakeOptions, film, observe, take_trajectory
from wand_calib_ros.sim.scenarios import SCENARIOS, Scenario, SimulatedData, simulate

FloatArray = NDArray[np.float64]


@cache
def scenario_data(
    name: str, seed: int, noise: float = 1.0, heldout: int = 100, **kwargs: float | tuple[float, float]
) -> tuple[Scenario, SimulatedData, SimulatedData]:
    """A scenario, its observations and held-out placements (cached: treat as read-only)."""
    scenario = SCENARIOS[name](**kwargs)
    rng = np.random.default_rng(seed)
    data = simulate(scenario, noise, rng)
    held = simulate(scenario, noise, rng, n=heldout)
    return scenario, data, held


def truth_bundle(
    scenario: Scenario,
    data: SimulatedData,
    fixed: tuple[tuple[str, ...], ...] | None = None,
    *,
    held: bool = False,
    placements: NDArray[np.bool_] | None = None,
) -> BundleResult:
    """Bundle adjustment of the same data started from the truth.

    Args:
        scenario: the rig with its true cameras.
        data: the observations and true placements.
        fixed: per camera the terms held at zero (names of CAMERA_PARAM_NAMES, as the pipeline chose), or
            None for all free.
        held: every camera's intrinsics held at the truth (as given intrinsics are).
        placements: (P,) the placements to adjust (default all).
    """
    models = tuple(c.model for c in scenario.cameras)
    free = default_free_mask(len(scenario.cameras), 0, models)
    adjusted = []
    for c, model in enumerate(models):
        indices = [CAMERA_PARAM_NAMES.index(name) for name in (fixed[c] if fixed else ())]
        free[c, indices] = False
        adjusted.append(zeroed(model, indices))
    if held:
        free[:, INTRINSICS] = False
    use = np.ones(len(data.wand_a), dtype=bool) if placements is None else placements
    poses = tuple(c.pose for c in scenario.cameras)
    state = BundleState(tuple(adjusted), poses, data.wand_a[use], data.wand_direction[use])
    return bundle_adjust(state, BundleProblem.from_dense(scenario.wand, data.observations.uv[use]), free)


def fixed_of(result: CalibrationResult, scenario: Scenario) -> tuple[tuple[str, ...], ...]:
    """The pipeline's fixed coefficients in the scenario's camera order."""
    return tuple(result.camera(c.spec.name).fixed_coefficients for c in scenario.cameras)


def in_truth_frame(result: CalibrationResult, scenario: Scenario) -> tuple[list[CameraModel], list[Pose]]:
    """The result's cameras in scenario order, poses re-expressed in camera 0's frame like the truth."""
    names = [c.spec.name for c in scenario.cameras]
    poses = rereference({n: result.camera(n).pose for n in names}, names[0])
    return [result.camera(n).model for n in names], [poses[n] for n in names]


def errors_against_truth(
    scenario: Scenario,
    held: SimulatedData,
    models: list[CameraModel] | tuple[CameraModel, ...],
    poses: list[Pose] | tuple[Pose, ...],
) -> dict[str, float]:
    """Per camera focal and principal-point errors (px), E_r and E_t, and the held-out D_RMS (mm)."""
    out: dict[str, float] = {}
    for c, camera in enumerate(scenario.cameras):
        e = camera_errors(models[c], poses[c], camera.model, camera.pose)
        out[f"{camera.spec.name} focal"] = e.focal_px
        out[f"{camera.spec.name} principal point"] = e.principal_point_px
        if c > 0:
            out[f"{camera.spec.name} E_r"] = e.rotation_deg
            out[f"{camera.spec.name} E_t"] = e.translation
    out["D_RMS"] = heldout_wand_rms(tuple(models), tuple(poses), held.observations.uv, scenario.wand)
    return out


def true_views(drawn: WandObservations, observations: WandObservations) -> FloatArray:
    """(F, C, 3, 2) the drawn (true) pixels of the images ``observations`` holds, matched by camera and stamp."""
    assert drawn.stamps is not None and observations.stamps is not None
    out = np.full(observations.uv.shape, np.nan)
    for c, name in enumerate(observations.camera_names):
        d = drawn.camera_index(name)
        stamps = drawn.stamps[:, d]
        known = np.flatnonzero(np.isfinite(stamps))
        order = known[np.argsort(stamps[known])]
        mine = np.flatnonzero(np.isfinite(observations.stamps[:, c]))
        at = np.clip(np.searchsorted(stamps[order], observations.stamps[mine, c]), 0, order.size - 1)
        match = np.abs(stamps[order[at]] - observations.stamps[mine, c]) < 1e-6
        out[mine[match], c] = drawn.uv[order[at[match]], d]
    return out


def compare_with_true_projections(
    scenario: Scenario,
    drawn: WandObservations,
    observations: WandObservations,
    result: CalibrationResult,
    factor: float,
) -> list[str]:
    """What makes ``result`` worse than calibrating the true projections of the same views.

    The reference calibrates the drawn (true) pixels of the images ``observations`` holds, with
    Gaussian noise of the detection's own level. ``result`` must determine every camera's k1,
    u0, v0 within ``factor`` x the reference's standard deviations, lie within 4 of its own
    standard deviations of the truth, and reach a held-out wand-length error within
    ``factor`` x the reference's (averaged over four noise draws).

    Args:
        scenario: the rig with its true cameras.
        drawn: the true pixels of the recording's images (with their stamps).
        observations: what the nodes stored (frame ids of their own, the images' stamps).
        result: what they computed from it.
        factor: allowed ratio.

    Returns:
        One line per failed check (empty: as good as the data allows).
    """
    found = np.isfinite(observations.uv)
    truth = true_views(drawn, observations)  # the same images' true pixels (a swapped view stays swapped)
    inliers = found & (np.abs(observations.uv - truth) < 1.0)  # the detector's noise, without mistakes
    sigma = float(np.sqrt(np.mean((observations.uv - truth)[inliers] ** 2)))
    rng = np.random.default_rng(0)
    references = [
        calibrate(
            scenario.rig,
            observations.with_uv(np.where(found, truth + rng.normal(scale=sigma, size=found.shape), np.nan)),
        )
        for _ in range(4)
    ]  # one noise draw's D_RMS varies by about 2x: average four
    reference = references[0]
    failures = []
    for camera in scenario.cameras:
        mine, best = result.camera(camera.spec.name), reference.camera(camera.spec.name)
        true = {"k1": camera.model.k[0], "u0": camera.model.principal_point[0], "v0": camera.model.principal_point[1]}
        value = {"k1": mine.model.k[0], "u0": mine.model.principal_point[0], "v0": mine.model.principal_point[1]}
        for name in true:
            std = mine.parameter_std[name]
            if std > factor * best.parameter_std[name]:
                failures.append(f"{camera.spec.name} {name}: std {std:.3g} vs {best.parameter_std[name]:.3g}")
            if abs(value[name] - true[name]) > 4 * std:
                failures.append(f"{camera.spec.name} {name}: off by {value[name] - true[name]:.3g}, std {std:.3g}")
    held = simulate(scenario, 0.0, np.random.default_rng(99), n=200)
    mine_rms = errors_against_truth(scenario, held, *in_truth_frame(result, scenario))["D_RMS"]
    best_rms = float(
        np.mean([errors_against_truth(scenario, held, *in_truth_frame(r, scenario))["D_RMS"] for r in references])
    )
    if mine_rms > factor * best_rms:
        failures.append(f"held-out D_RMS {mine_rms:.3f} mm vs {best_rms:.3f} mm")
    return failures


@cache
def timed_take(name: str, seed: int, noise: float, options: TakeOptions) -> tuple[Scenario, WandObservations, tuple]:  # type: ignore[type-arg]
    """A continuous take of a scenario filmed with ``options``' clocks: (scenario, observations, clocks).

    The trajectory and the pixel noise depend on the seed only, so the same seed with other clocks
    films the same wave (a synchronised twin of a free-running take). The scenario returned has the
    volume the wand was waved in (held-out placements there judge the calibration where it has data).
    """
    scenario = SCENARIOS[name]()
    trajectory = take_trajectory(scenario, options, np.random.default_rng(seed))
    clocks = options.clocks(len(scenario.cameras), np.random.default_rng(seed + 1))
    takes = film(scenario, trajectory, clocks, options.duration_s, np.random.default_rng(seed + 2))
    observations = observe(scenario.rig.camera_names, takes, noise, np.random.default_rng(seed + 3))
    waved = np.stack([trajectory.middle - trajectory.half, trajectory.middle + trajectory.half])
    return replace(scenario, volume=waved), observations, clocks


#: The errors of a calibration against the truth that :func:`truth_errors` gives.
TRUTH_MEASURES = ("focal", "principal point", "curve", "E_r", "E_t", "D_RMS")


def truth_errors(result: CalibrationResult, scenario: Scenario) -> dict[str, list[float]]:
    """Errors of a calibration against the scenario's truth, in its reference frame, per :data:`TRUTH_MEASURES`:
    focal, principal point, curve (px, every camera), E_r (deg), E_t (cameras but the first), D_RMS (mm, 200
    held-out noise-free placements in the scenario's volume)."""
    models, poses = in_truth_frame(result, scenario)
    out: dict[str, list[float]] = {k: [] for k in TRUTH_MEASURES}
    for c, camera in enumerate(scenario.cameras):
        e = camera_errors(models[c], poses[c], camera.model, camera.pose)
        out["focal"].append(e.focal_px)
        out["principal point"].append(e.principal_point_px)
        out["curve"].append(e.curve_px)
        if c > 0:
            out["E_r"].append(e.rotation_deg)
            out["E_t"].append(e.translation)
    held = simulate(scenario, 0.0, np.random.default_rng(99), n=200)
    out["D_RMS"].append(heldout_wand_rms(tuple(models), tuple(poses), held.observations.uv, scenario.wand))
    return out


@cache
def timed_calibration(
    name: str, seed: int, noise: float, options: TakeOptions, timing: tuple[str, str] = ("auto", "auto")
) -> dict[str, list[float]]:
    """Errors against the truth of calibrating a :func:`timed_take` (pooled over cameras per metric).

    Keys: focal, principal point, curve (px, every camera), E_r (deg), E_t (cameras but the first),
    D_RMS (mm, held-out noise-free placements), and for free-running clocks the errors of the time
    offsets between cameras (s, cameras but the reference) and of the readout times (s, every
    camera) with their z-scores (error / reported standard deviation), and the z-scores of every
    camera's k1, u0, v0.
    """
    scenario, observations, clocks = timed_take(name, seed, noise, options)
    result = calibrate(
        scenario.rig, observations, CalibrationOptions(time_offsets=timing[0], rolling_shutter=timing[1])
    )
    out = truth_errors(result, scenario)
    latency = {n: clock.latency_s for n, clock in zip(scenario.rig.camera_names, clocks, strict=True)}
    readout = {n: clock.readout_s for n, clock in zip(scenario.rig.camera_names, clocks, strict=True)}
    for key in ("offset", "offset z", "readout", "readout z", "intrinsics z"):
        out[key] = []
    z = z_scores(result, scenario)
    out["intrinsics z"] = z["focal"] + z["principal point"]
    for camera in result.cameras:
        std = camera.parameter_std
        if camera.name != result.reference_camera:
            error = camera.time_offset - (latency[camera.name] - latency[result.reference_camera])
            out["offset"].append(error)
            out["offset z"].append(error / std["time_offset"] if "time_offset" in std else (np.inf if error else 0.0))
        error = camera.readout - readout[camera.name]
        out["readout"].append(error)
        out["readout z"].append(error / std["readout"] if "readout" in std else (np.inf if error else 0.0))
    return out


def rms(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


#: The floor tool of the floor tests and benchmark: an L-frame of three markers, 500 x 300 mm.
L_FRAME = np.array([[0.0, 0.0, 0.0], [500.0, 0.0, 0.0], [0.0, 300.0, 0.0]])
#: Placements of the rigs the floor is measured on (ring6: six mixed cameras on a 2.5 m ring; mocap16).
FLOOR_PLACEMENTS = {"ring6": 2000, "mocap16": 10_000}


@cache
def floor_rig(name: str, seed: int) -> tuple[Scenario, CalibrationResult]:
    """A floor rig calibrated at 1 px, the truth's reference camera kept (cached: treat as read-only)."""
    scenario = SCENARIOS[name](n_placements=FLOOR_PLACEMENTS[name])
    data = simulate(scenario, 1.0, np.random.default_rng(seed))
    reference = scenario.cameras[0].spec.name  # the truth's frame
    return scenario, calibrate(scenario.rig, data.observations, CalibrationOptions(reference_camera=reference))


def floor_errors(name: str, *, tool: bool, seeds: range) -> dict[str, float]:
    """RMS over seeds of :func:`~wand_calib_ros.sim.floor.world_errors`: two lays of 15 still frames, or the
    L-frame seen in 15 frames with its points in any order per view, at 1 px."""
    from wand_calib_ros.core.after.world_frame import floor_of
    from wand_calib_ros.sim.floor import floor_lays, floor_tool, shuffled, world_errors

    rows = []
    for seed in seeds:
        scenario, result = floor_rig(name, seed)
        rng = np.random.default_rng([seed, 1])
        truth = floor_tool(scenario, L_FRAME, 1.0, rng) if tool else floor_lays(scenario, 1.0, rng)
        names = [c.spec.name for c in scenario.cameras]
        assert result.camera_covariance is not None
        floor = floor_of(
            tuple(result.camera(n).model for n in names),
            tuple(result.camera(n).pose for n in names),
            shuffled(truth, rng) if tool else truth.observations.uv,
            result.camera_covariance,
            result.sigma_px,
            positions_mm=scenario.wand.positions_mm,
            tool_mm=L_FRAME if tool else None,
        )
        rows.append(world_errors(scenario, floor.world, floor.models, floor.poses, truth))
    return {key: rms([row[key] for row in rows]) for key in rows[0]}


def z_scores(result: CalibrationResult, scenario: Scenario) -> dict[str, list[float]]:
    """Errors over reported standard deviations, pooled by kind: ``focal`` (k1), ``principal point`` (u0, v0;
    of the cameras whose intrinsics were estimated), ``rotation`` (the adjustment's left-multiplied update,
    rx ry rz) and ``translation`` (tx ty tz) of every camera but the reference, in its frame."""
    from wand_calib_ros.core.model.geometry import rotvec_from_rotation

    reference = result.reference_camera
    truth = rereference({c.spec.name: c.pose for c in scenario.cameras}, reference)
    out: dict[str, list[float]] = {"focal": [], "principal point": [], "rotation": [], "translation": []}
    for camera in scenario.cameras:
        mine = result.camera(camera.spec.name)
        std = mine.parameter_std
        if "k1" in std:
            out["focal"].append((mine.model.k[0] - camera.model.k[0]) / std["k1"])
            out["principal point"].extend(
                (mine.model.principal_point - camera.model.principal_point) / np.array([std["u0"], std["v0"]])
            )
        if camera.spec.name != reference:
            true = truth[camera.spec.name]
            error = rotvec_from_rotation(mine.pose.rotation @ true.rotation.T)
            out["rotation"].extend(error / np.array([std["rx"], std["ry"], std["rz"]]))
            out["translation"].extend(
                (mine.pose.translation - true.translation) / np.array([std["tx"], std["ty"], std["tz"]])
            )
    return out
