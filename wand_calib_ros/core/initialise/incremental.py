"""Cameras whose intrinsics are known placed one by one: the start of a sparse take.

The paper's Steps 1-3 estimate a pair's intrinsics from the views it shares, which takes many
(:attr:`~wand_calib_ros.core.initialise.pairwise.PairOptions.min_placements`). With the intrinsics known (a board
calibration given, or the nominal lens for a start the bundle adjustment then corrects) a pair needs
only what its relative pose needs, and a camera can be placed from views it shares with two or more
cameras already placed. Cameras are placed one at a time:

- the seed: the pair sharing the most views of the whole wand; its relative pose from Nister's
  5-point essential matrix fitted robustly (MSAC over minimal samples of views) on the markers'
  bearings, scaled by the wand's length;
- then, while a camera is unplaced, the one with the most support: **resection**, its views of wand
  markers that placed cameras triangulate (a perspective-n-point fit, robust: views that three or more
  cameras share), or its **relative pose** to one placed camera (as the seed's) where that has more;
- after each, the placed cameras' poses are adjusted (robust, intrinsics held).

A two-marker wand's labels may differ from view to view (another tool's points): every fit chooses per
view the pairing of markers that fits it, and the views are relabelled accordingly. A camera that
cannot be placed is refused with what it has and what would be enough.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS, BundleProblem, BundleState
from wand_calib_ros.core.adjust.gating import robust_adjustment
from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.errors import CoreError, DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.initialise.essential import (
    decompose_essential,
    epipolar_angles,
    linear_essential,
    minimal_solutions,
    wand_scale,
)
from wand_calib_ros.core.initialise.two_markers import swapped
from wand_calib_ros.core.initialise.vision_graph import covisibility
from wand_calib_ros.core.model.camera_model import N_INTRINSIC, CameraModel, unproject
from wand_calib_ros.core.model.geometry import Pose, skew, wand_directions
from wand_calib_ros.core.model.rig import RigSpec, WandSpec

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
log = logging.getLogger(__name__)

#: Marker correspondences a relative pose needs: 5 for the minimal solver and 2 that check it.
MIN_PAIR_POINTS = 7
#: Wand points a resection needs: 4 for the fit and 1 that checks it.
MIN_RESECTION_POINTS = 5
#: Minimal samples tried at most per fit, and the confidence at which fewer suffice.
MAX_SAMPLES = 400
CONFIDENCE = 0.999
#: Bearings nearer than this to a camera's image plane (z of the unit bearing) stay out of resection
#: samples (the perspective-n-point fit takes normalised image coordinates).
MIN_BEARING_Z = 0.15


@dataclass(frozen=True, eq=False)
class Fit:
    """A camera placed relative to others.

    Attributes:
        pose: X_cam = R X_ref + T (mm) in the frame of the placed cameras.
        swapped: (N,) per view fitted, whether its two markers' labels were exchanged (two-marker wand).
        rows: (N,) the placements those views belong to.
        inliers: wand points within the threshold.
    """

    pose: Pose
    swapped: BoolArray
    rows: NDArray[np.int64]
    inliers: int


def _samples(n: int, size: int, rng: np.random.Generator) -> list[tuple[int, ...]]:
    """Minimal samples of ``size`` of ``n`` items: all of them (shuffled) when few, else MAX_SAMPLES drawn."""
    count = 1
    for i in range(size):
        count = count * (n - i) // (i + 1)
    if count <= MAX_SAMPLES:
        every = list(itertools.combinations(range(n), size))
        order = rng.permutation(len(every))
        return [every[i] for i in order]
    return [tuple(int(v) for v in rng.choice(n, size, replace=False)) for _ in range(MAX_SAMPLES)]


def _needed(inlier_fraction: float, size: int) -> float:
    """Samples after which an all-inlier one was drawn with CONFIDENCE."""
    fail = 1.0 - inlier_fraction**size
    if fail <= 0:
        return 0.0
    return float(np.log(1.0 - CONFIDENCE) / np.log(max(fail, 1e-12)))


def _pair_errors(
    essential: FloatArray, b0: FloatArray, b1: FloatArray, ambiguous: bool
) -> tuple[FloatArray, BoolArray]:
    """(N, K) epipolar angles of each view pair's markers in the better pairing, and (N,) which is crossed."""
    n, k = b0.shape[:2]
    straight = epipolar_angles(essential, b0.reshape(-1, 3), b1.reshape(-1, 3)).reshape(n, k)
    if not ambiguous:
        return straight, np.zeros(n, dtype=bool)
    crossed = epipolar_angles(essential, b0.reshape(-1, 3), b1[:, ::-1].reshape(-1, 3)).reshape(n, k)
    swap = crossed.sum(axis=1) < straight.sum(axis=1)
    return np.where(swap[:, None], crossed, straight), swap


