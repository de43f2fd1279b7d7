"""The held-out check: the surrogate against K extra model runs at random inputs.

:func:`holdout_error` gives the RMS error of the surrogate and an upper confidence bound on it
that fits K; and, with the surrogate as a control variate, the errors of the mean and of the
standard deviation themselves (:func:`statistics_error`), which are what the error bars show,
and the mean and std those runs correct.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from statistics import NormalDist

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: The fewest held-out runs whose standard error is read from neighbouring pairs
#: (:func:`_standard_error`); fewer are taken as independent draws.
PAIRED_FROM = 16
#: ... and the largest kurtosis of an input's pair differences, P Σ d⁴ / (Σ d²)² over its P
#: pairs, at which they stand (a normal's is 3; a few pairs carrying the sum push it to P).
PAIRED_KURTOSIS = 10.0
#: The standard normal distribution, whose quantiles scale standard errors to confidence bounds.
STANDARD_NORMAL = NormalDist()
#: Confidence level of the held-out upper bound, and the one-sided level at which the verdict
#: calls an estimated error above (or below) the tolerance.
CONFIDENCE = 0.9


def _rms_over_scale(differences: NDArray[np.float64], scale: float, count: float) -> NDArray:
    """√(Σ d² / count) / scale over the first axis, scaled before squaring (no overflow)."""
    if not scale > 0 or not np.isfinite(scale):
        return np.zeros(differences.shape[1:])
    return np.sqrt(np.sum((differences / scale) ** 2, axis=0) / count)


@dataclass(frozen=True)
class HeldOutCheck:
    """The surrogate against K held-out model runs at random inputs.

    Attributes
    ----------
    error:
        (T,) RMS of surrogate minus model over the runs, over the scale.
    upper:
        (T,) upper confidence bound on the RMS error over the inputs' distribution, over
        the scale: with probability ``confidence`` the true RMS error is below it when the
        errors at the K inputs are roughly normal (χ² bound with K degrees of freedom).
    mean_error, std_error:
        (T,) estimated errors of the expansion's mean and standard deviation, over the scale
        (:func:`statistics_error`).
    spread:
        (T,) standard error of the larger of the two estimates (:attr:`statistics`), over the
        scale: how finely K runs resolve the error the verdict judges.
    corrected_mean, corrected_std:
        (T,) the mean and std corrected by the held-out runs (the surrogate as a control
        variate), in the output's units.
    corrected_mean_se, corrected_std_se:
        (T,) their standard errors, in the output's units.
    count:
        K, the finite runs used.
    confidence:
        The bound's confidence level.
    """

    error: NDArray[np.float64]
    upper: NDArray[np.float64]
    mean_error: NDArray[np.float64]
    std_error: NDArray[np.float64]
    spread: NDArray[np.float64]
    corrected_mean: NDArray[np.float64]
    corrected_std: NDArray[np.float64]
    corrected_mean_se: NDArray[np.float64]
    corrected_std_se: NDArray[np.float64]
    count: int
    confidence: float

    @property
    def statistics(self) -> NDArray[np.float64]:
        """(T,) the larger of the estimated errors of the mean and the std."""
        return np.fmax(self.mean_error, self.std_error)

    def widened(self, error: ArrayLike, scale: float) -> HeldOutCheck:
        """This check with ``error`` (T,), over the scale, added in quadrature to its standard
        errors (:attr:`spread`, and those of the corrected mean and std)."""
        error = np.asarray(error, dtype=float)
        return replace(
            self,
            spread=np.hypot(self.spread, error),
            corrected_mean_se=np.hypot(self.corrected_mean_se, error * scale),
            corrected_std_se=np.hypot(self.corrected_std_se, error * scale),
        )

    @property
    def noise(self) -> NDArray[np.float64]:
        """(T,) how far :attr:`statistics` may lie from the truth at the one-sided
        ``confidence``: the standard error times its normal quantile (1.28 at 90 %)."""
        return STANDARD_NORMAL.inv_cdf(self.confidence) * self.spread


def _standard_error(
    values: NDArray[np.float64], germ: NDArray[np.float64] | None
) -> NDArray[np.float64]:
    """(T,) standard error of the mean of (K, T) values drawn as a Latin hypercube at ``germ``
    ((K, n); ``None``: independent draws, sd/√K).

    A Latin hypercube stratifies every input, so its mean varies far less than that of
    independent draws (the double well at K = 32: 8 times less). Sorted along input k, the
    K runs pair with their neighbours, and Σ (y_a - y_b)² / (2 K · K/2) estimates the
    variance of a mean stratified along k alone, which bounds the Latin hypercube's (it
    stratifies k and the others); the smallest over the inputs is the estimate, never
    above sd/√K. Below ``PAIRED_FROM`` runs the few pairs' estimate is itself too noisy (a
    bouncing ball at K = 8: three flags on noise in ten seeds), and sd/√K stands; so it does
    along an input whose pair differences d have a kurtosis above ``PAIRED_KURTOSIS``: a
    residual spiking at one end of the input (a pole) puts its variance in the one slice
    whose pair is small in most draws (3 times too small a standard error at K = 56).
    """
    count = values.shape[0]
    plain = values.std(axis=0, ddof=1) / np.sqrt(count)
    if germ is None or count < PAIRED_FROM:
        return plain
    even = count // 2 * 2
    found = plain
    for column in np.asarray(germ, dtype=float).T:
        ordered = values[np.argsort(column, kind="stable")]
        squares = (ordered[1:even:2] - ordered[0:even:2]) ** 2
        total = squares.sum(axis=0)
        tails = squares.shape[0] * np.sum(squares * squares, axis=0)
        shared = tails <= PAIRED_KURTOSIS * total * total
        paired = np.sqrt(np.mean(squares, axis=0) / (2 * count))
        found = np.where(shared, np.fmin(found, paired), found)
    return found


@dataclass(frozen=True)
class _ControlVariate:
    """The held-out runs' corrections of the mean and std (:func:`statistics_error`), over the
    scale, with their standard errors."""

    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    mean_se: NDArray[np.float64]
    std_se: NDArray[np.float64]


def _control_variate(
    predicted: NDArray[np.float64],
    observed: NDArray[np.float64],
    mean: ArrayLike,
    std: ArrayLike,
    scale: float,
    weights: NDArray[np.float64],
    germ: NDArray[np.float64] | None,
) -> _ControlVariate:
    """The corrected mean and std over the scale (see :func:`statistics_error`); ``weights``
    (K,) or, per time, (K, T)."""
    count = predicted.shape[0]
    weight = weights[:, None] if weights.ndim == 1 else weights
    residual = (observed - predicted) / scale
    centred = (predicted - np.asarray(mean, dtype=float)) / scale
    sigma = np.asarray(std, dtype=float) / scale
    change = weight * (2 * centred + residual) * residual
    residual = weight * residual
    bias = residual.mean(axis=0)
    corrected = np.sqrt(np.maximum(sigma**2 + change.mean(axis=0) - bias**2, 0.0))
    if count < 2:
        infinite = np.full(bias.shape, np.inf)
        return _ControlVariate(np.asarray(mean) / scale + bias, corrected, infinite, infinite)
    mean_se = _standard_error(residual, germ)
    # Δσ = ΔV / (σ + σ'): the variance's standard error carried to the std; √ΔV where
    # neither varies.
    variance_se = _standard_error(change, germ)
    both = sigma + corrected
    std_se = np.sqrt(variance_se)
    np.divide(variance_se, both, out=std_se, where=both > 0)
    return _ControlVariate(np.asarray(mean) / scale + bias, corrected, mean_se, std_se)


def statistics_error(
    predicted: ArrayLike,
    observed: ArrayLike,
    mean: ArrayLike,
    std: ArrayLike,
    scale: float,
    weights: ArrayLike | None = None,
    germ: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Errors of the expansion's mean and std, estimated from K held-out runs.

    The surrogate s is a control variate whose mean μ and std σ are known exactly; with
    r = f - s at the runs, E f = μ + E r and Var f = σ² + E[2 (s - μ) r + r²] - (E r)². The
    weighted sample means of r and of q = 2 (s - μ) r + r² (importance weights w of the
    draws, :func:`held_out_draws`) estimate both without bias, with standard errors
    sd(w r)/√K and sd(w q)/√K (less for a Latin hypercube, :func:`_standard_error`); their
    noise is that of the residual, not of the output,
    so K = 32 runs resolve errors of a few percent of the std where plain sampling of f
    would need thousands. The surrogate's pointwise error bounds both (|Δ mean|,
    |Δ std| <= RMS r) but is often much larger: collocation statistics are quadratures, exact
    to a higher degree than the surrogate's values.

    Parameters
    ----------
    predicted, observed:
        (K, T) surrogate and model values at the same K inputs (finite rows only).
    mean, std:
        (T,) the expansion's mean and standard deviation.
    scale:
        The output's largest standard deviation over time.
    weights:
        (K,) importance weights of the runs (default: 1).
    germ:
        (K, n) germ of the runs when they are a Latin hypercube: a smaller standard error
        (:func:`_standard_error`; default: independent draws).

    Returns
    -------
    mean_error, std_error, spread:
        (T,) |estimated error of the mean|, |estimated error of the std| and the standard
        error of the larger of them, all over the scale (scaled before squaring: no overflow).
    """
    found = holdout_error(predicted, observed, mean, std, scale, weights=weights, germ=germ)
    return found.mean_error, found.std_error, found.spread


