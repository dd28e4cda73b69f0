"""The chi-square distribution's quantiles, for the significance tests, without scipy (whose import
costs a sixth of a second of the command line's start).

The regularised incomplete gamma functions ``P(a, x)`` and ``Q(a, x) = 1 - P(a, x)`` come from the
power series below ``x = a + 1`` and from the continued fraction (modified Lentz) above it, each where
it converges fast and keeps its precision; the quantile is found by Newton's method on the tail it
is given in, kept inside a bracket.
"""

from __future__ import annotations

import math
from statistics import NormalDist

_EPSILON = 1e-16
_TINY = 1e-300


def _log_prefactor(a: float, x: float) -> float:
    """log(x^a e^-x / Gamma(a))."""
    return a * math.log(x) - x - math.lgamma(a)


def _series(a: float, x: float) -> float:
    """P(a, x) by its power series (x < a + 1)."""
    term = total = 1.0 / a
    n = 1
    while term > _EPSILON * total:
        term *= x / (a + n)
        total += term
        n += 1
    return total * math.exp(_log_prefactor(a, x))


def _continued_fraction(a: float, x: float) -> float:
    """Q(a, x) by its continued fraction (x >= a + 1), modified Lentz."""
    b = x + 1.0 - a
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, 10_000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = _TINY if abs(d) < _TINY else d
        c = b + an / c
        c = _TINY if abs(c) < _TINY else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < _EPSILON:
            break
    return math.exp(_log_prefactor(a, x)) * h


def chi_square_tails(x: float, dof: int) -> tuple[float, float]:
    """(P(X <= x), P(X > x)) for X chi-square distributed with ``dof`` degrees of freedom."""
    if x <= 0.0:
        return 0.0, 1.0
    a, half = 0.5 * dof, 0.5 * x
    if half < a + 1.0:
        lower = _series(a, half)
        return lower, 1.0 - lower
    upper = _continued_fraction(a, half)
    return 1.0 - upper, upper


def chi_square_quantile(probability: float, dof: int) -> float:
    """x with P(X <= x) = ``probability`` for X chi-square distributed with ``dof`` (>= 1) degrees of freedom.

    Accurate to about 1e-12 relative (tested against scipy.special.chdtri).
    """
    if not 0.0 < probability < 1.0 or dof < 1:
        raise ValueError(f"need 0 < probability < 1 and dof >= 1, got {probability}, {dof}")
    upper_tail = probability > 0.5  # solve on the smaller tail, where it has its digits
    target = 1.0 - probability if upper_tail else probability
    z = NormalDist().inv_cdf(probability)  # Wilson-Hilferty start
    x = max(dof * (1.0 - 2.0 / (9.0 * dof) + z * math.sqrt(2.0 / (9.0 * dof))) ** 3, 1e-3)
    low, high = 0.0, math.inf
    for _ in range(500):
        lower, upper = chi_square_tails(x, dof)
        error = (target - upper) if upper_tail else (lower - target)  # increases with x
        if error == 0.0:
            return x
        if error > 0:
            high = x
        else:
            low = x
        a = 0.5 * dof
        density = 0.5 * math.exp(_log_prefactor(a, 0.5 * x)) / (0.5 * x)
        step = x - error / density if density > 0 else math.nan
        if not max(low, 0.5 * x) < step < min(high, 2.0 * x):  # Newton leaves the bracket: bisect or widen
            step = 0.5 * (low + high) if math.isfinite(high) and low > 0 else (2.0 * x if error < 0 else 0.5 * x)
        if abs(step - x) <= 1e-14 * x:
            return step
        x = step
    return x
