"""The bundle adjustment's Levenberg-Marquardt loop: linearise, solve the damped system, try the step, accept
or reject it, update the damping, stop.

:func:`minimise` is that loop. Each decision it makes has one owner here:

- :class:`Damping`: Nielsen's rule, and when an iteration tries Gauss-Newton's step first;
- :class:`Workspace`: the normal equations of the current state, the system they reduce to (the placements
  eliminated by the Schur complement), and the arrays reused between linearisations;
- :class:`Stopping`: when a step is not worth taking, and when the step after it would not be;
- :func:`held_placements`: a rejected step's placements that it made worse, held where they were;
- :func:`_last_step`: the last step taken without linearising again.

The wand-length start (:mod:`~wand_calib_ros.core.initialise.wand_lm`) keeps its own dense loop: a
14-parameter problem scaled MINPACK's way, whose starts the calibrations depend on to the last digit.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_problem import N_GEOMETRIC, BundleProblem, BundleState, apply_step
from wand_calib_ros.core.adjust.linearisation import evaluate, observation_costs, residuals, robust_cost
from wand_calib_ros.core.adjust.normal_equations import (
    BlockLayout,
    NormalEquations,
    back_substitute,
    damped,
    reduced_system,
    scaling,
    solve_free,
    undamped,
)
from wand_calib_ros.core.errors import ModelError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
log = logging.getLogger(__name__)

#: Near a solution (a step that lowered the cost by less than NEAR of it, as much as it promised to
#: within TRUSTED_GAIN), and after a Gauss-Newton step that did as much as it promised, the next iteration
#: first tries the undamped (Gauss-Newton) step.
NEAR = 1e-4
TRUSTED_GAIN = 0.75
#: Tries of one iteration: when none lowers the cost, the state is at a minimum to machine precision.
MAX_TRIES = 30


@dataclass(frozen=True)
class Damping:
    """Nielsen's damping rule, its decrease bounded at tenfold.

    Tenfold, not threefold: easy problems, most, keep converging in few iterations. Tenfold up and down by
    turns had a badly started 64-camera robust pass ping-pong between two dampings for 80 iterations (now 30).

    Attributes:
        lam: the damping of a damped try (lam D, D the normal equations' diagonal).
        growth: the factor of the next rejected damped try (doubling after each).
        trusted: the next try is Gauss-Newton's (undamped).
    """

    lam: float = 1e-6
    growth: float = 2.0
    trusted: bool = False

    def next_try(self) -> float:
        """The damping of the next try: 0 (Gauss-Newton's step) when trusted, else lam."""
        return 0.0 if self.trusted else self.lam

    def rejected(self, used: float) -> Damping:
        """After a try damped by ``used`` was rejected: lam itself after an undamped try, lam grown after a
        damped one."""
        if used == 0.0:
            return Damping(self.lam, self.growth)
        return Damping(self.lam * self.growth, 2.0 * self.growth)

    def accepted(self, gain: float, relative_decrease: float, used: float) -> Damping:
        """After a try damped by ``used`` was taken: lam follows the gain (actual over promised decrease)."""
        lam = max(self.lam * max(0.1, 1.0 - (2.0 * gain - 1.0) ** 3), 1e-12)
        return Damping(lam, 2.0, gain > TRUSTED_GAIN and (relative_decrease < NEAR or used == 0.0))


class ReducedSystem(NamedTuple):
    """An undamped system reduced: its normal equations, S, rhs and V^-1 (see :func:`reduced_system`)."""

    normal: NormalEquations
    s: FloatArray
    rhs: FloatArray
    v_inv: FloatArray


@dataclass(frozen=True, eq=False)
class Step:
    """A step of the cameras and the placements, solved from the normal equations damped by ``damping``.

    Attributes:
        damping: lam of the system (0: Gauss-Newton's step).
        s: (C K, C K) S of that system (empty without camera parameters).
        rhs: (C K,) its right-hand side.
        cameras: (C, K) the cameras' step, over the parameters carried.
        placements: (P, 5) the placements' step.
        predicted: the decrease of the cost the linearised problem promises.
    """

    damping: float
    s: FloatArray
    rhs: FloatArray
    cameras: FloatArray
    placements: FloatArray
    predicted: float


@dataclass(frozen=True, eq=False)
class Iterate:
    """A state the loop has reached, and the step that took it there.

    Attributes:
        state: the unknowns.
        res: (M, 2) its residuals, px.
        cost: its robust cost.
        previous: the cameras' part of the step taken to it, chi-square units (0: none yet).
        promised: the decrease that step promised (0: none yet).
    """

    state: BundleState
    res: FloatArray
    cost: float
    previous: float = 0.0
    promised: float = 0.0


@dataclass(frozen=True, eq=False)
class Trial:
    """A step tried: its state, residuals and cost, and its normal equations when they were formed with them.

    Attributes:
        over: the normal equations were formed in the arrays of the current state's.
    """

    state: BundleState
    res: FloatArray
    cost: float
    normal: NormalEquations | None
    over: bool


class Workspace:
    """The normal equations of the adjustment's current state, and the memory reused between linearisations.

    W, the largest array of an adjustment (80 MB for 10,000 placements seen by 16 cameras), is held at most
    twice: the current state's and one spare. A first try's normal equations come with its residuals (steps
    are rarely rejected near a solution, Gauss-Newton's least of all): a Gauss-Newton try's are summed into
    the current state's own arrays when no spare is left (the state's are summed again should the step fail).
    A later try is likelier rejected too: its residuals first, its normal equations once it is taken (a
    rejected try then costs a pass over the residuals, not two linearisations).
    """

    def __init__(self, problem: BundleProblem, layout: BlockLayout, carried: IntArray, loss_scale: float | None):
        self.problem, self.layout, self.carried, self.loss_scale = problem, layout, carried, loss_scale
        self.normal: NormalEquations | None = None
        self._spare: NormalEquations | None = None
        self._reduced: ReducedSystem | None = None  # the undamped system of ``normal``, once reduced

    def linearise(self, state: BundleState) -> FloatArray:
        """(M, 2) the residuals of ``state``, its normal equations the current ones (in the current arrays)."""
        self._reduced = None  # (before: its V^-1 need not outlive the arrays it was reduced from)
        res, self.normal = evaluate(state, self.problem, self.layout, self.carried, self.loss_scale, self.normal)
        return res

    def reduced(self) -> ReducedSystem:
        """The current normal equations undamped and reduced to the cameras (computed once per state)."""
        assert self.normal is not None
        if self._reduced is None:
            gauss_newton = undamped(self.normal)
            self._reduced = ReducedSystem(gauss_newton, *reduced_system(gauss_newton, self.layout))
        return self._reduced

    def solve(self, damping: float, free_flat: NDArray[np.bool_]) -> Step:
        """The step of the current normal equations damped by ``damping`` over the ``free_flat`` (C K,) camera
        parameters: S and rhs empty without camera parameters, the placements' 5 x 5 systems solved alone."""
        normal, layout = self.normal, self.layout
        assert normal is not None
        if damping == 0.0 and layout.width:
            system, s, rhs, v_inv = self.reduced()
        else:
            system = undamped(normal) if damping == 0.0 else damped(normal, damping)
            if layout.width:
                s, rhs, v_inv = reduced_system(system, layout)
        if layout.width:
            delta_c = solve_free(s, rhs, free_flat).reshape(layout.n_cameras, layout.width)
            delta_p = back_substitute(delta_c, v_inv, system, layout)
            # the decrease the linearised problem promises: delta^T g + lambda delta^T D delta
            predicted = float(np.sum(delta_c * normal.gc)) + damping * float(np.sum(scaling(normal.u) * delta_c**2))
        else:  # placements only: independent 5x5 systems
            s, rhs = np.zeros((0, 0)), np.zeros(0)
            delta_c = np.zeros((layout.n_cameras, N_GEOMETRIC + self.carried.size))
            delta_p = np.asarray(np.linalg.solve(system.v, normal.gp[..., None])[..., 0], dtype=np.float64)
            predicted = 0.0
        predicted += float(np.sum(delta_p * normal.gp)) + damping * float(np.sum(scaling(normal.v) * delta_p**2))
        return Step(damping, s, rhs, delta_c, delta_p, predicted)

    def trial(self, candidate: BundleState, *, first: bool, gauss_newton: bool) -> Trial:
        """``candidate`` tried: its residuals, and with them its normal equations on an iteration's ``first`` try."""
        if not first:
            res = residuals(candidate, self.problem)
            return Trial(candidate, res, robust_cost(res, self.loss_scale), None, False)
        over = self._spare is None and gauss_newton
        into = self.normal if over else self._spare
        res, normal = evaluate(candidate, self.problem, self.layout, self.carried, self.loss_scale, into)
        self._spare = None
        if over:
            self._reduced = None
        return Trial(candidate, res, robust_cost(res, self.loss_scale), normal, over)

    def moved(self, trial: Trial, state: BundleState) -> Trial:
        """``trial`` with its state replaced by ``state`` (in the arrays of its normal equations, if formed)."""
        if trial.normal is None:
            res = residuals(state, self.problem)
            return Trial(state, res, robust_cost(res, self.loss_scale), None, False)
        res, normal = evaluate(state, self.problem, self.layout, self.carried, self.loss_scale, trial.normal)
        return Trial(state, res, robust_cost(res, self.loss_scale), normal, trial.over)

    def accept(self, trial: Trial) -> tuple[FloatArray, float]:
        """Make ``trial`` the current state: (M, 2) its residuals and its cost, from its normal equations'
        linearisation (formed now if they were not)."""
        res, cost, normal = trial.res, trial.cost, trial.normal
        if normal is None:
            res, normal = evaluate(trial.state, self.problem, self.layout, self.carried, self.loss_scale, self._spare)
            cost = robust_cost(res, self.loss_scale)
        self._spare = None if trial.over else self.normal
        self.normal, self._reduced = normal, None
        return res, cost

    def reject(self, trial: Trial, state: BundleState) -> None:
        """``trial`` rejected: the current state's normal equations kept (summed again where the trial's took
        their arrays), the trial's arrays the spare."""
        if trial.normal is None:
            return
        if trial.over:
            _, self.normal = evaluate(state, self.problem, self.layout, self.carried, self.loss_scale, trial.normal)
        else:
            self._spare = trial.normal


@dataclass(frozen=True)
class Stopping:
    """When the adjustment stops (see :func:`~wand_calib_ros.core.adjust.bundle_adjustment.bundle_adjust`).

    Attributes:
        tolerance: the relative decrease of the cost below which a step is not worth taking.
        settled: the worth of the cameras' step, in chi-square units, below which it is not worth taking.
        last_step: whether the last step may be taken without linearising again.
        dof: residual degrees of freedom (a chi-square unit is cost / dof).
        cameras: whether any camera parameter is estimated.
    """

    tolerance: float
    settled: float
    last_step: bool
    dof: int
    cameras: bool

    def worth(self, step: Step, cost: float) -> float:
        """The cameras' part of ``step``, in chi-square units (inf without camera parameters)."""
        return float(step.cameras.reshape(-1) @ step.rhs) / (cost / self.dof) if self.cameras else np.inf

    def not_worth_taking(self, step: Step, cost: float) -> bool:
        """Whether ``step`` promises less than the tolerance, or moves the cameras (their marginal: the
        placements follow) by less than ``settled`` of a chi-square unit: what is left moves poorly seen
        placements only."""
        return step.predicted < self.tolerance * cost or self.worth(step, cost) < self.settled

    def successor_ends(self, step: Step, current: Iterate) -> bool:
        """Whether the step after ``step`` would end the adjustment, at the rate the steps shrink."""
        worth, predicted = self.worth(step, current.cost), step.predicted
        return self.last_step and (
            worth * worth < self.settled * current.previous
            or predicted * predicted < self.tolerance * current.cost * current.promised
        )


class Outcome(NamedTuple):
    """Where :func:`minimise` stopped, and the cameras' reduced system (S, rhs) there when it ended with it."""

    current: Iterate
    iterations: int
    converged: bool
    system: tuple[FloatArray, FloatArray] | None


def minimise(
    work: Workspace,
    current: Iterate,
    free_flat: NDArray[np.bool_],
    stopping: Stopping,
    damping: Damping,
    max_iterations: int,
) -> Outcome:
    """Levenberg-Marquardt from ``current``, whose normal equations ``work`` holds, over the camera parameters
    ``free_flat`` (C K,) and every placement."""
    for iteration in range(1, max_iterations + 1):
        for attempt in range(MAX_TRIES):
            step = work.solve(damping.next_try(), free_flat)
            if attempt == 0 and stopping.not_worth_taking(step, current.cost):
                ended = stopping.cameras and step.damping == 0.0  # (Gauss-Newton's system: the final one)
                return Outcome(current, iteration, True, (step.s, step.rhs) if ended else None)
            if attempt == 0 and stopping.successor_ends(step, current):
                step, last = _last_step(work, current, step, free_flat, stopping)
                if last is not None:  # the system where the step was computed, its gradient moved along the step
                    moved = (step.s, step.rhs - step.s @ step.cameras.reshape(-1)) if stopping.cameras else None
                    return Outcome(last, iteration, True, moved)
            trial = _tried(work, current, step, first=attempt == 0)
            if trial is None or not trial.cost < current.cost:
                if trial is not None:
                    work.reject(trial, current.state)
                damping = damping.rejected(step.damping)
                continue
            worth, (res, cost) = stopping.worth(step, current.cost), work.accept(trial)
            relative_decrease = (current.cost - cost) / max(current.cost, 1e-300)
            log.debug("LM iteration %d: cost %.6g, relative decrease %.3g, lambda %.1e",
                      iteration, cost, relative_decrease, damping.lam)  # fmt: skip
            gain = (current.cost - cost) / max(step.predicted, 1e-300)
            damping = damping.accepted(gain, relative_decrease, step.damping)
            current = Iterate(trial.state, res, cost, worth, step.predicted)
            if relative_decrease < stopping.tolerance:
                return Outcome(current, iteration, True, None)
            break
        else:  # no decrease possible: at a minimum to machine precision
            return Outcome(current, iteration, True, None)
    return Outcome(current, max(max_iterations, 0), False, None)


def _tried(work: Workspace, current: Iterate, step: Step, *, first: bool) -> Trial | None:
    """``step`` tried from ``current`` (None: it leaves the camera model, e.g. k1 <= 0). Where it costs more,
    the placements it made worse are held first (:func:`held_placements`)."""
    try:
        candidate = apply_step(current.state, step.cameras, step.placements, work.carried)
    except ModelError:
        return None
    trial = work.trial(candidate, first=first, gauss_newton=step.damping == 0.0)
    if not trial.cost < current.cost:
        held = held_placements(current.state, candidate, work.problem, trial.res, work.loss_scale, current.cost)
        if held is not None:
            trial = work.moved(trial, held)
    return trial


def _last_step(
    work: Workspace, current: Iterate, step: Step, free_flat: NDArray[np.bool_], stopping: Stopping
) -> tuple[Step, Iterate | None]:
    """The adjustment's last step, taken without linearising again where the convergence so far says the step
    after it would end the adjustment (:meth:`Stopping.successor_ends`).

    The step is Gauss-Newton's (a damped step is shorter: Gauss-Newton's is checked too), taken once its
    residuals (a fraction of the cost of a linearisation) show a lower cost. The rate at which the steps shrink
    guesses the next step within a few times: mocap16's final adjustment, steps worth 1,075 and 0.056
    chi-square units (the second taken so: next 3e-6 by the rate, 1e-7 measured); a two-camera pair, 14.5,
    0.41 and 0.0072 (the third taken so: next 1.2e-4 by the rate, 5.6e-4 measured, both settled). The state
    is the one the linearisation after it would have stopped at.

    Returns:
        The step to try should the last one not be taken (Gauss-Newton's), and the state it reached, or None.
    """
    if step.damping != 0.0:
        step = work.solve(0.0, free_flat)
        if not stopping.successor_ends(step, current):
            return step, None
    try:
        candidate = apply_step(current.state, step.cameras, step.placements, work.carried)
    except ModelError:
        return step, None
    res = residuals(candidate, work.problem)
    cost = robust_cost(res, work.loss_scale)
    return step, (Iterate(candidate, res, cost) if cost < current.cost else None)


def held_placements(
    state: BundleState,
    candidate: BundleState,
    problem: BundleProblem,
    res: FloatArray,
    loss_scale: float | None,
    cost: float,
) -> BundleState | None:
    """``candidate`` with the placements whose own cost its step raised held where ``state`` had them;
    None when that would not cost less than ``cost`` (nothing to hold, or the cameras' step is wrong).

    The cameras' step is shared, the placements' steps are each their own: a step the linearisation
    got wrong is often wrong only for a few poorly conditioned placements (seen by nearly parallel
    rays), whose linearised steps run far off. Given the cameras, each placement's cost depends on
    that placement alone, so each can keep whichever of its two values costs less.

    Args:
        res: (M, 2) the residuals at ``candidate``.
    """
    held = replace(candidate, wand_a=state.wand_a, wand_direction=state.wand_direction)
    n = problem.n_placements
    stepped = np.bincount(problem.placement, observation_costs(res, loss_scale), minlength=n)
    kept = np.bincount(problem.placement, observation_costs(residuals(held, problem), loss_scale), minlength=n)
    worse = ~(stepped <= kept)  # NaN costs count as worse
    if not worse.any() or not float(np.sum(np.where(worse, kept, stepped))) < cost:
        return None
    return replace(
        candidate,
        wand_a=np.where(worse[:, None], state.wand_a, candidate.wand_a),
        wand_direction=np.where(worse[:, None], state.wand_direction, candidate.wand_direction),
    )