def pair_pose(
    b0: FloatArray, b1: FloatArray, wand: WandSpec, *, threshold_rad: float, rng: np.random.Generator
) -> Fit | None:
    """Camera 1 relative to camera 0 from views of the whole wand both have (intrinsics known).

    Args:
        b0, b1: (N, K, 3) unit bearings of the K markers in each camera's view of N placements.
        wand: the wand (its length scales the pose; two markers: labels may differ per view).
        threshold_rad: inlier threshold on the epipolar angle.
        rng: seeded generator.

    Returns:
        The fit (``rows`` index the N views), or None when the views cannot determine one.
    """
    n, k = b0.shape[:2]
    ambiguous = k == 2
    size = 3 if k == 2 else 2  # views per minimal sample: 5 correspondences
    if n < size or n * k < MIN_PAIR_POINTS:
        return None
    combos = list(itertools.product((False, True), repeat=size)) if ambiguous else [(False,) * size]
    best_score, best_e = np.inf, None
    needed: float = MAX_SAMPLES
    for tried, sample in enumerate(_samples(n, size, rng)):
        if tried >= needed:
            break
        index = np.array(sample)
        for combo in combos:
            m0 = b0[index].reshape(-1, 3)[:5]
            m1 = swapped(b1[index], np.array(combo)).reshape(-1, 3)[:5]
            for essential in minimal_solutions(m0, m1):
                errors, _ = _pair_errors(essential, b0, b1, ambiguous)
                score = float(np.sum(np.minimum(errors, threshold_rad) ** 2))
                if score < best_score:
                    best_score, best_e = score, essential
                    whole = np.all(errors < threshold_rad, axis=1)
                    needed = _needed(float(whole.mean()), size)
    if best_e is None:
        return None
    essential = best_e
    errors, swap = _pair_errors(essential, b0, b1, ambiguous)
    inlier = np.all(errors < threshold_rad, axis=1)
    if inlier.sum() * k >= 8:  # the linear refit needs eight correspondences
        refined = linear_essential(b0[inlier].reshape(-1, 3), swapped(b1, swap)[inlier].reshape(-1, 3))
        errors_r, swap_r = _pair_errors(refined, b0, b1, ambiguous)
        if np.all(errors_r < threshold_rad, axis=1).sum() >= inlier.sum():
            essential, errors, swap = refined, errors_r, swap_r
            inlier = np.all(errors < threshold_rad, axis=1)
    if inlier.sum() * k < MIN_PAIR_POINTS:
        return None
    paired = swapped(b1, swap)
    unit, front = decompose_essential(essential, b0[inlier].reshape(-1, 3), paired[inlier].reshape(-1, 3))
    if front < 0.8 * inlier.sum() * k:
        return None
    try:
        scale, _ = wand_scale(unit, b0[inlier], paired[inlier], wand.L)
    except DegenerateDataError:  # no placement triangulates
        return None
    pose = Pose(unit.rotation, unit.translation * scale)
    return Fit(pose, swap, np.arange(n), int(inlier.sum() * k))


def _resection_errors(
    pose: Pose, bearings: FloatArray, points: FloatArray, ambiguous: bool
) -> tuple[FloatArray, BoolArray]:
    """(N, K) angles between each view's bearings and its placement's markers seen from ``pose`` (NaN where
    a marker is unseen), in the better pairing, and (N,) which is crossed."""
    toward = pose.apply(points)
    toward /= np.linalg.norm(toward, axis=-1, keepdims=True)
    straight = np.arccos(np.clip(np.sum(bearings * toward, axis=-1), -1.0, 1.0))
    if not ambiguous:
        return straight, np.zeros(len(points), dtype=bool)
    crossed = np.arccos(np.clip(np.sum(bearings[:, ::-1] * toward, axis=-1), -1.0, 1.0))
    swap = np.nansum(crossed, axis=1) < np.nansum(straight, axis=1)
    return np.where(swap[:, None], crossed, straight), swap


