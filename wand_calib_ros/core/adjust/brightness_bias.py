"""Which centre bias the data support, and in which shape (:mod:`~wand_calib_ros.core.model.brightness`).

Per camera the bias starts in the CLASSES shape: each brightness class with MIN_CLASS_POINTS points free, in a
camera with MIN_REFERENCE_POINTS points below full scale to measure them against. After an adjustment that
estimated them, each camera is decided on its terms' estimates and covariance, as the distortion model's order
is (:func:`~wand_calib_ros.core.adjust.model_order.reduce_radial`: the linearised problem, no adjustment more):

1. from CLASSES, a LINEAR bias (from one class on, its *start*, none below: a step there and a growth with the
   classes' mean stops beyond its edge) where that fits the classes' estimates; where it cannot be told (fewer
   than three classes) or does not fit, CONSTANT (the step alone) or PROPORTIONAL (the growth alone), whichever
   fits better; else CLASSES. A shape fits where the classes' estimates differ from its generalised
   least-squares fit by no more than chance (chi-square at SHAPE_LEVEL), from the lowest start that fits. Fewer
   terms estimate a camera's parameters more surely;
2. whether its bias differs from zero: all its terms together, chi-square at SIGNIFICANCE_LEVEL (else it has none).
   In the CLASSES shape, which classes are biased is then a question of its shape: a class that does not differ from
   zero at SHAPE_LEVEL is held there, the least significant first, and the others are tested again as a whole (class
   by class at SIGNIFICANCE_LEVEL, a camera's 8-16x class 0.28 +- 0.08 px from zero was held there too, and the
   others moved to make up for it). A LINEAR bias, once adjusted in that shape, whose growth or step does not differ
   from zero (at SHAPE_LEVEL) is CONSTANT or PROPORTIONAL.

The camera is then adjusted again in that shape, from the fitted terms, and decided again there (a shape only
ever gives way to a simpler one). Classes held at zero, and a camera without a bias, are measured as if their
centres were unbiased.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult
from wand_calib_ros.core.adjust.bundle_problem import BIAS, GEOMETRY_PARTS, N_CAMERA_PARAMS, BundleProblem, CameraBias
from wand_calib_ros.core.adjust.chi_square import chi_square_quantile
from wand_calib_ros.core.adjust.linearisation import in_pixels, squared_norms
from wand_calib_ros.core.model.brightness import (
    BIAS_COMPONENTS,
    BIAS_EDGES,
    CLASSES,
    CONSTANT,
    LINEAR,
    N_BIAS,
    N_BIAS_CLASSES,
    PROPORTIONAL,
    SHAPE_NAMES,
    brightness_classes,
)

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: A class of a camera with fewer points than this has no term of its own ...
MIN_CLASS_POINTS = 10
#: ... nor does any class of a camera with fewer points than this below full scale to measure it against.
MIN_REFERENCE_POINTS = 10
#: A brightness class's centres are weighed by their own noise where a camera has this many of them (else by the
#: camera's): enough to know it to about 13 % (1 / sqrt(2 n)); it is held within 0.25-4x the camera's.
MIN_NOISE_POINTS = 30
#: A camera's bias is kept when it differs from zero at this level (chi-square): with a dozen classes tested per
#: rig, a take without bias keeps one by chance about once in a thousand.
SIGNIFICANCE_LEVEL = 0.9999
#: A simpler shape is taken unless the classes' estimates differ from it at this level (chi-square).
SHAPE_LEVEL = 0.99

_WIDTH = len(BIAS_COMPONENTS)


def stops_of(brightness: FloatArray | None, used: NDArray[np.int64]) -> FloatArray | None:
    """The brightness (P, C, K) of the placements ``used`` (None: not known)."""
    return None if brightness is None else brightness[used]


def class_points(problem: BundleProblem) -> tuple[NDArray[np.int64], FloatArray]:
    """(C, N_BIAS_CLASSES + 1) how many of each camera's points are of each brightness class (class 0 first), and
    their mean brightness (stops; NaN for none, and for class 0)."""
    n = N_BIAS_CLASSES + 1
    if problem.brightness is None:
        return np.zeros((problem.n_cameras, n), dtype=np.int64), np.full((problem.n_cameras, n), np.nan)
    classes = brightness_classes(problem.brightness)
    index = problem.camera * n + classes
    counts = np.bincount(index, minlength=problem.n_cameras * n)
    sums = np.bincount(index, np.where(classes > 0, problem.brightness, 0.0), minlength=problem.n_cameras * n)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(counts > 0, sums / counts, np.nan)
    means[::n] = np.nan
    return counts.reshape(problem.n_cameras, n), means.reshape(problem.n_cameras, n)


def bias_candidates(problem: BundleProblem) -> NDArray[np.bool_] | None:
    """(C, N_BIAS) the terms to start free, in the CLASSES shape (module docstring); None: no camera has one."""
    counts, _ = class_points(problem)
    enough = (counts[:, 1:] >= MIN_CLASS_POINTS) & (counts[:, :1] >= MIN_REFERENCE_POINTS)
    if not enough.any():
        return None
    return np.repeat(enough, _WIDTH, axis=1)


def class_noise(result: BundleResult, problem: BundleProblem) -> FloatArray:
    """(C, N_BIAS_CLASSES + 1) each camera's centres' noise by brightness class (class 0 first) relative to all of
    its centres', from an adjustment's residuals (in pixels); 1 for a class of fewer than MIN_NOISE_POINTS points.

    A dim spot's centre is noisier than a bright one's (less light over the same read noise), and the points below
    full scale are what a bias is measured against: weighed alike, the bias's standard deviation would be too
    small, and chance would pass for a bias.
    """
    n, cameras = N_BIAS_CLASSES + 1, problem.n_cameras
    if problem.brightness is None:
        return np.ones((cameras, n))
    counts, _ = class_points(problem)
    index = problem.camera * n + brightness_classes(problem.brightness)
    res = in_pixels(result.residuals, result.state, problem)
    squares = np.bincount(index, squared_norms(res), minlength=cameras * n).reshape(cameras, n)
    mean_square = squares.sum(axis=1) / np.maximum(counts.sum(axis=1), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.sqrt(squares / counts / mean_square[:, None])
    return np.where(counts >= MIN_NOISE_POINTS, np.clip(np.nan_to_num(ratio, nan=1.0), 0.25, 4.0), 1.0)


def unmeasured_bias(problem: BundleProblem, names: tuple[str, ...]) -> list[str]:
    """What to say of each camera with points over full scale but too few below it to measure a bias against
    (MIN_REFERENCE_POINTS): its bright centres may be biased, and nothing can tell or correct it."""
    counts, _ = class_points(problem)
    lines = []
    for name, row in zip(names, counts, strict=True):
        over = int(row[1:].sum())
        if row[0] < MIN_REFERENCE_POINTS and over >= MIN_CLASS_POINTS:
            lines.append(
                f"{name}: {over} of its {int(row.sum())} points are over full scale and {int(row[0])} below it: a "
                "bias of the bright spots' centres cannot be measured against so few, nor corrected; shorten the "
                "exposure or dim the LEDs so that more stay below full scale"
            )
    return lines


#: Estimating a camera's centre bias costs its geometry precision where the two look alike in its data (a u bias
#: that grows with brightness and a pair's baseline); a cost beyond this factor on a parameter's standard deviation
#: is said (what a bias's correction is held to: its calibration within 1.3x of the same take's without it).
BIAS_COST = 1.3


def bias_costs(covariance: FloatArray, free: NDArray[np.bool_] | None, names: tuple[str, ...]) -> list[str]:
    """What estimating the centre bias costs each camera's geometry, where that is more than BIAS_COST: the standard
    deviation of its focal length, principal point, orientation and position against the one it would have were the
    bias known (the camera ``covariance`` (C N_CAMERA_PARAMS, C N_CAMERA_PARAMS) conditioned on the bias terms
    ``free``, (C, N_BIAS)). The reported standard deviations already carry the cost: this says where it comes
    from."""
    if free is None or not free.any():
        return []
    cameras = len(names)
    bias = (np.arange(cameras)[:, None] * N_CAMERA_PARAMS + BIAS.start + np.arange(N_BIAS)[None, :])[free]
    columns = np.array([j for _, group in GEOMETRY_PARTS for j in group])
    geometry = (np.arange(cameras)[:, None] * N_CAMERA_PARAMS + columns[None, :]).reshape(-1)
    across = covariance[np.ix_(geometry, bias)]
    explained = np.einsum("ij,jk,ik->i", across, np.linalg.pinv(covariance[np.ix_(bias, bias)], hermitian=True), across)
    total = np.diag(covariance)[geometry]
    known = total - explained  # (the variance were the bias known)
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.where((total > 0) & (known > 0), np.sqrt(total / known), 1.0).reshape(cameras, columns.size)
    lines = []
    for c, name in enumerate(names):
        first, worst, what = 0, 1.0, ""
        for group, group_columns in GEOMETRY_PARTS:
            cost = float(factor[c, first : first + len(group_columns)].max())
            first += len(group_columns)
            if cost > worst:
                worst, what = cost, group
        if worst > BIAS_COST:
            whose = "its centre bias" if free[c].any() else "the other cameras' centre bias"
            lines.append(
                f"{name}: {whose} and its {what} are hard to tell apart in these views: estimating the bias "
                f"leaves its {what} {worst:.2f}x less precise than a known bias would (said in its standard "
                "deviations); cameras that see the volume from other directions, or LEDs that stay below full scale, "
                "tell them apart"
            )
    return lines


def decide_bias(
    result: BundleResult, free: NDArray[np.bool_], problem: BundleProblem, names: tuple[str, ...]
) -> tuple[NDArray[np.bool_], CameraBias]:
    """Each camera's shape and terms after an adjustment that estimated the terms ``free`` (C, N_BIAS) (module
    docstring): the terms still to estimate, and the bias to start the next adjustment from."""
    state = result.state
    values, shapes, starts = state.camera_bias.copy(), state.bias_shapes.copy(), state.bias_starts.copy()
    kept = free.copy()
    counts, means = class_points(problem)
    for c in range(free.shape[0]):
        terms = [j for j in range(N_BIAS_CLASSES) if free[c, _WIDTH * j]]
        if not terms:
            continue
        index = c * N_CAMERA_PARAMS + BIAS.start + np.arange(N_BIAS)
        fit = _Fit(int(shapes[c]), int(starts[c]), values[c], result.camera_covariance[np.ix_(index, index)], terms)
        shaped = _simplified(fit, counts[c, 1:] >= MIN_CLASS_POINTS, means[c, 1:], names[c])
        # (a shape just taken is tested on its own adjustment, which estimates it more surely than the classes did)
        fit = _significant(shaped, names[c], shape_tests=shaped.shape == fit.shape)
        shapes[c], starts[c], values[c] = fit.shape, fit.start, fit.estimate
        kept[c] = False
        for j in fit.terms:
            kept[c, _WIDTH * j : _WIDTH * (j + 1)] = True
    return kept, CameraBias(values, shapes, starts, state.bias_noise)


@dataclass(frozen=True, eq=False)
class _Fit:
    """One camera's bias as estimated: its shape and start, its (N_BIAS,) terms and their covariance, the terms free."""

    shape: int
    start: int
    estimate: FloatArray
    covariance: FloatArray
    terms: list[int]

    def without(self, dropped: list[int]) -> _Fit:
        """The fit with the terms ``dropped`` held at zero (the others moved to their conditional estimate)."""
        index = np.concatenate([np.arange(_WIDTH * j, _WIDTH * (j + 1)) for j in dropped])
        gain = self.covariance[:, index] @ np.linalg.pinv(self.covariance[np.ix_(index, index)], hermitian=True)
        estimate = self.estimate - gain @ self.estimate[index]
        estimate[index] = 0.0
        covariance = self.covariance - gain @ self.covariance[index, :]
        return _Fit(self.shape, self.start, estimate, covariance, [j for j in self.terms if j not in dropped])


