"""The spectral decay: how much of the largest variance the outer layers of the index set carry.

:func:`spectral_decay` is the share of the largest variance carried by the outer two layers of
the index set (terms of degree >= 2 only) — the top two total degrees of a total basis, the top
two degrees of each input of a tensor basis. An expansion that converges has little there; two
layers rather than one, because a response even in a symmetric input has exactly zero odd
coefficients, so its top shell alone can be empty while the expansion is far from converged.
Also the coefficients' energies, an element's top layer and next coefficient, and the shape of
an input's decay, which the placed check and the remedy read.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.basis import tail_terms
from pcmb.chaos.elements import PiecewiseExpansion
from pcmb.chaos.expansion import ChaosExpansion

#: A top coefficient below this share of the one before is a parity's zero (a response even
#: or odd about an element's centre), not a converged tail.
_PARITY = 1e-8
#: The fewest degrees after the peak of an input's spectrum that tell its decay's shape.
SHAPE_LAYERS = 3
#: The expansions the diagnostics judge: one element, or a multi-element one.
Expansion = ChaosExpansion | PiecewiseExpansion


def largest_std(std: NDArray[np.float64]) -> float:
    """The largest of an expansion's ``std`` over time (the scale of its diagnostics), 0 where
    none is finite."""
    finite = std[np.isfinite(std)]
    return float(finite.max()) if finite.size else 0.0


def coefficient_energies(expansion: Expansion, scale: float = 1.0) -> NDArray[np.float64]:
    """(S, T) the squared coefficients over ``scale`` (scaled before squaring: outputs near
    1e200), summed over the elements by their probability."""
    if isinstance(expansion, PiecewiseExpansion):
        weights = expansion.partition.probability
        return np.einsum("e,es...->s...", weights, (expansion.coefficients / scale) ** 2)
    return (expansion.coefficients / scale) ** 2


def spectral_decay(expansion: Expansion, scale: float) -> NDArray[np.float64]:
    """(T,) share of the largest variance carried by the tail terms (:func:`tail_terms`);
    of a multi-element expansion, the elements' tails weighted by their probability.

    Σ_{α in tail} c_α² / scale²: a converged expansion has little energy in its outer
    layers. As a share of variance it is the square of the tail's norm over the scale, so
    it reaches the tolerance where the tail's norm is √tolerance (22 % at 5 %) of the
    largest standard deviation: the outer layers overstate the truncation error of smooth
    responses by a factor 3–6 (the pendulum at order 7), so their norm alone would raise
    false alarms, while a spectrum that does not decay (a jump, chaos) passes this mark.
    Zero where the scale is zero.
    """
    if not scale > 0 or not np.isfinite(scale):
        return np.zeros(expansion.shape)
    return np.sum(coefficient_energies(expansion, scale)[tail_terms(expansion.multi_index)], axis=0)


def top_layer(coefficients: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """(T,) |top coefficient| of (M, T) ``coefficients`` by degree, or, where a parity zeroes
    it (below ``_PARITY`` of the one before), of the one before; and (T,) its ratio to the
    coefficient of its parity before it, at most 1 (1 where only the mean is before it)."""
    size = np.abs(coefficients[1:])  # degrees 1 to M - 1
    zero = np.zeros(size.shape[1:])

    def degree_below(steps: int) -> NDArray[np.float64]:
        return size[-1 - steps] if size.shape[0] > steps else zero

    parity = size[-1] <= _PARITY * degree_below(1)
    top = np.where(parity, degree_below(1), size[-1])
    before = np.where(parity, degree_below(3), degree_below(1))
    return top, np.where(before > top, top / np.where(before > 0, before, 1.0), 1.0)


def next_coefficient(coefficients: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T,) |the next coefficient| beyond an element's (M, T) expansion, what nothing checks
    where no held-out run is: its top one times their ratio to the one before of its parity
    (at most 1; :func:`top_layer`)."""
    top, ratio = top_layer(coefficients)
    return top * ratio


def decay_shape(
    energy: NDArray[np.float64], multi_index: NDArray[np.int64], k: int
) -> tuple[str, float, int, int] | None:
    """How the chaos coefficients' energy along input k falls with its degree p, from the
    spectrum's peak to the top degree: ``("algebraic", s, first, top)`` with energy ~ p^-s (a
    jump: s ≈ 2, a kink: s ≈ 4; a higher order resolves it slowly), or ``("geometric", r,
    first, top)`` with energy ~ r^p (an analytic response: a higher order resolves it);
    ``None`` when fewer than ``SHAPE_LAYERS`` degrees follow the peak.

    The energy of degree p is that of the terms of degree p in k, averaged with degree p + 1:
    a response even or odd about the centre has every other coefficient zero. Of two straight
    lines through its logarithm, against p and against log p, the closer one names the shape.
    """
    degrees = multi_index[:, k]
    by_degree = np.bincount(degrees, weights=energy, minlength=degrees.max() + 1)[1:]
    pairs = (by_degree[:-1] + by_degree[1:]) / 2
    if pairs.size == 0 or not np.all(pairs > 0):
        return None
    peak = int(np.argmax(pairs))
    centres = np.arange(peak, pairs.size) + 1.5
    logs = np.log(pairs[peak:])
    if centres.size < SHAPE_LAYERS:
        return None
    fits = {}
    for shape, x in (("geometric", centres), ("algebraic", np.log(centres))):
        slope, intercept = np.polyfit(x, logs, 1)
        fits[shape] = (float(np.sum((slope * x + intercept - logs) ** 2)), slope)
    shape = min(fits, key=lambda name: fits[name][0])
    slope = fits[shape][1]
    rate = float(-slope) if shape == "algebraic" else float(np.exp(slope))
    return shape, rate, peak + 1, int(degrees.max())
