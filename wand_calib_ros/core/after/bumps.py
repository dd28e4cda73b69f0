"""Has a camera moved since the calibration? The camera pairs' agreement on the wand seen afterwards.

For every placement two cameras both see whole, the wand (its known marker spacing) is fitted to
their two views with the cameras as calibrated (5 parameters, 4K residuals: 4K - 5 degrees of
freedom). With the calibration still right the fit's mean square residual per degree of freedom is
the calibration's own (its level on the calibration's data); once a camera is turned, knocked or
refocused, every pair it belongs to stops agreeing (the two views no longer meet in a wand of the
right length), pairs without it stay as they were. Over a pair's last :data:`WINDOW` placements
the ratio F of its mean square to its level is tested against 1 + :data:`MARGIN` + Z sqrt(2 / dof)
(:data:`Z` standard errors of a chi-square mean, plus what fresh views of an untouched rig add to
the calibration's own residuals through its estimation error: measured up to 12 %). Once a pair disagrees, each
camera's best-agreeing pair (its smallest F) decides: a moved camera disturbs every pair it is in,
any other keeps one that agrees, so the camera whose smallest F stands out (:data:`DISTINCT` times
the next one's excess, and two standard errors) moved; otherwise the two leading cameras are named
together. Two cameras cannot tell which of them moved.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_problem import BundleProblem, BundleState
from wand_calib_ros.core.adjust.linearisation import squared_norms
from wand_calib_ros.core.adjust.placements import fit_placements
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.rig import WandSpec

FloatArray = NDArray[np.float64]

#: Placements per camera pair a decision is made on (two seconds of wand views at 30 fps).
WINDOW = 60
#: Standard errors of the window's mean square above the level that make a pair disagree.
Z = 4.0
#: Fresh views of an untouched rig fit a little worse than the calibration's own (measured: mean F up to
#: 1.12 on mixed3 at 1 px after 300 placements): allowed on top.
MARGIN = 0.15
#: The moved camera's excess (smallest F - 1) must exceed the runner-up's by this factor to be named alone.
DISTINCT = 1.5


def pair_squares(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], wand: WandSpec, uv: FloatArray
) -> FloatArray:
    """(F, C, C) each placement's sum of squared residuals (px^2) of the wand fitted to a camera pair's two
    whole views (symmetric; NaN where the pair does not both see the whole wand, and on the diagonal).

    Args:
        models, poses: the calibration (poses X_cam = R X_ref + T).
        wand: the wand (its marker spacing constrains the fit).
        uv: (F, C, K, 2) pixels, NaN where not seen.
    """
    n_frames, n_cameras = uv.shape[:2]
    whole = np.all(np.isfinite(uv), axis=(2, 3))
    out = np.full((n_frames, n_cameras, n_cameras), np.nan)
    cameras = BundleState(models, poses, np.zeros((0, 3)), np.zeros((0, 3)))
    for i in range(n_cameras):
        for j in range(i + 1, n_cameras):
            rows = np.flatnonzero(whole[:, i] & whole[:, j])
            if rows.size == 0:
                continue
            pair = np.full((rows.size, *uv.shape[1:]), np.nan)
            pair[:, [i, j]] = uv[rows][:, [i, j]]
            index, fit = fit_placements(wand, cameras, pair, max_iterations=10)
            problem = BundleProblem.from_dense(wand, pair[index])
            squares = np.bincount(problem.placement, squared_norms(fit.residuals), minlength=index.size)
            out[rows[index], i, j] = out[rows[index], j, i] = squares
    return out


def pair_dof(wand: WandSpec) -> int:
    """Degrees of freedom of one placement's two-view wand fit: 2 views x K markers x 2 - 5."""
    return 4 * wand.n_points - 5


def calibration_levels(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], wand: WandSpec, uv: FloatArray
) -> FloatArray:
    """(C, C) each pair's mean square residual per degree of freedom on data the calibration fits
    (px^2; NaN: the pair shares no placement)."""
    squares = pair_squares(models, poses, wand, uv)
    counts = np.isfinite(squares).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, np.nansum(squares, axis=0) / (counts * pair_dof(wand)), np.nan)