def _significant(fit: _Fit, name: str, *, shape_tests: bool = True) -> _Fit:
    """The fit with what does not differ from zero held there: a LINEAR shape's step or growth (then PROPORTIONAL
    or CONSTANT; with ``shape_tests``), the whole bias (at SIGNIFICANCE_LEVEL), and of a CLASSES bias that does, the
    classes that do not (at SHAPE_LEVEL, the least significant first, the rest tested again as a whole)."""
    if fit.shape == LINEAR and shape_tests:  # (a question of its shape: at SHAPE_LEVEL)
        step, growth = (_statistic(*_block(fit.estimate, fit.covariance, [j])) for j in (0, 1))
        if min(step, growth) > chi_square_quantile(SHAPE_LEVEL, _WIDTH):
            return fit
        if growth <= step:
            fit = replace(fit.without([1]), shape=CONSTANT)
        else:  # (its growth alone: the term moves to the first place, as a PROPORTIONAL shape has it)
            alone = fit.without([0])
            order = np.r_[_WIDTH : 2 * _WIDTH, 0:_WIDTH, 2 * _WIDTH : N_BIAS]
            fit = _Fit(PROPORTIONAL, fit.start, alone.estimate[order], alone.covariance[np.ix_(order, order)], [0])
    while fit.terms:
        whole = _statistic(*_block(fit.estimate, fit.covariance, fit.terms))
        if whole <= chi_square_quantile(SIGNIFICANCE_LEVEL, _WIDTH * len(fit.terms)):
            log.debug("%s: centre bias %s %s (chi-square %.1f) held at zero", name, SHAPE_NAMES[fit.shape],
                      fit.terms, whole)  # fmt: skip
            return fit.without(fit.terms)
        if fit.shape != CLASSES or len(fit.terms) == 1:
            break
        statistics = [_statistic(*_block(fit.estimate, fit.covariance, [j])) for j in fit.terms]
        weakest = int(np.argmin(statistics))
        if statistics[weakest] > chi_square_quantile(SHAPE_LEVEL, _WIDTH):  # (which classes: a question of its shape)
            break
        log.debug("%s: centre bias class %d (chi-square %.1f) held at zero", name, fit.terms[weakest] + 1,
                  statistics[weakest])  # fmt: skip
        fit = fit.without([fit.terms[weakest]])  # (and the rest tested again as a whole)
    return fit