def chi_square_quantile(dof: int, probability: float) -> float:
    """The quantile of the χ² law of ``dof`` >= 1 (whole) degrees of freedom at
    ``probability``, by bisection on its closed-form survival function: scipy.special's
    ``gammaincinv`` gives the same to 1e-12 for probabilities in [0.01, 0.99], and its
    import (0.2 s) was most of the held-out check's cost."""
    low, high = 0.0, dof + 20.0 * math.sqrt(2.0 * dof) + 100.0
    while high - low > 1e-13 * high:
        middle = 0.5 * (low + high)
        if _chi_square_survival(middle, dof) > 1.0 - probability:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def _chi_square_survival(x: float, dof: int) -> float:
    """P(χ²_dof > x): e^(-x/2) Σ_j (x/2)^(j+s) / Γ(j+s+1) over j < dof // 2 terms (s = 0),
    plus erfc(√(x/2)) with s = ½ and (dof - 1) // 2 terms for an odd ``dof``; the terms in
    logarithms, so that a large ``dof`` does not underflow."""
    half = 0.5 * x
    if half == 0.0:
        return 1.0
    offset = 0.5 * (dof % 2)
    j = np.arange((dof - 1) // 2 if dof % 2 else dof // 2)
    log_gamma = math.lgamma(offset + 1.0) + np.concatenate(
        ([0.0], np.cumsum(np.log(j[1:] + offset)))
    )
    terms = np.exp(-half + (j + offset) * math.log(half) - log_gamma)
    return float(terms.sum()) + (math.erfc(math.sqrt(half)) if dof % 2 else 0.0)


def holdout_error(
    predicted: ArrayLike,
    observed: ArrayLike,
    mean: ArrayLike,
    std: ArrayLike,
    scale: float,
    confidence: float = CONFIDENCE,
    weights: ArrayLike | None = None,
    germ: ArrayLike | None = None,
) -> HeldOutCheck:
    """The surrogate at K held-out runs: its RMS error with an upper confidence bound, the
    estimated errors of its mean and std (:func:`statistics_error`), and the mean and std
    those runs correct.

    With d_k the errors at K independent inputs drawn from their distribution, Σ d_k² / σ²
    is χ²_K when the d_k are N(0, σ²), so σ <= √(Σ d_k² / χ²_K(1 - confidence)) with the
    given confidence: 1.9 times the RMS estimate for K = 4, 1.4 for K = 10, 1.25 for K = 20
    at 90 %. Errors with heavier tails than the normal (a jump met by few of the K inputs)
    make it optimistic: the spectral decay covers those.

    Parameters
    ----------
    predicted, observed:
        (K, T) surrogate and model values at the same K inputs; rows with a non-finite
        model value (failed runs) are left out.
    mean, std:
        (T,) the expansion's mean and std.
    scale:
        The output's largest standard deviation over time.
    confidence:
        Level of the upper bound, in (0, 1).
    weights:
        (K,) importance weights of the runs (:func:`held_out_draws`; default: 1), or (K, T)
        per time (:func:`diagnose`'s moment weights), which weight the RMS error too: that of
        the inputs' distribution, not of the widened draws.
    germ:
        (K, n) germ of the runs when they are a Latin hypercube (:func:`_standard_error`;
        default: independent draws).

    Returns
    -------
    HeldOutCheck
        Zeros if the scale is zero; NaN if no run is finite.
    """
    predicted, observed = np.atleast_2d(predicted), np.atleast_2d(observed)
    if predicted.shape != observed.shape:
        raise ValueError(f"predicted {predicted.shape} and observed {observed.shape} differ")
    kept = np.isfinite(observed).all(axis=tuple(range(1, observed.ndim)))
    count = int(kept.sum())
    mean, std = np.asarray(mean, dtype=float), np.asarray(std, dtype=float)
    if count == 0:
        nan = np.full(observed.shape[1:], np.nan)
        return HeldOutCheck(nan, nan, nan, nan, nan, nan, nan, nan, nan, 0, confidence)
    weights = np.ones(kept.size) if weights is None else np.asarray(weights, dtype=float)
    # Weighted back to the inputs' distribution: a widened draw far in a tail counts as
    # little as the distribution makes it (a moment weight below zero, as nothing).
    share = np.clip(weights[kept], 0.0, None)
    differences = (predicted[kept] - observed[kept]) * np.sqrt(share.reshape(count, -1))
    quantile = chi_square_quantile(count, 1.0 - confidence)
    if not scale > 0 or not np.isfinite(scale):  # nothing varies: nothing to correct
        zeros = np.zeros(observed.shape[1:])
        corrected = (mean, std, zeros, zeros)
        errors = (zeros, zeros, zeros)
    else:
        germ = None if germ is None else np.asarray(germ, dtype=float)[kept]
        found = _control_variate(
            predicted[kept], observed[kept], mean, std, scale, weights[kept], germ
        )
        corrected = (found.mean * scale, found.std * scale)
        corrected += (found.mean_se * scale, found.std_se * scale)
        mean_error, std_error = np.abs(found.mean - mean / scale), np.abs(found.std - std / scale)
        larger = np.where(mean_error >= std_error, found.mean_se, found.std_se)
        errors = (mean_error, std_error, larger)
    return HeldOutCheck(
        _rms_over_scale(differences, scale, count),
        _rms_over_scale(differences, scale, quantile),
        *errors,
        *corrected,
        count,
        confidence,
    )