def noise_levels(sigma_px: float, n_cameras: int) -> FloatArray:
    """(C, C) pair levels from a calibration's pixel noise alone (per coordinate, px): a right two-view
    fit's mean square per degree of freedom is the noise's variance (when the calibration's own data are
    not at hand, as for a result file)."""
    levels = np.full((n_cameras, n_cameras), float(sigma_px) ** 2)
    np.fill_diagonal(levels, np.nan)
    return levels


@dataclass
class BumpMonitor:
    """Watches a calibrated rig as wand views arrive (see the module docstring).

    Attributes:
        names: the cameras.
        models, poses: the calibration.
        wand: the wand.
        levels: (C, C) the pairs' levels (:func:`calibration_levels`).
        window: placements per pair a decision is made on.
    """

    names: tuple[str, ...]
    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    wand: WandSpec
    levels: FloatArray
    window: int = WINDOW
    _recent: dict[tuple[int, int], deque[float]] = field(default_factory=dict)

    def add(self, uv: FloatArray) -> None:
        """New frames: (F, C, K, 2) or (C, K, 2) pixels, NaN where not seen."""
        squares = pair_squares(self.models, self.poses, self.wand, uv.reshape(-1, *uv.shape[-3:]))
        for frame in squares:
            for i, j in zip(*np.triu_indices(len(self.names), 1), strict=True):
                if not np.isfinite(frame[i, j]):
                    continue
                self._recent.setdefault((int(i), int(j)), deque(maxlen=self.window)).append(float(frame[i, j]))

    def ratios(self) -> dict[tuple[int, int], float]:
        """F of each pair with a full window: its mean square per degree of freedom over its level."""
        dof = pair_dof(self.wand)
        return {
            (i, j): float(np.mean(r)) / dof / float(self.levels[i, j])
            for (i, j), r in self._recent.items()
            if len(r) == self.window and np.isfinite(self.levels[i, j]) and self.levels[i, j] > 0
        }

    def standard_error(self) -> float:
        """Standard error of a full window's F on a rig left alone (a chi-square mean)."""
        return float(np.sqrt(2.0 / (self.window * pair_dof(self.wand))))

    def limit(self) -> float:
        """The F above which a pair disagrees."""
        return 1.0 + MARGIN + Z * self.standard_error()

    def moved(self) -> tuple[int, ...]:
        """The cameras judged to have moved; () while every pair agrees."""
        ratios = self.ratios()
        if not any(f > self.limit() for f in ratios.values()):
            return ()
        # A moved camera disturbs every pair it is in; any other camera keeps a pair that agrees.
        least = sorted(
            (
                (min(f for p, f in ratios.items() if c in p), c)
                for c in range(len(self.names))
                if any(c in p for p in ratios)
            ),
            reverse=True,
        )
        if len(self.names) == 2 or len(least) < 2:
            return tuple(sorted(c for _, c in least))
        (best, camera), (second, other) = least[0], least[1]
        if best - 1.0 >= DISTINCT * max(second - 1.0, 0.0) and best - 1.0 >= 2.0 * self.standard_error():
            return (camera,)
        return tuple(sorted((camera, other)))

    def messages(self) -> list[str]:
        """One line per camera judged moved: ``cam3 moved: its pairs' residual 6.1 px, was 0.4``."""
        moved = self.moved()
        ratios = self.ratios()
        either = " (or the other one: two cameras cannot tell which)" if len(self.names) == 2 else ""
        together = " (or with another: the pairs cannot tell them apart)" if len(moved) > 1 else ""
        lines = []
        for c in moved:
            worst = max((p for p in ratios if c in p), key=ratios.__getitem__)
            was = float(np.sqrt(self.levels[worst]))
            now = was * np.sqrt(ratios[worst])
            lines.append(f"{self.names[c]} moved{either or together}: residual {now:.1f} px, was {was:.1f}")
        return lines
