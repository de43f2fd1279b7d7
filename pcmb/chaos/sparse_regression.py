"""Sparse chaos regression: term selection by LARS or OMP, scored by the corrected LOO error.

The hybrid LARS of Blatman & Sudret (J. Comput. Phys. 230, 2011): a greedy path over a
large candidate set (typically hyperbolic, :func:`pcmb.chaos.basis.hyperbolic_index_set`)
proposes nested active sets; each is refitted by ordinary least squares and scored by its
corrected leave-one-out error; the best one is the basis.

One basis serves every time point of an (N, T) output. The path is run on all times at once:
a time-normalised response Ỹ (centred, each time divided by its std) is a point cloud of T
targets, and both selectors extend to it with the Euclidean norm over targets:

- LARS (Similä & Tikka, Comput. Stat. Data Anal. 50, 2006): the active correlations
  ‖x_jᵀR‖₂ decrease together along the move towards the least-squares fit, and the next term
  is the first whose correlation norm catches up (a quadratic per candidate);
- OMP (simultaneous OMP): the term with the largest ‖x_jᵀR‖₂ against the least-squares residual.

Every quantity the path and its score use is a function of ỸỸᵀ only, so Ỹ is replaced by any Z
with ZZᵀ = ỸỸᵀ: its principal components U·S (Ỹ = U S Vᵀ), at most N of them, fewer where the
singular values fall to round-off (13 of 200 for a damped oscillator's displacement). The score
of a step is the relative LOO error summed over time, Σ_t ε_t, the quantity a user reads.

Corrected LOO (Blatman & Sudret Eq. 34; Chapelle, Vapnik & Bengio 2002): the LOO error of an
ordinary least-squares fit with P terms on N nodes, multiplied by
N/(N-P) · (1 + tr(C⁻¹)/N), C = ΨᵀΨ/N, which offsets its optimism on small designs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.chaos.basis import PolynomialBasis
from pcmb.chaos.recovery import fit_least_squares
from pcmb.errors import IllPosedError

__all__ = [
    "SELECTIONS",
    "SelectionPath",
    "SparseFit",
    "fit_sparse",
    "minimum_samples",
    "next_batch",
    "selection_path",
]

Selection = Literal["lars", "omp", "none"]
SELECTIONS: tuple[str, ...] = ("lars", "omp", "none")

#: A candidate whose part orthogonal to the active terms is below this (unit columns) is
#: treated as dependent on them and never enters.
_DEPENDENT = 1e-8
#: Relative size of round-off: times whose std is below it (relative to their RMS) do not vary,
#: and principal components of the response below it (relative to the first) are dropped.
_NOISE = 1e-12
#: The path stops once the least-squares residual is this small relative to the response.
_EXACT = 1e-13


@dataclass(frozen=True)
class SparseFit:
    """A sparse chaos fit of one output.

    Attributes
    ----------
    multi_index:
        (S, n) the selected terms, in candidate order (the zero index first).
    coefficients:
        (S, ...) least-squares coefficients on the selected terms.
    loo_error:
        (...) corrected relative leave-one-out error (NaN where the output does not vary).
    condition:
        Condition number of the information matrix ΨᵀΨ/N of the selected terms.
    """

    multi_index: NDArray[np.int64]
    coefficients: NDArray[np.float64]
    loo_error: NDArray[np.float64]
    condition: float


@dataclass(frozen=True)
class SelectionPath:
    """The nested active sets of a selection path, with their scores."""

    order: NDArray[np.intp]  # candidate columns in the order they entered (constant excluded)
    score: NDArray[np.float64]  # (K + 1,) corrected LOO summed over time, active sets 0..K
    correction: NDArray[np.float64]  # (K + 1,) the LOO correction factors


def _targets(values: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """Z with ZZᵀ = ỸỸᵀ for the time-normalised response Ỹ (times that do not vary dropped),
    its principal components U·S down to singular values of round-off size; with row
    ``weights`` w (mean 1), Ỹ is centred and normalised by weighted means and its rows scaled
    by √w."""
    centred = values - weights @ values / values.shape[0]
    spread = np.sqrt(weights @ centred**2 / values.shape[0])
    scale = np.sqrt(weights @ values**2 / values.shape[0])
    varies = spread > _NOISE * scale
    normalised = centred[:, varies] / spread[varies] * np.sqrt(weights)[:, None]
    if normalised.shape[1] <= 1:
        return normalised
    left, singular, _ = np.linalg.svd(normalised, full_matrices=False)
    rank = int(np.sum(singular > _NOISE * singular[0]))
    return left[:, :rank] * singular[:rank]


def selection_path(
    matrix: NDArray[np.float64],
    values: ArrayLike,
    selection: Selection = "lars",
    weights: ArrayLike | None = None,
) -> SelectionPath:
    """The LARS or OMP path over the columns of a basis matrix, scored by the corrected LOO.

    Parameters
    ----------
    matrix:
        (N, P) basis matrix whose column 0 is the constant term (always kept).
    values:
        (N, ...) responses; the path is shared by all trailing entries.
    selection:
        ``"lars"`` or ``"omp"``.
    weights:
        (N,) positive row weights of a weighted least squares (default: 1): the path of the
        rows scaled by √w after weighted centring, its LOO errors weighted the same way.

    Returns
    -------
    SelectionPath
        Entry order of the columns and the score of every active set along the path (step
        k: the constant and the first k entered columns).
    """
    n_nodes = matrix.shape[0]
    weights = _mean_one(weights, n_nodes)
    target = _targets(np.asarray(values, dtype=float).reshape(n_nodes, -1), weights)
    mean = weights @ matrix / n_nodes
    centred = (matrix - mean) * np.sqrt(weights)[:, None]
    norm = np.sqrt(np.sum(centred**2, axis=0))
    usable = norm > _DEPENDENT * np.sqrt(n_nodes) * np.maximum(1.0, np.abs(mean))
    usable[0] = False
    columns = np.divide(centred, norm, out=np.zeros_like(centred), where=usable)
    steps = min(int(usable.sum()), n_nodes - 2)
    # Q (orthonormal basis of the active centred columns), their triangular factor R in the
    # units of the original columns, and R⁻¹ for tr((ΨᵀΨ)⁻¹) = ‖R⁻¹‖²_F with Ψ = [1, Ψ_A].
    q = np.empty((n_nodes, steps))
    r_inv = np.zeros((steps + 1, steps + 1))
    r_inv[0, 0] = 1.0 / math.sqrt(n_nodes)
    trace = 1.0 / n_nodes
    correlation = columns.T @ target  # (P, r): x_jᵀR for the LARS/OMP residual R
    direction = np.zeros_like(correlation)  # LARS: x_jᵀ P_A R
    residual = target.copy()  # least-squares residual (I - H) Z, Z centred
    leverage = weights / n_nodes
    total = float(np.sum(target**2))
    order: list[int] = []
    score = [_score(residual, leverage, trace, n_nodes, 1)]
    correction = [_correction(trace, n_nodes, 1)]
    level = np.max(np.sum(correlation**2, axis=1), initial=0.0)
    pick = int(np.argmax(np.where(usable, np.sum(correlation**2, axis=1), -1.0)))
    while len(order) < steps and total > 0 and np.sum(residual**2) > _EXACT**2 * total:
        column = columns[:, pick]
        k = len(order)
        coords = q[:, :k].T @ column
        fresh = column - q[:, :k] @ coords
        fresh -= q[:, :k] @ (q[:, :k].T @ fresh)  # re-orthogonalised (CGS2)
        length = float(np.linalg.norm(fresh))
        usable[pick] = False
        if length <= _DEPENDENT:
            correlation[pick] = direction[pick] = 0.0
        else:
            q[:, k] = fresh / length
            order.append(pick)
            # Append the column (√N m_j, s_j R_X[:, j]) / (s_j ρ) of R and update R⁻¹.
            top = np.concatenate(([math.sqrt(n_nodes) * mean[pick]], norm[pick] * coords))
            r_inv[: k + 1, k + 1] = -r_inv[: k + 1, : k + 1] @ top / (norm[pick] * length)
            r_inv[k + 1, k + 1] = 1.0 / (norm[pick] * length)
            trace += float(np.sum(r_inv[: k + 2, k + 1] ** 2))
            projection = q[:, k] @ target
            residual -= np.outer(q[:, k], projection)
            leverage += q[:, k] ** 2
            score.append(_score(residual, leverage, trace, n_nodes, k + 2))
            correction.append(_correction(trace, n_nodes, k + 2))
            update = np.outer(columns.T @ q[:, k], projection)
            if selection == "omp":
                correlation -= update
            else:
                direction += update
        if not usable.any():
            break
        if selection == "omp":
            pick = int(np.argmax(np.where(usable, np.sum(correlation**2, axis=1), -1.0)))
        else:
            step, pick = _lars_step(correlation, direction, level, usable)
            if pick < 0:
                break
            correlation -= step * direction
            direction *= 1.0 - step
            level *= (1.0 - step) ** 2
    return SelectionPath(
        np.asarray(order, dtype=np.intp), np.asarray(score), np.asarray(correction)
    )


def _mean_one(weights: ArrayLike | None, n_nodes: int) -> NDArray[np.float64]:
    """(N,) row weights scaled to mean 1 (all 1 without ``weights``)."""
    if weights is None:
        return np.ones(n_nodes)
    weights = np.asarray(weights, dtype=float)
    return weights * (n_nodes / np.sum(weights))


def _lars_step(
    correlation: NDArray[np.float64],
    direction: NDArray[np.float64],
    level: float,
    usable: NDArray[np.bool_],
) -> tuple[float, int]:
    """The LARS step γ ∈ [0, 1] and the candidate whose correlation norm ‖c_j - γ a_j‖ first
    reaches the active ones' (1 - γ)·√level: the smallest root of a quadratic per candidate
    (pick -1: no candidate catches up)."""
    alpha = np.sum(direction**2, axis=1) - level
    beta = np.sum(correlation * direction, axis=1) - level
    delta = np.minimum(np.sum(correlation**2, axis=1) - level, 0.0)
    denominator = beta - np.sqrt(np.maximum(beta**2 - alpha * delta, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        gamma = np.where(usable & (denominator < 0), delta / denominator, np.inf)
    pick = int(np.argmin(gamma))
    if not np.isfinite(gamma[pick]):
        return 1.0, -1
    return float(np.clip(gamma[pick], 0.0, 1.0)), pick


def _correction(trace: float, n_nodes: int, n_terms: int) -> float:
    """The LOO correction factor N/(N-P) · (1 + tr(C⁻¹)/N), with tr(C⁻¹) = N·tr((ΨᵀΨ)⁻¹)."""
    return n_nodes / (n_nodes - n_terms) * (1.0 + trace) if n_terms < n_nodes else np.inf


def _score(
    residual: NDArray[np.float64],
    leverage: NDArray[np.float64],
    trace: float,
    n_nodes: int,
    n_terms: int,
) -> float:
    """Σ_t of the corrected relative LOO error, from the residual of the normalised response."""
    with np.errstate(divide="ignore"):
        loo = np.sum(residual**2, axis=1) / (1.0 - leverage) ** 2
    return float(np.sum(loo) / n_nodes * _correction(trace, n_nodes, n_terms))


def minimum_samples(n_candidates: int, selection: Selection) -> int:
    """The fewest nodes a fit needs: more than the candidates for plain least squares
    (``"none"``), else 3 (the constant and one term, with a finite corrected LOO error)."""
    return n_candidates + 1 if selection == "none" else 3


def fit_sparse(
    basis: PolynomialBasis,
    nodes: ArrayLike,
    values: ArrayLike,
    selection: Selection = "lars",
    weights: ArrayLike | None = None,
) -> SparseFit:
    """Select terms of a candidate basis and fit them by (weighted) least squares.

    Parameters
    ----------
    basis:
        The candidate basis (P terms, the zero index first).
    nodes:
        (N, n) germ coordinates.
    values:
        (N, ...) model values; one basis is selected for all trailing entries.
    selection:
        ``"lars"`` or ``"omp"`` (hybrid: least squares on every active set along the path,
        the one with the smallest corrected LOO error summed over the trailing entries kept),
        or ``"none"``: least squares on the whole candidate set.
    weights:
        (N,) positive row weights (default: 1), e.g. the importance weights of runs drawn
        from another density than the inputs' (:func:`selection_path`,
        :func:`~pcmb.chaos.recovery.fit_least_squares`); the LOO correction takes them
        scaled to mean 1.

    Returns
    -------
    SparseFit

    Raises
    ------
    ValueError
        If the basis does not start with the zero index or the selection is unknown.
    IllPosedError
        If there are fewer nodes than :func:`minimum_samples` or the selected least-squares
        problem is ill conditioned.
    """
    if selection not in SELECTIONS:
        raise ValueError(f"unknown selection {selection!r}: use {', '.join(SELECTIONS)}")
    if basis.multi_index[0].any():
        raise ValueError("the candidate basis must start with the zero index (the mean term)")
    nodes = np.asarray(nodes, dtype=float)
    values = np.asarray(values, dtype=float)
    n_nodes = nodes.shape[0]
    least = minimum_samples(basis.size, selection)
    if n_nodes < least:
        raise IllPosedError(
            f"{selection} regression on {basis.size} candidate terms needs at least {least} "
            f"nodes, got {n_nodes}"
        )
    matrix = basis.evaluate(nodes)
    if selection == "none":
        keep = np.arange(basis.size)
        root = np.sqrt(_mean_one(weights, n_nodes))[:, None]
        trace = float(np.sum(np.linalg.pinv(matrix * root) ** 2))
        factor = _correction(trace, n_nodes, basis.size)
    else:
        path = selection_path(matrix, values, selection, weights)
        best = int(np.argmin(path.score))
        keep = np.sort(np.concatenate(([0], path.order[:best])))
        factor = float(path.correction[best])
    selected = PolynomialBasis(basis.families, basis.multi_index[keep])
    fit = fit_least_squares(selected, nodes, values, weights)
    return SparseFit(
        selected.multi_index, fit.coefficients, fit.loo_error * factor, fit.condition**2
    )


#: The least growth of a round: rounded up to a power of two, 2N from a power of two, and
#: 1.6 N from 40 runs (64, where doubling's 80 rounded to 128).
GROWTH = 1.5


def next_batch(history: Sequence[tuple[int, float]], tolerance: float, max_samples: int) -> int:
    """How many samples to add before the next fit; 0: stop.

    Stops when the last error (the regression design's estimate of the error of the mean and
    std from the corrected LOO error) meets ``tolerance`` or ``max_samples`` is
    reached. Otherwise the next total extrapolates the error's observed decay
    ε ∝ N^(-rate) from the last two rounds to the size that meets the tolerance (1.5 N when
    there is no decay to extrapolate yet), kept between 1.5 N and 8N and rounded up to a power
    of two (the sizes at which Sobol' points are balanced: from a power of two, at least 2N),
    and capped at ``max_samples``.

    Parameters
    ----------
    history:
        (samples, error) of every fit so far.
    tolerance:
        The error wanted.
    max_samples:
        The largest total number of samples.
    """
    samples, error = history[-1]
    if error <= tolerance or samples >= max_samples:
        return 0
    wanted = GROWTH * samples
    if len(history) > 1:
        before, error_before = history[-2]
        if 0 < error < error_before and samples > before:
            rate = math.log(error_before / error) / math.log(samples / before)
            wanted = samples * (error / tolerance) ** (1.0 / rate)
    wanted = min(max(wanted, GROWTH * samples), 8.0 * samples)
    total = min(2 ** math.ceil(math.log2(wanted)), max_samples)
    return total - samples
