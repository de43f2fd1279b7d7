"""The placed check: a grid of one input against held-out runs that extend its nodes.

:func:`placed_check` compares the design's mean and std with those of the interpolant through
nodes and held-out runs (placed by :func:`~pcmb.analysis.diagnostics.draws.held_out_placed`),
plus the mean's part beyond its degree.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.check import CONFIDENCE, STANDARD_NORMAL, HeldOutCheck
from pcmb.analysis.diagnostics.decay import SHAPE_LAYERS, next_coefficient
from pcmb.chaos.elements import PiecewiseExpansion
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.nested import interpolatory_weights
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.polynomials import OrthonormalFamily

#: A placed check's noise: how far its richer surrogate's statistics move without its last
#: this many held-out runs (:func:`placed_check`); two, as Leja points come in pairs about
#: the centre.
PLACED_SPARE = 2
#: A placed check extrapolates its interpolant's spectrum up to this many times its degree
#: to estimate the mean's error beyond it (:func:`_unseen_mean_error`).
UNSEEN_DEGREES = 3
#: A rule whose error on an orthonormal polynomial is below this integrates it exactly.
_EXACT = 1e-8


def unseen_errors(
    family: OrthonormalFamily,
    points: NDArray[np.float64],
    coefficients: NDArray[np.float64],
    std: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """(T,) estimated errors of the mean (:func:`_unseen_mean_error`) and, with ``std``, of
    the std (:func:`_unseen_std_error`, else ``None``) of the interpolant of (M, T)
    ``coefficients`` through the (M,) germ ``points`` from the degrees beyond it
    (:func:`_unseen_energies`, zero where there are too few degrees to extrapolate)."""
    energies = _unseen_energies(coefficients)
    if energies is None:
        zero = np.zeros(coefficients.shape[1:])
        return zero, zero if std else None
    basis = family.evaluate(points, coefficients.shape[0] + energies.shape[0] - 1)
    mean = _unseen_mean_error(family, points, energies, basis)
    return mean, _unseen_std_error(family, points, coefficients, energies, basis) if std else None


def _unseen_mean_error(
    family: OrthonormalFamily,
    points: NDArray[np.float64],
    energies: NDArray[np.float64],
    basis: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(T,) estimated error of the mean of the interpolant through the (M,) germ ``points``
    from the (U, T) ``energies`` of the degrees M to M + U - 1 beyond it, the (M, M + U)
    ``basis`` at the points: the error of its interpolatory rule on them. Where the design's
    own rule integrates every degree below M exactly, the two rules agree on every response,
    and this is the design mean's error itself."""
    rule_errors = interpolatory_weights(family, points) @ basis
    return np.sqrt(np.sum(energies * rule_errors[points.size :, None] ** 2, axis=0))