def _pnp(bearings: FloatArray, points: FloatArray) -> Pose | None:
    """The pose of (M, 3) unit bearings of (M, 3) known points (SQPnP on normalised coordinates)."""
    usable = bearings[:, 2] > MIN_BEARING_Z
    if usable.sum() < 4:
        return None
    image = np.ascontiguousarray(bearings[usable, :2] / bearings[usable, 2:])
    try:
        ok, rvec, tvec = cv2.solvePnP(
            np.ascontiguousarray(points[usable]), image, np.eye(3), None, flags=cv2.SOLVEPNP_SQPNP
        )
    except cv2.error:
        return None
    if not ok or not np.all(np.isfinite(rvec)) or not np.all(np.isfinite(tvec)):
        return None
    return Pose.from_rotvec(np.asarray(rvec, dtype=np.float64).ravel(), np.asarray(tvec, dtype=np.float64).ravel())


def resect(bearings: FloatArray, points: FloatArray, *, threshold_rad: float, rng: np.random.Generator) -> Fit | None:
    """A camera's pose from its views of placements whose markers are known (triangulated by others).

    Args:
        bearings: (N, K, 3) unit bearings of the camera's views (NaN for a marker it did not see).
        points: (N, K, 3) the placements' markers in the reference frame, mm.
        threshold_rad: inlier threshold on the angle between a bearing and its marker's direction.
        rng: seeded generator.

    Returns:
        The fit (``rows`` index the N views), or None when the views cannot determine one.
    """
    n, k = bearings.shape[:2]
    ambiguous = k == 2
    seen = np.all(np.isfinite(bearings), axis=-1)
    whole = np.flatnonzero(seen.all(axis=1))
    if int(seen.sum()) < MIN_RESECTION_POINTS or whole.size * k < 4:
        return None
    size = -(-4 // k)  # whole views per sample: 4 wand points or more
    combos = list(itertools.product((False, True), repeat=size)) if ambiguous else [(False,) * size]
    best_score, best_pose = np.inf, None
    needed: float = MAX_SAMPLES
    for tried, sample in enumerate(_samples(whole.size, size, rng)):
        if tried >= needed:
            break
        index = whole[np.array(sample)]
        for combo in combos:
            pose = _pnp(swapped(bearings[index], np.array(combo)).reshape(-1, 3), points[index].reshape(-1, 3))
            if pose is None:
                continue
            errors, _ = _resection_errors(pose, bearings, points, ambiguous)
            score = float(np.nansum(np.minimum(errors, threshold_rad) ** 2))
            if score < best_score:
                best_score, best_pose = score, pose
                needed = _needed(float(np.mean(np.all(errors[whole] < threshold_rad, axis=1))), size)
    if best_pose is None:
        return None
    errors, swap = _resection_errors(best_pose, bearings, points, ambiguous)
    inlier = seen & (errors < threshold_rad)
    if inlier.sum() < MIN_RESECTION_POINTS:
        return None
    refit = _pnp(swapped(bearings, swap)[inlier], points[inlier])
    if refit is not None:
        errors_r, swap_r = _resection_errors(refit, bearings, points, ambiguous)
        inlier_r = seen & (errors_r < threshold_rad)
        if inlier_r.sum() >= inlier.sum():
            best_pose, swap, inlier = refit, swap_r, inlier_r
    return Fit(best_pose, swap, np.arange(n), int(inlier.sum()))


@dataclass
class _Placing:
    """The state of the placing: which cameras are placed, where, and the views relabelled so far."""

    rig: RigSpec
    models: tuple[CameraModel, ...]
    bearings: FloatArray  # (P, C, K, 3)
    uv: FloatArray  # (P, C, K, 2), relabelled as the fits decide
    poses: list[Pose | None]
    threshold_rad: float
    rng: np.random.Generator

    @property
    def placed(self) -> list[int]:
        return [c for c, pose in enumerate(self.poses) if pose is not None]

    @property
    def complete(self) -> BoolArray:
        return np.all(np.isfinite(self.uv), axis=(2, 3))

    def apply(self, camera: int, fit: Fit, rows: NDArray[np.int64]) -> None:
        """Place ``camera`` at the fit's pose and relabel the views it fitted (``rows``: their placements)."""
        self.poses[camera] = fit.pose
        swap = rows[fit.swapped]
        self.uv[swap, camera] = self.uv[swap, camera, ::-1]
        self.bearings[swap, camera] = self.bearings[swap, camera, ::-1]
        self.relabel(camera)

    def relabel(self, camera: int) -> None:
        """The camera's views of placements another placed camera sees whole, labelled as that one's
        (the pairing with the smaller epipolar error; two-marker wand only)."""
        if self.uv.shape[2] != 2:
            return
        pose = self.poses[camera]
        assert pose is not None
        complete = self.complete
        for other in self.placed:
            if other == camera:
                continue
            rows = np.flatnonzero(complete[:, camera] & complete[:, other])
            other_pose = self.poses[other]
            assert other_pose is not None
            relative = pose.compose(other_pose.inverse())
            essential = skew(relative.translation) @ relative.rotation
            _, swap = _pair_errors(essential, self.bearings[rows, other], self.bearings[rows, camera], True)
            flip = rows[swap]
            self.uv[flip, camera] = self.uv[flip, camera, ::-1]
            self.bearings[flip, camera] = self.bearings[flip, camera, ::-1]

    def points(self) -> FloatArray:
        """(P, K, 3) the markers the placed cameras' whole views triangulate (NaN elsewhere)."""
        placed = self.placed
        uv = np.where(self.complete[:, placed, None, None], self.uv[:, placed], np.nan)
        poses = tuple(self.poses[c] for c in placed)
        return triangulate_placements(tuple(self.models[c] for c in placed), poses, uv)  # type: ignore[arg-type]

    def adjust(self, fixed: int) -> None:
        """A robust adjustment of the placed cameras' poses (intrinsics held; ``fixed`` holds the frame)."""
        placed = self.placed
        points = self.points()
        complete = self.complete[:, placed]
        rows = np.flatnonzero((complete.sum(axis=1) >= 2) & np.all(np.isfinite(points), axis=(1, 2)))
        if rows.size < 3:
            return
        uv = np.full(self.uv[rows].shape, np.nan)
        uv[:, placed] = np.where(complete[rows, :, None, None], self.uv[rows][:, placed], np.nan)
        poses = tuple(pose if pose is not None else Pose.identity() for pose in self.poses)
        state = BundleState(self.models, poses, points[rows, 0], wand_directions(points[rows, 0], points[rows, -1]))
        free = np.zeros((len(self.models), N_CAMERA_PARAMS), dtype=bool)
        free[placed, N_INTRINSIC : N_INTRINSIC + 6] = True
        free[fixed] = False
        try:
            result, _ = robust_adjustment(state, BundleProblem.from_dense(self.rig.wand, uv), free)
        except CoreError as error:
            log.info("adjusting the placed cameras failed (%s): their poses stay", error)
            return
        for c in placed:
            self.poses[c] = result.state.poses[c]


def place_cameras(
    rig: RigSpec,
    uv: FloatArray,
    models: tuple[CameraModel, ...],
    reference: int,
    *,
    threshold_rad: float,
    seed: int = 0,
) -> tuple[Pose, ...]:
    """Every camera's pose from its known intrinsics, placed one by one (see the module docstring).

    Args:
        rig: the rig description (cameras in the order of ``uv``'s axis 1).
        uv: (P, C, K, 2) pixels, NaN where not seen (a two-marker wand's labels may differ per view).
        models: each camera's intrinsics.
        reference: the camera whose frame the poses are returned in.
        threshold_rad: inlier threshold of the fits (an angle).
        seed: of the samplers.

    Returns:
        The poses, X_cam = R X_ref + T (mm); a two-marker wand's labels are settled from them
        (:func:`~wand_calib_ros.core.initialise.two_markers.consistent_labels`).

    Raises:
        InsufficientDataError: a camera that cannot be placed, with what it has and what would do.
    """
    names = rig.camera_names
    n_cameras, k = uv.shape[1], uv.shape[2]
    bearings = np.stack([unproject(models[c], uv[:, c]) for c in range(n_cameras)], axis=1)
    bearings = np.where(np.isfinite(uv).all(axis=-1, keepdims=True), bearings, np.nan)
    state = _Placing(rig, models, bearings, uv.copy(), [None] * n_cameras, threshold_rad, np.random.default_rng(seed))
    complete = state.complete
    shared = covisibility(complete)
    pairs = sorted(((int(shared[a, b]), a, b) for a in range(n_cameras) for b in range(a + 1, n_cameras)), reverse=True)
    for count, a, b in pairs:
        rows = np.flatnonzero(complete[:, a] & complete[:, b])
        fit = pair_pose(bearings[rows, a], bearings[rows, b], rig.wand, threshold_rad=threshold_rad, rng=state.rng)
        if fit is not None:
            log.info("seed pair %s-%s: %d shared views, %d wand points fit", names[a], names[b], count, fit.inliers)
            state.poses[a] = Pose.identity()
            state.apply(b, fit, rows)
            state.adjust(fixed=a)
            seed_camera = a
            break
    else:
        counts = ", ".join(f"{names[a]}-{names[b]} {count}" for count, a, b in pairs)
        raise InsufficientDataError(
            f"no camera pair shares enough views of the whole wand for a relative pose ({counts}); a pair needs "
            f"{-(-MIN_PAIR_POINTS // k)} views of all {k} markers that both cameras see"
        )
    while len(state.placed) < n_cameras:
        if not _place_next(state):
            raise InsufficientDataError(_unplaced_message(state))
        state.adjust(fixed=seed_camera)
    poses = [p for p in state.poses if p is not None]
    inverse = poses[reference].inverse()
    return tuple(pose.compose(inverse) for pose in poses)


def _candidates(state: _Placing) -> list[tuple[int, int, int | None]]:
    """(support, camera, placed partner or None for resection) of every way to place an unplaced camera,
    most support first."""
    points = state.points()
    known = np.all(np.isfinite(points), axis=(1, 2))
    seen = np.all(np.isfinite(state.uv), axis=-1)  # (P, C, K)
    complete = state.complete
    out: list[tuple[int, int, int | None]] = []
    for c in range(len(state.poses)):
        if state.poses[c] is not None:
            continue
        out.append((int(seen[known, c].sum()), c, None))
        for other in state.placed:
            out.append((int((complete[:, c] & complete[:, other]).sum()) * state.uv.shape[2], c, other))
    return sorted(out, key=lambda item: (-item[0], item[2] is not None, item[1]))


def _place_next(state: _Placing) -> bool:
    """Place the unplaced camera with the most support that fits; False when none does."""
    points = state.points()
    known = np.flatnonzero(np.all(np.isfinite(points), axis=(1, 2)))
    complete = state.complete
    names = state.rig.camera_names
    for support, camera, partner in _candidates(state):
        if partner is None:
            rows = known[np.any(np.isfinite(state.bearings[known, camera, :, 0]), axis=1)]
            if support < MIN_RESECTION_POINTS:
                continue
            fit = resect(state.bearings[rows, camera], points[rows], threshold_rad=state.threshold_rad, rng=state.rng)
            how = "resection"
        else:
            rows = np.flatnonzero(complete[:, camera] & complete[:, partner])
            if support < MIN_PAIR_POINTS:
                continue
            partner_pose = state.poses[partner]
            assert partner_pose is not None
            pair = pair_pose(
                state.bearings[rows, partner], state.bearings[rows, camera], state.rig.wand,
                threshold_rad=state.threshold_rad, rng=state.rng,
            )  # fmt: skip
            fit = None if pair is None else Fit(pair.pose.compose(partner_pose), pair.swapped, pair.rows, pair.inliers)
            how = f"its pose relative to {names[partner]}"
        if fit is not None:
            log.info("%s placed by %s: %d wand points fit", names[camera], how, fit.inliers)
            state.apply(camera, fit, rows)
            return True
    return False


def _unplaced_message(state: _Placing) -> str:
    """Why the unplaced cameras cannot be placed and what would be enough."""
    names, k = state.rig.camera_names, state.uv.shape[2]
    points = state.points()
    known = np.all(np.isfinite(points), axis=(1, 2))
    seen = np.all(np.isfinite(state.uv), axis=-1)
    complete = state.complete
    parts = []
    for c in range(len(state.poses)):
        if state.poses[c] is not None:
            continue
        shared = ", ".join(f"{names[o]} {int((complete[:, c] & complete[:, o]).sum())}" for o in state.placed)
        parts.append(
            f"camera '{names[c]}' cannot be placed: it sees {int(seen[known, c].sum())} wand points of placements "
            f"the placed cameras ({', '.join(names[o] for o in state.placed)}) triangulate (a resection needs "
            f"{MIN_RESECTION_POINTS} that fit) and shares whole-wand views with them: {shared} (a relative pose "
            f"needs {-(-MIN_PAIR_POINTS // k)} that fit)"
        )
    return "; ".join(parts) + "; wave the wand where it and the others see it together"