def _simplified(fit: _Fit, populated: NDArray[np.bool_], means: FloatArray, name: str) -> _Fit:
    """A CLASSES fit as a LINEAR bias where that fits its classes' estimates (module docstring), from the lowest
    class it fits from; where LINEAR cannot be told (fewer than three classes) or does not fit, the better fitting of
    CONSTANT and PROPORTIONAL where one fits; else as it is. A shape from class k gives the classes below k no
    bias: it starts only where every populated class from k on is estimated."""
    if fit.shape != CLASSES or not fit.terms:
        return fit
    starts = [k for k in fit.terms if all(j in fit.terms for j in range(k, N_BIAS_CLASSES) if populated[j])]
    linear = _lowest_start(fit, LINEAR, starts, means)
    simple = [c for c in (_lowest_start(fit, shape, starts, means) for shape in (CONSTANT, PROPORTIONAL)) if c]
    chosen = (
        linear
        if linear is not None and linear.fits
        else min((c for c in simple if c.fits), key=lambda c: c.misfit, default=None)
    )
    if chosen is None:
        return fit
    log.debug("%s: centre bias %s from class %d (misfit %.1f)", name, SHAPE_NAMES[chosen.shape], chosen.first + 1,
              chosen.misfit)  # fmt: skip
    size = chosen.parameters.size
    values, full = np.zeros(N_BIAS), np.zeros((N_BIAS, N_BIAS))
    values[:size], full[:size, :size] = chosen.parameters, chosen.covariance
    return _Fit(chosen.shape, chosen.first + 1, values, full, list(range(size // _WIDTH)))


@dataclass(frozen=True, eq=False)
class _Shaped:
    """A shape fitted to a camera's classes' estimates from class ``first``: its parameters and their covariance,
    the misfit's chi-square and whether it fits (at SHAPE_LEVEL)."""

    shape: int
    first: int
    parameters: FloatArray
    covariance: FloatArray
    misfit: float
    fits: bool


def _lowest_start(fit: _Fit, shape: int, starts: list[int], means: FloatArray) -> _Shaped | None:
    """``shape`` fitted from the lowest of the ``starts`` it fits from (of none, the one it fits best); None: no
    start gives one. (The lowest: a class held at zero is a claim the data must make.)"""
    best: _Shaped | None = None
    for first in sorted(starts):
        design = _design(shape, fit.terms, first, means - BIAS_EDGES[first])
        solved = None if design is None else _gls(fit.estimate, fit.covariance, fit.terms, design)
        if design is None or solved is None:
            continue
        fits = solved[2] <= chi_square_quantile(SHAPE_LEVEL, max(design.shape[0] - design.shape[1], 1))
        shaped = _Shaped(shape, first, solved[0], solved[1], solved[2], fits)
        if fits:
            return shaped
        if best is None or shaped.misfit < best.misfit:
            best = shaped
    return best


def _design(shape: int, terms: list[int], first: int, beyond: FloatArray) -> FloatArray | None:
    """(3 T, p) the classes' terms ``terms`` (T,) as a CONSTANT or PROPORTIONAL (p = 3) or LINEAR (p = 6) bias from
    class ``first`` on (none below it), ``beyond`` each class's mean stops beyond that class's edge; None: LINEAR
    over fewer than three classes (it fits any two)."""
    identity, zero = np.eye(_WIDTH), np.zeros((_WIDTH, _WIDTH))
    over = [j for j in terms if j >= first]
    if shape == CONSTANT:
        return np.vstack([identity if j >= first else zero for j in terms])
    if shape == PROPORTIONAL:
        if not np.all(np.isfinite(beyond[over])):
            return None
        return np.vstack([beyond[j] * identity if j >= first else zero for j in terms])
    if len(over) < 3 or not np.all(np.isfinite(beyond[over])):
        return None
    return np.vstack([np.hstack([identity, beyond[j] * identity]) if j >= first else np.hstack([zero, zero])
                      for j in terms])  # fmt: skip


def _gls(
    estimate: FloatArray, covariance: FloatArray, terms: list[int], design: FloatArray
) -> tuple[FloatArray, FloatArray, float] | None:
    """The generalised least-squares fit of the classes' estimates by ``design``: its parameters, their
    covariance and the misfit's chi-square; None where the classes' covariance does not determine it."""
    index = np.concatenate([np.arange(_WIDTH * j, _WIDTH * (j + 1)) for j in terms])
    theta, weight = estimate[index], np.linalg.pinv(covariance[np.ix_(index, index)], hermitian=True)
    normal = design.T @ weight @ design
    try:
        fitted_covariance = np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        return None
    parameters = np.asarray(fitted_covariance @ design.T @ weight @ theta, dtype=np.float64)
    misfit = theta - design @ parameters
    return parameters, np.asarray(fitted_covariance, dtype=np.float64), float(misfit @ weight @ misfit)


def _block(estimate: FloatArray, covariance: FloatArray, terms: list[int]) -> tuple[FloatArray, FloatArray]:
    index = np.concatenate([np.arange(_WIDTH * j, _WIDTH * (j + 1)) for j in terms])
    return estimate[index], covariance[np.ix_(index, index)]


def _statistic(values: FloatArray, covariance: FloatArray) -> float:
    """The chi-square statistic of estimates against zero."""
    return float(values @ np.linalg.pinv(covariance, hermitian=True) @ values)