def _unseen_std_error(
    family: OrthonormalFamily,
    points: NDArray[np.float64],
    coefficients: NDArray[np.float64],
    energies: NDArray[np.float64],
    basis: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(T,) estimated error of the std of the interpolant of (M, T) ``coefficients`` through
    the (M,) germ ``points`` from the (U, T) ``energies`` beyond it (``basis`` as in
    :func:`_unseen_mean_error`): each aliases onto degrees 1 to M - 1 as its own interpolant
    there, which moves the std by that interpolant's projection on the interpolant's own
    direction (to first order)."""
    aliased = interpolated(family, points, basis[:, points.size :])[1:]
    varying = coefficients[1:]
    norm = np.sqrt(np.sum(varying**2, axis=0))
    along = np.divide(aliased.T @ varying, norm, out=np.zeros(energies.shape), where=norm > 0)
    return np.sqrt(np.sum(energies * along**2, axis=0))


def _unseen_energies(coefficients: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """(U, T) extrapolated energies of degrees M to ``UNSEEN_DEGREES`` × M of the function
    whose interpolant has (M, T) ``coefficients``, or None with fewer than ``SHAPE_LAYERS``
    averages to fit (M < 5: an element without placed runs, whose own three degrees once read
    flat extrapolated its 4-point rule's errors into a false alarm).

    The energies of degrees 1 to M - 1 (neighbours averaged), from the spectrum's peak on
    (all of them with fewer than ``SHAPE_LAYERS`` after it), are fitted by a line against p
    and against log p, each extrapolated, and the larger kept."""
    first = coefficients.shape[0]
    # Degrees 1 to M - 1 make M - 2 neighbour averages; fewer than three cannot tell a shape.
    if first - 2 < SHAPE_LAYERS:
        return None
    energy = coefficients[1:] ** 2
    paired = np.log(0.5 * (energy[:-1] + energy[1:]) + np.finfo(float).tiny)
    seen = np.arange(1.0, first - 1)
    fitted = np.arange(seen.size)[:, None] >= np.argmax(paired, axis=0)
    fitted[:, fitted.sum(axis=0) < SHAPE_LAYERS] = True
    unseen = np.arange(first, UNSEEN_DEGREES * first + 1.0)[:, None]
    tails = [
        _extrapolated(transform(seen), paired, fitted, transform(unseen))
        for transform in (np.asarray, np.log)
    ]
    return np.fmax(*tails)


def _extrapolated(
    x: NDArray[np.float64], y: NDArray[np.float64], fitted: NDArray[np.bool_], at: NDArray
) -> NDArray[np.float64]:
    """(U, T) exp of the least-squares line through the (P, T) ``y`` against the (P,) ``x``
    where ``fitted``, column by column, at the (U, 1) ``at``; a rising line is held flat."""
    count = fitted.sum(axis=0)
    x_mean = (fitted * x[:, None]).sum(axis=0) / count
    y_mean = np.where(fitted, y, 0.0).sum(axis=0) / count
    dx = np.where(fitted, x[:, None] - x_mean, 0.0)
    slope = (dx * np.where(fitted, y - y_mean, 0.0)).sum(axis=0) / (dx**2).sum(axis=0)
    slope = np.minimum(slope, 0.0)
    return np.exp(y_mean + slope * (at - x_mean))


def interpolated(
    family: OrthonormalFamily, germ: NDArray[np.float64], values: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(M, T) coefficients of the polynomial of degree M - 1 through M runs of one input,
    in its orthonormal basis: its mean is the first, its variance the sum of the others'
    squares. Each row is scaled by √(germ density), as the weighted Leja points are chosen:
    the same solution, but well conditioned (at 67 Hermite points: 10, not 10³⁰)."""
    root = np.sqrt(family.germ.pdf(germ))[:, None]
    return np.linalg.solve(root * family.evaluate(germ, germ.size - 1), root * values)


def placed_check(
    expansion: ChaosExpansion | PiecewiseExpansion,
    node_germ: ArrayLike,
    node_values: ArrayLike,
    germ: ArrayLike,
    observed: ArrayLike,
    scale: float,
    confidence: float = CONFIDENCE,
) -> HeldOutCheck:
    """The held-out check of a one-input expansion by K runs placed to extend its N nodes
    (:func:`held_out_placed`; per element, :func:`held_out_placed_elements`).

    Nodes and held-out runs are interpolated by one polynomial of degree N + K - 1 in the
    orthonormal basis (of each element, in its own coordinate), a far richer surrogate than the
    expansion (Leja points keep the interpolation well conditioned); its mean and std (exact: c_0
    and √Σ_{i>=1} c_i²; the elements' combined by their probabilities) are the corrected mean and
    std, and their differences from the expansion's the estimated errors, the mean's plus the
    interpolant's own error from the degrees beyond it (:func:`_unseen_mean_error`; where the two
    means agree exactly, K <= N placed runs beside N Gauss nodes, the design mean's whole error).
    Their standard errors are how far the estimates move when the last ``PLACED_SPARE`` held-out
    runs (of each element) are left out, shrunk by the rate at which they converge
    (:func:`converging`; infinite with no more runs than that), plus in quadrature the next
    coefficient of each element without held-out runs (:func:`next_coefficient`: nothing checks
    it) and, for the std, the interpolant's own error from the degrees beyond it
    (:func:`_unseen_std_error`; at most each element's L2 distance); the spread is that of the
    larger estimate (:func:`larger_spread`; the corrected mean's adds the unseen error); the
    surrogate error is the L2 distance of the two surrogates (their coefficients' difference), its
    upper bound that plus how far it moves.
    Runs that are not finite are left out; zeros if the scale is zero.
    """
    observed = np.atleast_2d(np.asarray(observed, dtype=float))
    kept = np.isfinite(observed).all(axis=1)
    count = int(kept.sum())
    mean, std = expansion.mean(), expansion.std()
    if not scale > 0 or not np.isfinite(scale):
        zeros = np.zeros(observed.shape[1:])
        return HeldOutCheck(*[zeros] * 5, mean, std, zeros, zeros, count, confidence)
    node_values = np.asarray(node_values, dtype=float)
    runs = np.isfinite(node_values).all(axis=1)
    probability, pieces = _placed_pieces(
        expansion,
        np.ravel(node_germ)[runs],
        node_values[runs],
        np.ravel(germ)[kept],
        observed[kept],
    )

    def moments(spare: int) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray | None]:
        """The check's statistics without the last ``spare`` held-out runs (the unseen std
        error only with all of them, ``spare`` 0, the only fit it is read from)."""
        found = [_placed_moments(*piece, scale, spare) for piece in pieces]
        means, stds, errors, unseen, unseen_std = (
            np.array(column) for column in zip(*found, strict=True)
        )
        rich_mean = np.sum(probability * means, axis=0)
        variance = np.sum(probability * (stds**2 + (means - rich_mean) ** 2), axis=0)
        rich_std = np.sqrt(variance)
        own_std_error = None
        if spare == 0:
            # Each element's own std error, at most its distance from the expansion (the
            # premise: the interpolant errs less than the design), moves the whole std by
            # p_e s_e / std.
            own = np.sqrt(np.sum((probability * stds * np.fmin(unseen_std, errors)) ** 2, axis=0))
            own_std_error = np.divide(own, rich_std, out=np.zeros_like(own), where=rich_std > 0)
        return (
            rich_mean,
            rich_std,
            np.sqrt(np.sum(probability * errors**2, axis=0)),
            np.sum(probability * unseen, axis=0),
            own_std_error,
        )

    rich_mean, rich_std, error, unseen, unseen_std = moments(0)
    # The elements without held-out runs, which nothing checks, add their next coefficients.
    unchecked = np.sqrt(
        sum(
            (p * next_coefficient(own / scale)) ** 2
            for p, (_, points, _, nodes, own) in zip(probability[:, 0], pieces, strict=True)
            if points.size == nodes
        )
    )
    mean_error, std_error = (
        np.abs(rich_mean - mean / scale) + unseen,
        np.abs(rich_std - std / scale),
    )
    if count > PLACED_SPARE:
        fewer_mean, fewer_std, fewer_error, fewer_unseen, _ = moments(PLACED_SPARE)
        fewer_mean_error = np.abs(fewer_mean - mean / scale) + fewer_unseen
        # The unseen mean's noise, like the rest, is how far the estimate holding it moves (its
        # size is a bias, which the corrected mean, leaving it out, adds to that noise); the
        # elements without runs, which nothing checks, add their next coefficients.
        mean_moved, std_moved = np.abs(mean_error - fewer_mean_error), np.abs(rich_std - fewer_std)
        if count > 2 * PLACED_SPARE:
            least_mean, least_std, _, least_unseen, _ = moments(2 * PLACED_SPARE)
            least_mean_error = np.abs(least_mean - mean / scale) + least_unseen
            mean_moved = converging(mean_moved, np.abs(fewer_mean_error - least_mean_error))
            std_moved = converging(std_moved, np.abs(fewer_std - least_std))
        mean_se = np.hypot(mean_moved, unchecked)
        std_se = np.hypot(np.hypot(std_moved, unseen_std), unchecked)
        moved = np.abs(error - fewer_error)
    else:
        mean_se = std_se = moved = np.full(observed.shape[1], np.inf)
    return placed_result(
        (error, mean_error, std_error),
        (moved, mean_se, std_se, mean_se + unseen),
        (rich_mean, rich_std),
        scale,
        count,
        confidence,
    )


def placed_result(
    errors: tuple[NDArray, NDArray, NDArray],
    moves: tuple[NDArray, NDArray, NDArray, NDArray],
    corrected: tuple[NDArray, NDArray],
    scale: float,
    count: int,
    confidence: float,
) -> HeldOutCheck:
    """The check of ``count`` placed runs from its (T,) estimates over the scale: ``errors``,
    the richer surrogate's L2 distance from the expansion and the errors of the mean and std;
    ``moves``, how far the distance moves and the standard errors of the two errors and of
    the corrected mean; ``corrected``, the richer surrogate's mean and std. The surrogate
    error's upper bound is the distance plus its move, the spread that of the larger
    estimate (:func:`larger_spread`)."""
    distance, mean_error, std_error = errors
    moved, mean_se, std_se, corrected_mean_se = moves
    return HeldOutCheck(
        distance,
        distance + moved,
        mean_error,
        std_error,
        larger_spread(mean_error, mean_se, std_error, std_se, confidence),
        corrected[0] * scale,
        corrected[1] * scale,
        corrected_mean_se * scale,
        std_se * scale,
        count,
        confidence,
    )


def larger_spread(
    mean_error: NDArray[np.float64],
    mean_se: NDArray[np.float64],
    std_error: NDArray[np.float64],
    std_se: NDArray[np.float64],
    confidence: float,
) -> NDArray[np.float64]:
    """(T,) standard error of the larger of the two estimates, each with its own: the larger
    lies above the larger of their lower confidence bounds (a std estimate that is mostly the
    interpolant's own error leaves a steady mean's flag standing)."""
    quantile = STANDARD_NORMAL.inv_cdf(confidence)
    lower = np.fmax(mean_error - quantile * mean_se, std_error - quantile * std_se)
    return (np.fmax(mean_error, std_error) - lower) / quantile


def converging(moved: NDArray[np.float64], before: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T,) what is left of an estimate's error after its last move ``moved`` (without the last
    ``PLACED_SPARE`` runs), the move ``before`` it (without as many more) giving the rate ρ:
    a geometric convergence leaves ρ / (1 − ρ) of the last move; at most all of it."""
    rate = np.divide(moved, before, out=np.ones_like(moved), where=before > 0)
    left = np.divide(rate, 1.0 - rate, out=np.ones_like(rate), where=rate < 0.5)
    return moved * left


def _placed_pieces(
    expansion: ChaosExpansion | PiecewiseExpansion,
    node_germ: NDArray[np.float64],
    node_values: NDArray[np.float64],
    germ: NDArray[np.float64],
    observed: NDArray[np.float64],
) -> tuple[NDArray[np.float64], list[tuple[OrthonormalFamily, NDArray, NDArray, int, NDArray]]]:
    """(E, 1) the element probabilities (one element for a :class:`ChaosExpansion`) and per
    element its family, points (its nodes, then its held-out runs, in its own coordinate),
    their values, its number of nodes and its own (S, T) coefficients by degree. An element's
    nodes are its own Gauss nodes, their values its expansion's there (which interpolates
    them): the design's runs also hold the nodes of the elements split on the way."""
    degrees = expansion.multi_index[:, 0]
    order = int(degrees.max())

    def own(coefficients: NDArray[np.float64], size: int) -> NDArray[np.float64]:
        padded = np.zeros((max(size, order + 1), *coefficients.shape[1:]))
        padded[degrees] = coefficients
        return padded

    if isinstance(expansion, ChaosExpansion):
        family = expansion.distributions[0].family
        points = np.concatenate([node_germ, germ])
        values = np.vstack([node_values, observed])
        coefficients = own(expansion.coefficients, points.size)
        return np.ones((1, 1)), [(family, points, values, node_germ.size, coefficients)]
    partition = expansion.partition
    distribution = partition.distributions[0]
    physical = distribution.to_physical(germ)
    where = partition.locate(physical[:, None])
    pieces = []
    for e, (conditional,) in enumerate(partition.inputs):
        nodes = TensorGrid((conditional,), (order,)).nodes[:, 0]
        basis = conditional.family.evaluate(nodes, order)[:, degrees]
        points = np.concatenate([nodes, conditional.to_germ(physical[where == e])])
        values = np.vstack([basis @ expansion.coefficients[e], observed[where == e]])
        coefficients = own(expansion.coefficients[e], points.size)
        pieces.append((conditional.family, points, values, nodes.size, coefficients))
    return partition.probability[:, None], pieces


