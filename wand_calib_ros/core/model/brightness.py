"""How bright each point's spot was, and the centre bias that brightness can bring.

A detector measures a spot's centre. Where the spot is far over the sensor's full scale, a bloom that spreads
one way, or an LED's bright spot that sits off its centre when seen obliquely, moves the centre by a fraction of
a pixel that grows with the brightness; the residuals stay at the noise while the calibration absorbs it.

A point's brightness is its spot's *stops over full scale*: log2 of the spot's peak (before clipping) over the
image's full scale: 0 where it just reaches full scale, 3 where it is 8x over, negative below, NaN where not
known. Spots below full scale (or of unknown brightness) are what the others are measured against: a bias is
where the centres of brighter spots sit relative to theirs.

Each camera's bias has a *shape* and up to N_BIAS_TERMS terms, each an offset along u and v and a radial one
(along the direction away from the principal point), px. A point's offset is the sum of the terms, each weighted
by the point's brightness (:func:`bias_weights`):

- ``CLASSES``: one term per brightness class (:data:`BIAS_EDGES`, whole stops: 1-2x, 2-4x, ... over 16x full
  scale), weight 1 for a point of that class: any curve, a step anywhere;
- ``LINEAR``: from a class on (its *start*), a term of weight 1 and one that grows per stop beyond the class's
  edge (weight: the stops beyond it);
- ``CONSTANT``: from a class on, a term of weight 1 (a step there);
- ``PROPORTIONAL``: from a class on, a term that grows per stop beyond its edge (zero there: a bloom that grows
  from nothing as the spot saturates).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Where each brightness class starts, stops over full scale (1x, 2x, 4x, 8x and 16x full scale).
BIAS_EDGES = (0.0, 1.0, 2.0, 3.0, 4.0)
#: Brightness classes above full scale (class 0 is below it, or not known).
N_BIAS_CLASSES = len(BIAS_EDGES)
#: The shapes of a camera's bias (module docstring).
CLASSES, LINEAR, CONSTANT, PROPORTIONAL = 0, 1, 2, 3
SHAPE_NAMES = ("classes", "linear", "constant", "proportional")
#: Terms of a camera's bias: as many as brightness classes (the richest shape).
N_BIAS_TERMS = N_BIAS_CLASSES
#: Each term: an offset along u and v, and a radial one, px.
BIAS_COMPONENTS = ("u", "v", "r")
N_BIAS = N_BIAS_TERMS * len(BIAS_COMPONENTS)
#: Within this distance of the principal point a radial offset fades linearly to zero (its direction is not
#: defined at the centre), px.
RADIAL_CORE_PX = 10.0


def brightness_classes(stops: FloatArray) -> NDArray[np.int8]:
    """The brightness class (0..N_BIAS_CLASSES) of each brightness (any shape, stops over full scale; NaN: 0)."""
    classes = np.searchsorted(np.asarray(BIAS_EDGES), np.nan_to_num(stops, nan=-np.inf), side="right")
    return classes.astype(np.int8)


def saturated_of(brightness: FloatArray | None) -> NDArray[np.bool_] | None:
    """Which points (any shape) were saturated spots: a brightness of full scale or more (None: not known)."""
    if brightness is None:
        return None
    with np.errstate(invalid="ignore"):
        return np.asarray(brightness >= 0.0)


def class_text(klass: int) -> str:
    """A brightness class in words: ``1-2x full scale`` ... ``over 16x full scale``."""
    low = 2.0 ** BIAS_EDGES[klass - 1]
    if klass == N_BIAS_CLASSES:
        return f"over {low:.0f}x full scale"
    return f"{low:.0f}-{2.0 ** BIAS_EDGES[klass]:.0f}x full scale"


def radial_directions(uv: FloatArray, principal_point: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Where a radial offset of 1 px moves each point, and its derivative by the principal point.

    Args:
        uv: (M, 2) observed pixels.
        principal_point: (M, 2) the principal point of each point's camera.

    Returns:
        (M, 2) the unit direction away from the principal point (shorter within RADIAL_CORE_PX of it), and
        (M, 2, 2) its derivative by the principal point (u0, v0).
    """
    d = uv - principal_point
    length = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    scale = np.maximum(length, RADIAL_CORE_PX)
    direction = d / scale[:, None]
    outside = length > RADIAL_CORE_PX
    # d direction / d pp: -(I - r r^T) / |d| beyond the core (r the unit direction), -I / core within it.
    derivative = -np.eye(2)[None] / scale[:, None, None]
    derivative[outside] += np.einsum("mi,mj->mij", direction[outside], direction[outside]) / scale[outside, None, None]
    return direction, derivative


def bias_weights(stops: FloatArray, shapes: NDArray[np.int8], starts: NDArray[np.int8]) -> FloatArray:
    """(M, N_BIAS_TERMS) how much each term of its camera's bias moves each point (module docstring).

    Args:
        stops: (M,) each point's brightness, stops over full scale (NaN: not known, no bias).
        shapes: (M,) the shape of each point's camera's bias.
        starts: (M,) the class a LINEAR or CONSTANT shape starts from (1..N_BIAS_CLASSES).
    """
    weights = np.zeros((stops.size, N_BIAS_TERMS))
    classes = brightness_classes(stops)
    by_class = shapes == CLASSES
    rows = np.flatnonzero(by_class & (classes > 0))
    weights[rows, classes[rows] - 1] = 1.0
    from_start = ~by_class & (classes >= np.maximum(starts, 1))
    beyond = np.nan_to_num(stops) - np.asarray(BIAS_EDGES)[np.clip(starts, 1, N_BIAS_CLASSES) - 1]
    weights[:, 0] = np.where(from_start, np.where(shapes == PROPORTIONAL, beyond, 1.0), weights[:, 0])
    weights[:, 1] = np.where(from_start & (shapes == LINEAR), beyond, weights[:, 1])
    return weights


def bias_offsets(bias: FloatArray, weights: FloatArray, direction: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(M, 2) the offset of each point's centre, and (M,) the radial part of it.

    Args:
        bias: (M, N_BIAS) the bias of each point's camera (term by term: u, v, r).
        weights: (M, N_BIAS_TERMS) the point's weight of each term (:func:`bias_weights`).
        direction: (M, 2) the radial directions (:func:`radial_directions`).
    """
    terms = np.einsum("mj,mjc->mc", weights, bias.reshape(bias.shape[0], N_BIAS_TERMS, len(BIAS_COMPONENTS)))
    return terms[:, :2] + terms[:, 2:3] * direction, terms[:, 2]


def bias_basis(weights: FloatArray, direction: FloatArray, parameters: NDArray[np.int64]) -> FloatArray:
    """(M, 2, B) how each point's offset moves with each of the bias ``parameters`` (B,) (indices into a
    camera's (N_BIAS,) bias: term by term u, v, r)."""
    term = parameters // len(BIAS_COMPONENTS)
    axis = parameters % len(BIAS_COMPONENTS)
    basis = np.zeros((weights.shape[0], 2, parameters.size))
    basis[:, 0, axis == 0] = 1.0
    basis[:, 1, axis == 1] = 1.0
    basis[:, :, axis == 2] = direction[:, :, None]
    basis *= weights[:, None, term]
    return basis
