"""Steps 1-3 of the paper for one camera pair, with the lens chosen by the data.

Every plausible Step 1 start (one classic projection per camera) goes through
Step 2 (essential matrix) and Step 3 (wand-length LM) on a spread subset of the
placements, paired with the other camera's best start; the combination with the
lowest wand-length RMS wins. A robust bundle adjustment of the pair (k1, k2,
principal points, pose) on more placements then makes the pair geometrically
consistent, since Step 3 matches wand lengths only.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_problem import BundleProblem, BundleState, default_free_mask
from wand_calib_ros.core.adjust.gating import robust_adjustment
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.errors import CoreError, DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.initialise.essential import RelativePose, epipolar_angles, relative_pose
from wand_calib_ros.core.initialise.intrinsics_init import initial_model, lens_candidates
from wand_calib_ros.core.initialise.two_markers import match_pair
from wand_calib_ros.core.initialise.wand_lm import WandFit, optimise_wand_lengths, wand_fit
from wand_calib_ros.core.model.camera_model import CameraModel, monotonic_limit, unproject
from wand_calib_ros.core.model.geometry import Pose, wand_directions
from wand_calib_ros.core.model.result import LensTrial
from wand_calib_ros.core.model.rig import CameraSpec, WandSpec, spread_subset

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)


#: A lens start whose fitted r(theta) turns over within this angle of the centre (rad) fails its trial.
FOLDED_RAD = float(np.radians(1.0))


@dataclass(frozen=True)
class PairOptions:
    """Settings of the pairwise initialisation.

    Attributes:
        ransac_threshold_px: RANSAC inlier threshold, as pixels at the nominal focal length
            (generous: the Step 1 intrinsics can be off by 20 % and 50 px).
        screening_placements: placements (spread over the recording) on which every lens start goes
            through Steps 2-3; the winner's Step 3 solution is the pair's initialisation.
        screening_evaluations: residual evaluations allowed per start in Step 3.
        pair_placements: placements (spread over the recording, agreeing with the winner's epipolar
            geometry) in the pair's bundle adjustment, which makes the pair consistent before chaining.
        min_placements: fewest placements both cameras must see completely.
        seed: seed of the RANSAC sampler.
    """

    ransac_threshold_px: float = 10.0
    screening_placements: int = 30
    screening_evaluations: int = 12
    pair_placements: int = 100
    min_placements: int = 15
    seed: int = 0


@dataclass(frozen=True, eq=False)
class PairInitialisation:
    """Pairwise calibration of cameras (0, 1).

    Attributes:
        models: intrinsics after the pair's bundle adjustment (k1, k2, principal point).
        pose: camera 1 relative to camera 0 after it.
        fit: the Step 3 solution it started from.
        projections: the Step 1 projection each camera started from.
        trials: every lens start tried and its Step 3 wand-length RMS.
    """

    models: tuple[CameraModel, CameraModel]
    pose: Pose
    fit: WandFit
    projections: tuple[str, str]
    trials: tuple[LensTrial, ...]


def check_motion(spec: CameraSpec, uv: FloatArray) -> None:
    """Refuse data in which the wand hardly moved or always points at the camera.

    Args:
        spec: the camera.
        uv: (N, K, 2) pixels of complete placements.

    Raises:
        DegenerateDataError: with what the user should change.
    """
    # Column by column: numpy's reductions along the first axis of a few columns cost 4-15x more here (30 checks of
    # about 9,000 placements on mocap16: 40 -> 10-12 ms).
    columns = uv.reshape(uv.shape[0], -1).T.copy()  # (2K, N): u, v of each marker in turn
    std = np.std(columns, axis=1).reshape(-1, 2)  # (K, 2)
    spread = float(np.max(np.hypot(std[:, 0], std[:, 1])))  # largest spread of A, B or C over placements
    diagonal = float(np.hypot(*spec.image_size))
    if spread < 0.02 * diagonal:
        raise DegenerateDataError(
            f"camera '{spec.name}': the wand hardly moved (its points spread over only {spread:.1f} px of a "
            f"{spec.image_size[0]} x {spec.image_size[1]} image); wave it through the whole view"
        )
    u, v = columns[0::2].reshape(-1), columns[1::2].reshape(-1)  # every marker's pixels
    u, v = u - u.mean(), v - v.mean()
    suu, suv, svv = float(u @ u) / u.size, float(u @ v) / u.size, float(v @ v) / u.size  # their 2 x 2 covariance
    smallest = (suu + svv) / 2 - float(np.hypot((suu - svv) / 2, suv))  # its smaller eigenvalue
    across = np.sqrt(max(smallest, 0.0))  # least spread
    if across < 0.01 * diagonal:
        raise DegenerateDataError(
            f"camera '{spec.name}': all wand points lie on one line in its image (spread across it "
            f"{across:.1f} px): the wand moved only along its own axis or in a plane seen edge-on; "
            "move and turn it through the whole volume"
        )
    image_length = np.sqrt(np.square(columns[-2] - columns[0]) + np.square(columns[-1] - columns[1]))  # |ac|, px
    if np.median(image_length) < 3.0:
        raise DegenerateDataError(
            f"camera '{spec.name}': the wand images as a dot (median |ac| {np.median(image_length):.1f} px); "
            "it points along the line of sight or is too far away"
        )


#: A camera's possible starts: (name of the start, its intrinsics).
Start = tuple[str, CameraModel]


def camera_starts(spec: CameraSpec, known: tuple[str, CameraModel] | None = None) -> list[Start]:
    """Step 1 starts of one camera: each plausible projection, or an already calibrated model."""
    if known is not None:
        return [known]
    return [(c.projection, initial_model(spec, c)) for c in lens_candidates(spec)]


def _step2(
    models: tuple[CameraModel, CameraModel], uv0: FloatArray, uv1: FloatArray, wand: WandSpec, options: PairOptions
) -> RelativePose:
    focal_px = min(float(np.min(m.focal_px)) for m in models)
    return relative_pose(
        unproject(models[0], uv0),
        unproject(models[1], uv1),
        wand.L,
        threshold_rad=options.ransac_threshold_px / focal_px,
        rng=np.random.default_rng(options.seed),
    )


def initialise_pair(
    specs: tuple[CameraSpec, CameraSpec],
    uv0: FloatArray,
    uv1: FloatArray,
    wand: WandSpec,
    options: PairOptions = PairOptions(),
    *,
    known: tuple[tuple[str, CameraModel] | None, tuple[str, CameraModel] | None] = (None, None),
) -> PairInitialisation:
    """Steps 1-3 for two cameras on the placements both see completely.

    Args:
        specs: the two cameras' descriptions.
        uv0, uv1: (N, K, 2) pixels of the markers in each camera (a two-marker wand's labels need not
            agree: camera 1's are matched to camera 0's first,
            :func:`~wand_calib_ros.core.initialise.two_markers.match_pair`).
        wand: wand lengths.
        options: settings.
        known: per camera, a (projection name, intrinsics) start from an earlier pair that
            replaces its Step 1 candidates (multi-camera chains). With both cameras started so, Step 3 is
            skipped: its wand-length fit of four intrinsics per camera only starts the pair's adjustment, and
            such lenses start it as well (mocap16's 15 pairs: 0.49 -> 0.26 s, every camera's errors the same).

    Raises:
        InsufficientDataError: fewer than ``options.min_placements`` placements.
        DegenerateDataError: the motion cannot determine the calibration.
    """
    uv1 = _checked_and_matched(specs, uv0, uv1, wand, options, known)
    n = uv0.shape[0]
    screening, spread = spread_subset(n, options.screening_placements), spread_subset(n, options.pair_placements)
    started = known[0] is not None and known[1] is not None
    screen = _Screening(specs, wand, options, uv0[screening], uv1[screening], uv0[spread], uv1[spread], spread, started)
    trials: list[LensTrial] = []
    tried: dict[tuple[str, str], tuple[WandFit, NDArray[np.int64]] | None] = {}

    def attempt(start0: Start, start1: Start) -> float:
        """Steps 2-3 (screening) for one pair of starts, once; returns its wand-length RMS (inf on failure)."""
        names = (start0[0], start1[0])
        if names not in tried:
            trial, tried[names] = _screened(screen, start0, start1)
            trials.append(trial)
        outcome = tried[names]
        return np.inf if outcome is None else outcome[0].rms_mm

    starts0, starts1 = camera_starts(specs[0], known[0]), camera_starts(specs[1], known[1])
    if replace(specs[1], name=specs[0].name) == specs[0] and known == (None, None):
        # Two cameras of one data sheet carry the same kind of lens: each projection on both.
        best0, best1 = min(zip(starts0, starts1, strict=True), key=lambda starts: attempt(*starts))
    else:
        # Each camera's candidates are tried with the other camera at its best start so far
        # (first camera 1's, then camera 0's): every plausible projection of each camera goes
        # through Steps 2-3, in |C0| + |C1| - 1 runs instead of |C0| x |C1|.
        best1 = min(starts1, key=lambda start: attempt(starts0[0], start))
        best0 = min(starts0, key=lambda start: attempt(start, best1))
    names = (best0[0], best1[0])
    best = tried[names]
    if best is None:
        reasons = "; ".join(f"{'/'.join(t.projections)}: {t.failure}" for t in trials)
        raise DegenerateDataError(
            f"cameras '{specs[0].name}' and '{specs[1].name}': no lens start gives a relative pose ({reasons})"
        )
    screened, use = best
    # The winner's Step 3 (on the screening placements) seeds a bundle adjustment of the pair
    # on a larger spread of the placements that agree with its epipolar geometry.
    models, pose = _pair_bundle(screened, uv0[use], uv1[use], wand)
    return PairInitialisation(models, pose, screened, names, tuple(trials))


def _checked_and_matched(
    specs: tuple[CameraSpec, CameraSpec],
    uv0: FloatArray,
    uv1: FloatArray,
    wand: WandSpec,
    options: PairOptions,
    known: tuple[tuple[str, CameraModel] | None, tuple[str, CameraModel] | None],
) -> FloatArray:
    """(N, K, 2) camera 1's pixels, its labels matched to camera 0's for a two-marker wand, once the pair's
    placements are checked to be enough and its motion to determine a calibration."""
    n = uv0.shape[0]
    if n < options.min_placements:
        raise InsufficientDataError(
            f"cameras '{specs[0].name}' and '{specs[1].name}' both see the whole wand in only {n} placements; "
            f"need at least {options.min_placements}"
        )
    for spec, uv in zip(specs, (uv0, uv1), strict=True):
        check_motion(spec, uv)
    if wand.n_points != 2:
        return uv1
    first = (camera_starts(specs[0], known[0])[0][1], camera_starts(specs[1], known[1])[0][1])
    focal_px = min(float(np.min(model.focal_px)) for model in first)
    threshold_rad = options.ransac_threshold_px / focal_px
    return match_pair(first, uv0, uv1, threshold_rad=threshold_rad, rng=np.random.default_rng(options.seed))


@dataclass(frozen=True, eq=False)
class _Screening:
    """What a pair's lens starts are screened on.

    Attributes:
        specs: the two cameras' descriptions.
        wand: the wand lengths.
        options: the pair's settings.
        s0, s1: (S, K, 2) the screening placements' pixels in each camera.
        spread0, spread1: (A, K, 2) the pixels of the placements the pair's bundle adjustment draws on.
        spread: (A,) those placements' indices.
        started: both lenses come from earlier pairs (Step 3 is skipped).
    """

    specs: tuple[CameraSpec, CameraSpec]
    wand: WandSpec
    options: PairOptions
    s0: FloatArray
    s1: FloatArray
    spread0: FloatArray
    spread1: FloatArray
    spread: NDArray[np.int64]
    started: bool


def _screened(
    screen: _Screening, start0: Start, start1: Start
) -> tuple[LensTrial, tuple[WandFit, NDArray[np.int64]] | None]:
    """Steps 2-3 on the screening placements for one pair of starts: its score, and its wand-length fit with the
    spread placements that agree with its epipolar geometry (None: it failed)."""
    names, models = (start0[0], start1[0]), (start0[1], start1[1])
    wand, options, s0, s1 = screen.wand, screen.options, screen.s0, screen.s1
    try:
        step2 = _step2(models, s0, s1, wand, options)
        agree = step2.inliers.reshape(-1, wand.n_points).all(axis=1)
        if screen.started:  # both lenses from earlier pairs: the pair's adjustment refines them, not Step 3
            fit = wand_fit(models, step2.pose, s0[agree], s1[agree], wand)
        else:
            fit = optimise_wand_lengths(models, step2.pose, s0[agree], s1[agree], wand,
                                        max_evaluations=options.screening_evaluations, tolerance=1e-4)  # fmt: skip
        folded = [s.name for s, m in zip(screen.specs, fit.models, strict=True) if monotonic_limit(m.k) < FOLDED_RAD]
        if folded:  # r(theta) falls from (nearly) the centre on: no lens images like that
            raise DegenerateDataError(f"the lens curve of {', '.join(folded)} turns over at the image centre")
    except CoreError as error:
        log.info("lens start %s: failed (%s)", "/".join(names), error)
        return LensTrial(names, float("nan"), str(error)), None
    log.info("lens start %s: wand-length RMS %.3f mm", "/".join(names), fit.rms_mm)
    agreeing = _epipolar_agreement(models, step2.essential, screen.spread0, screen.spread1, options)
    return LensTrial(names, fit.rms_mm), (fit, screen.spread[agreeing])


def _pair_bundle(
    fit: WandFit, uv0: FloatArray, uv1: FloatArray, wand: WandSpec
) -> tuple[tuple[CameraModel, CameraModel], Pose]:
    """A robust bundle adjustment of the pair on the Step 3 placements (k1, k2, principal points, pose).

    Step 3 only matches wand lengths, which leaves the rays of the two cameras
    slightly skew; this makes the pair geometrically consistent before poses
    are chained through the vision graph.
    """
    uv = np.stack([uv0, uv1], axis=1)
    points = triangulate_placements(fit.models, (Pose.identity(), fit.pose), uv)
    ok = np.all(np.isfinite(points), axis=(1, 2))
    if ok.sum() < 3:
        return fit.models, fit.pose
    state = BundleState(
        fit.models, (Pose.identity(), fit.pose), points[ok, 0], wand_directions(points[ok, 0], points[ok, -1])
    )
    problem = BundleProblem.from_dense(wand, uv[ok])
    free = default_free_mask(2)
    free[:, 2:5] = False
    try:
        result, _ = robust_adjustment(state, problem, free)
    except CoreError:
        return fit.models, fit.pose
    models = result.state.models
    return (models[0], models[1]), result.state.poses[1]


def _epipolar_agreement(
    models: tuple[CameraModel, CameraModel],
    essential: FloatArray,
    uv0: FloatArray,
    uv1: FloatArray,
    options: PairOptions,
) -> NDArray[np.bool_]:
    """(N,) placements whose markers all pass Step 2's RANSAC test under ``essential``."""
    angles = epipolar_angles(
        essential, unproject(models[0], uv0).reshape(-1, 3), unproject(models[1], uv1).reshape(-1, 3)
    )
    focal_px = min(float(np.min(m.focal_px)) for m in models)
    return np.asarray((angles < options.ransac_threshold_px / focal_px).reshape(-1, uv0.shape[1]).all(axis=1))