def _placed_moments(
    family: OrthonormalFamily,
    points: NDArray[np.float64],
    values: NDArray[np.float64],
    nodes: int,
    own: NDArray[np.float64],
    scale: float,
    spare: int,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray | None]:
    """(T,) mean, std, L2 distance from ``own`` (the expansion's coefficients), unseen
    mean error (:func:`_unseen_mean_error`; where the design's rule is not exact on the
    interpolant's degrees, at most its mean's difference from the design's) and unseen std
    error (:func:`_unseen_std_error`; ``None`` where ``spare`` is not 0) of the interpolant
    through an element's nodes and held-out runs (its first ``nodes`` points are its nodes)
    without its last ``spare`` held-out runs, over the scale."""
    kept = max(nodes, points.size - spare)
    own = own / scale
    coefficients = interpolated(family, points[:kept], values[:kept] / scale)
    missed = np.sum((coefficients - own[:kept]) ** 2, axis=0)
    unseen, unseen_std = unseen_errors(family, points[:kept], coefficients, std=spare == 0)
    design = points[:nodes]
    rule_errors = interpolatory_weights(family, design) @ family.evaluate(design, kept - 1)
    if not np.allclose(rule_errors[1:], 0.0, atol=_EXACT):
        # The interpolant holds degrees the design's rule does not integrate: its mean measures
        # the design's error, and its own error is, by the check's premise, at most that.
        unseen = np.fmin(unseen, np.abs(coefficients[0] - own[0]))
    return (
        coefficients[0],
        np.sqrt(np.sum(coefficients[1:] ** 2, axis=0)),
        np.sqrt(missed + np.sum(own[kept:] ** 2, axis=0)),
        unseen,
        unseen_std,
    )
