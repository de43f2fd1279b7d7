"""The held-out runs: how many, and where.

K is sized to the design (:func:`held_out_budget`); :func:`held_out_draws` draws a Latin
hypercube of the inputs' distribution, normal inputs widened into their tails and weighted
back, by moment weights where the surrogate is linear in them. A grid of one input places its
held-out runs instead (:func:`held_out_placed`: Leja points extending its nodes; per element,
:func:`held_out_placed_elements`). :class:`HeldOut` holds the runs made.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.check import STANDARD_NORMAL
from pcmb.analysis.diagnostics.decay import Expansion, coefficient_energies, top_layer
from pcmb.analysis.diagnostics.placed import interpolated
from pcmb.chaos.basis import tail_terms
from pcmb.chaos.elements import Partition
from pcmb.chaos.expansion import RELATIVE_NOISE
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nested import leja_sequence
from pcmb.chaos.nodes import NodeSet, latin_hypercube, unit_nodes
from pcmb.chaos.polynomials import Hermite
from pcmb.chaos.truncated import MAX_TERMS

#: By default the held-out check makes at most this many runs or this share of the design's
#: runs, the larger (:func:`held_out_budget`; ``method.validation: K`` fixes K instead) ...
HELD_OUT_FLOOR, HELD_OUT_SHARE = 8, 0.25
#: ... in a first batch of at most this many, and the rest only where the verdict is undecided.
FIRST_BATCH = 8
#: Largest second moment of the importance weights of the held-out draws (:func:`held_out_draws`):
#: the weighted runs count at least as 1/this many plain ones.
WEIGHT_MOMENT = 3.0
#: Widened held-out draws of a normal germ stay within ±this (:func:`held_out_draws`): the
#: standard normal's mass beyond is 2·10⁻⁹, and a widened draw there would weigh at most 2·10⁻⁷.
TAIL_BOUND = 6.0
#: The surrogate is linear in the widened inputs where the terms of degree 2 or more along
#: them hold at most this share of its variance (:func:`linear_in_widened`).
LINEAR_SHARE = 1e-6
#: Most points (nodes and placed held-out runs) in one element of a one-input multi-element
#: design (:func:`held_out_placed_elements`): a truncated family's Leja points need four
#: times as many recurrence terms as points.
ELEMENT_POINTS = MAX_TERMS // 4
#: Added to ``method.seed`` for the held-out draws, so that they are not a sampling
#: design's own first nodes.
HELD_OUT_SEED = 7919


def held_out_budget(design_runs: int) -> int:
    """The most held-out runs a check makes by default: ``HELD_OUT_FLOOR`` or
    ``HELD_OUT_SHARE`` of the design's runs (rounded down: at most that share), the larger."""
    return max(HELD_OUT_FLOOR, math.floor(HELD_OUT_SHARE * design_runs))


def _tail_width(normal_inputs: int) -> float:
    """λ of the N(0, λ²) draws of each of m normal germs: the widest that keeps the weights'
    second moment E[w²] = (λ² / √(2λ² - 1))^m at ``WEIGHT_MOMENT`` (λ = 4.2 for one normal
    input, 2.3 for two, 1.7 for four), less with the plain draws beyond ±``TAIL_BOUND``."""
    b = WEIGHT_MOMENT ** (1.0 / normal_inputs)
    return math.sqrt(b * b + b * math.sqrt(b * b - 1.0))


def _plain_share(width: float) -> float:
    """P, the share of plain N(0, 1) draws of a widened normal germ (:func:`held_out_draws`):
    the mass of N(0, λ²), λ = ``width``, beyond ±``TAIL_BOUND``."""
    return 2.0 * STANDARD_NORMAL.cdf(-TAIL_BOUND / width)


def widened_inputs(distributions: Sequence[Distribution]) -> NDArray[np.bool_]:
    """(n,) which inputs :func:`held_out_draws` widens into their tails: the normal ones."""
    return np.array([isinstance(d.family, Hermite) for d in distributions], dtype=bool)


def held_out_unit(
    count: int, inputs: int, seed: int, before: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """(count, inputs) points in the unit cube of a batch of held-out draws: a Latin
    hypercube (:func:`~pcmb.chaos.nodes.latin_hypercube`, the points of
    :func:`~pcmb.chaos.nodes.random_nodes`'s ``"lhs"`` with the same ``seed``); after an
    earlier batch of K points ``before``, one point in each of ``count`` slices of K +
    ``count`` that those leave empty, so that the union stratifies every input as one Latin
    hypercube of K + ``count`` does (exactly where that is a multiple of K)."""
    rng = np.random.default_rng(seed)
    if before is None:
        return latin_hypercube(count, inputs, rng)
    total = before.shape[0] + count
    taken = np.floor(before * total).astype(int)
    empty = [np.setdiff1d(np.arange(total), taken[:, k]) for k in range(inputs)]
    slices = np.column_stack([rng.permutation(free)[:count] for free in empty])
    return (slices + rng.random((count, inputs))) / total


def held_out_draws(
    distributions: Sequence[Distribution],
    count: int,
    seed: int,
    before: NDArray[np.float64] | None = None,
) -> tuple[NodeSet, NDArray[np.float64]]:
    """K held-out inputs and their importance weights.

    A Latin hypercube of the inputs' distribution (one run in each of K equal-probability
    slices of every input), except that each normal germ is drawn from N(0, λ²)
    (:func:`_tail_width`): the errors of a surrogate of a normal input sit in its tails (a
    lognormal response), which K plain draws rarely reach. The slices beyond ±``TAIL_BOUND``
    (a share P, :func:`_plain_share`) are drawn from N(0, 1) instead, their probabilities
    stretched onto (0, 1) in order: a parameter there is often meaningless and its weight
    nil. The density is q = φ_λ 1(|z| <= bound) + P φ, each run weighted by the ratio
    w = Π φ / q (at most 1/P). Without normal inputs the weights are 1. A later batch fills
    the slices that the earlier one's unit-cube points ``before`` leave empty
    (:func:`held_out_unit`).
    """
    batch = unit_nodes(distributions, held_out_unit(count, len(distributions), seed, before))
    normal = widened_inputs(distributions)
    if not normal.any():
        return batch, np.ones(count)
    width = _tail_width(int(normal.sum()))
    plain = _plain_share(width)
    germ = batch.nodes.copy()
    z = width * germ[:, normal]
    beyond = np.abs(z) > TAIL_BOUND
    # An outer slice's tail probability over P: a standard normal draw on its side.
    outer = germ[:, normal][beyond]
    tail = np.vectorize(STANDARD_NORMAL.cdf, otypes=[float])(-np.abs(outer)) / plain
    z[beyond] = -np.sign(outer) * np.vectorize(STANDARD_NORMAL.inv_cdf, otypes=[float])(tail)
    germ[:, normal] = z
    params = np.column_stack([d.to_physical(germ[:, k]) for k, d in enumerate(distributions)])
    widened = np.where(
        np.abs(z) <= TAIL_BOUND, np.exp(z**2 * (1.0 - 1.0 / width**2) / 2.0) / width, 0.0
    )
    return NodeSet(batch.distributions, germ, params), 1.0 / np.prod(plain + widened, axis=1)


def linear_in_widened(expansion: Expansion, scale: float) -> NDArray[np.bool_]:
    """(T,) the times at which the terms of degree 2 or more along the inputs
    :func:`held_out_draws` widens (the normal ones) hold at most ``LINEAR_SHARE`` of the
    expansion's variance: the response is linear in them (a damped oscillator in its initial
    displacement), not heavy-tailed; all False without normal inputs."""
    index = np.asarray(expansion.multi_index)
    if not widened_inputs(expansion.distributions).any() or not scale > 0 or not np.isfinite(scale):
        return np.zeros(expansion.shape, dtype=bool)
    energy = coefficient_energies(expansion, scale)
    curved = np.sum(energy[_curved_in_widened(expansion)], axis=0)
    return curved <= LINEAR_SHARE * np.sum(energy[index.sum(axis=1) > 0], axis=0)


def _curved_in_widened(expansion: Expansion) -> NDArray[np.bool_]:
    """(S,) the terms of degree 2 or more along some input :func:`held_out_draws` widens."""
    normal = widened_inputs(expansion.distributions)
    return np.any(np.asarray(expansion.multi_index)[:, normal] >= 2, axis=1)


def _slowness(expansion: Expansion, energies: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T,) r / (1 - r), at most 1 (1 where r >= 1), r the slowest rate at which the (S, T)
    coefficient ``energies`` fall per degree along a widened input, read from its top three
    degrees in pairs (E_P + E_P-1) / (E_P-1 + E_P-2) (a response even in an input has every
    other one zero): the energy beyond the top degree over the outer ones' is about r², so
    a fast fall leaves little unseen; 1 along an input of fewer than three degrees."""
    index = np.asarray(expansion.multi_index)
    rate = np.zeros(energies.shape[1:])
    for k in np.flatnonzero(widened_inputs(expansion.distributions)):
        top = int(index[:, k].max())
        if top < 3:
            return np.ones(rate.shape)
        layers = [np.sum(energies[index[:, k] == top - j], axis=0) for j in range(3)]
        outer, before = layers[0] + layers[1], layers[1] + layers[2]
        rate = np.fmax(rate, np.divide(outer, before, out=np.ones(rate.shape), where=before > 0))
    slowest = np.fmin(rate, 0.5)
    return slowest / (1.0 - slowest)


def coverage_error(
    expansion: Expansion,
    predicted: ArrayLike,
    observed: ArrayLike,
    weights: ArrayLike | None,
    scale: float,
) -> NDArray[np.float64]:
    """(T,) how far the drawn check's estimates may be off, over the scale, where its draws
    missed the tails of the normal inputs that carry the variance (heavy tails along a
    direction of several normal inputs: ``docs/diagnostics.md``).

    The draws' weighted estimate of the surrogate's own variance, ρ σ² = mean w (s - μ)² over
    the (K, T) surrogate values ``predicted`` at them (importance ``weights``; ``None``: 1),
    falls short by (1 - ρ) σ² where they missed where it lives; the variance the surrogate
    itself misses lives there or beyond, taken as the energy E of its outer layers
    (:func:`~pcmb.chaos.basis.tail_terms`) curved along the widened inputs, so the check may
    miss as much of it: (1 - ρ) (within [0, 1]) times E / σ, as Δσ <= ΔV / σ. Zero where
    the draws recover the surrogate's variance, where it is linear in the widened inputs
    (none: zero), where it does not vary, and where it matches the model's (K, T) finite
    ``observed`` values to round-off (``RELATIVE_NOISE`` of their largest size, at least the
    scale): an exact polynomial's outer terms are its own."""
    outer = tail_terms(expansion.multi_index) & _curved_in_widened(expansion)
    if not outer.any() or not scale > 0 or not np.isfinite(scale):
        return np.zeros(expansion.shape)
    sigma = expansion.std() / scale
    energies = coefficient_energies(expansion, scale)
    energy = np.sum(energies[outer], axis=0) * _slowness(expansion, energies)
    predicted, observed = np.asarray(predicted, dtype=float), np.asarray(observed, dtype=float)
    weights = 1.0 if weights is None else np.asarray(weights, dtype=float)
    weights = np.reshape(weights, (-1,) + (1,) * (predicted.ndim - 1))
    seen = np.mean(weights * ((predicted - expansion.mean()) / scale) ** 2, axis=0)
    exact = _largest_residual(predicted, observed, scale) == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        missed = np.clip((sigma**2 - seen) / sigma**2, 0.0, 1.0) * energy / sigma
    return np.where((sigma > 0) & ~exact, missed, 0.0)


def signed_residuals(predicted: ArrayLike, observed: ArrayLike, scale: float) -> NDArray:
    """(K, T) model - surrogate of the finite runs over the scale; 0 where it is round-off
    (``RELATIVE_NOISE`` of the run's size, at least the scale): an exact polynomial's."""
    observed = np.asarray(observed, dtype=float)
    residual = observed - np.asarray(predicted, dtype=float)
    # Ranges, not squares: outputs near 1e200 must not overflow.
    size = np.fmax(np.abs(observed), scale)
    return np.where(np.abs(residual) <= RELATIVE_NOISE * size, 0.0, residual / scale)


def _residuals(predicted: ArrayLike, observed: ArrayLike, scale: float) -> NDArray:
    """(K, T) |:func:`signed_residuals`|."""
    return np.abs(signed_residuals(predicted, observed, scale))


def _largest_residual(predicted: ArrayLike, observed: ArrayLike, scale: float) -> NDArray:
    """(T,) the largest :func:`_residuals` over the runs."""
    return np.max(_residuals(predicted, observed, scale), axis=0, initial=0.0)


def unseen_region_error(
    predicted: ArrayLike,
    observed: ArrayLike,
    weights: ArrayLike | None,
    scale: float,
    confidence: float,
) -> NDArray[np.float64]:
    """(T,) how large an error of the mean the K drawn runs may have missed, over the scale,
    at the one-sided ``confidence``, where they no longer see residuals of the size the
    output has shown (0 elsewhere). A region of mass m under the draws' density holds none of
    K draws with probability (1 - m)^K, so one of mass -ln(1 - confidence) / K (2.3 / K at
    90 %, the rule of three) may hold none; where the response changes abruptly (a contact's
    jump moving through the inputs), its residual there may be as large, against the runs'
    spread s now (their std over the scale), as the largest seen at this time or before
    against the largest spread so far: J = running maxima along the axis of the largest
    |model - surrogate| over the (K, T) finite runs, each times its (K,) importance
    ``weights`` (``None``: 1), which carry the draws' mass to the inputs', and of s. The
    floor 2.3 J s / K applies where every weighted residual now is below it: the error has
    moved where the draws are not, or settled faster than the output, which they cannot tell
    apart; one that settles with the output keeps pace with s and is not floored. Residuals
    at round-off (``RELATIVE_NOISE`` of a run's size, at least the scale; an exact
    polynomial's) count as none."""
    predicted, observed = np.asarray(predicted, dtype=float), np.asarray(observed, dtype=float)
    count = predicted.shape[0]
    if count == 0 or not scale > 0 or not np.isfinite(scale):
        return np.zeros(predicted.shape[1:])
    weights = np.ones(count) if weights is None else np.asarray(weights, dtype=float)
    residual = _residuals(predicted, observed, scale)  # a weight scales it, not its round-off
    largest = np.max(np.reshape(weights, (-1,) + (1,) * (residual.ndim - 1)) * residual, axis=0)
    spread = np.std(observed / scale, axis=0)  # scaled first: outputs near 1e200
    widest = np.maximum.accumulate(spread, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):  # nothing varied yet: nothing hides
        seen = np.where(widest > 0, np.maximum.accumulate(largest, axis=0) / widest, 0.0)
    floor = -math.log1p(-confidence) / count * seen * spread
    return np.where(largest < floor, floor, 0.0)


def _moment_weights(distributions: Sequence[Distribution], germ: ArrayLike) -> NDArray:
    """(K,) weights ω = Π (a + b z²) over the normal germs z of the widened draws
    (:func:`held_out_draws`), of second and fourth moments m₂ and m₄, with
    b = (1 - m₂) / (m₄ - m₂²) and a = 1 - b m₂: E ω g(z) = E_N(0, 1) g for every g of degree
    3 or less in each, at E ω² = 1.55 per germ (λ = 4.2) where the importance weights' is
    1.99 (all widened: a = (3λ² - 1) / (2λ²), b = (1 - λ²) / (2λ⁴), 1.44 and 3)."""
    normal = widened_inputs(distributions)
    width = _tail_width(int(normal.sum()))
    plain = _plain_share(width)
    # The widened part's moments within ±TAIL_BOUND, by parts, and the plain draws'.
    beta = TAIL_BOUND / width
    edge = 2.0 * beta * STANDARD_NORMAL.pdf(beta)
    second = width**2 * (1.0 - plain - edge) + plain
    fourth = width**4 * (3.0 * (1.0 - plain) - (beta**2 + 3.0) * edge) + 3.0 * plain
    b = (1.0 - second) / (fourth - second**2)
    z2 = np.asarray(germ, dtype=float)[:, normal] ** 2
    return np.prod(1.0 - b * second + b * z2, axis=1)


def judging_weights(
    expansion: Expansion, scale: float, weights: ArrayLike | None, germ: ArrayLike | None
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """The weights and the Latin-hypercube germ (:func:`_standard_error`) the held-out check
    judges drawn runs by. Where the surrogate is linear in every widened input
    (:func:`linear_in_widened`), the residual and the control variate's terms are of degree 2
    at most along them: (K, T) the moment weights (:func:`_moment_weights`) there, the
    importance ``weights`` elsewhere, and no germ, as neighbours paired along an input
    understate the spread of these weights' products (a narrow damped oscillator at 16
    runs: two false alarms in ten seeds). ``weights`` and ``germ`` as given where no draw
    is widened (either missing) or the surrogate is nowhere linear in them."""
    if weights is None or germ is None:
        return weights, germ
    weights = np.asarray(weights, dtype=float)
    linear = linear_in_widened(expansion, scale)
    if not linear.any():
        return weights, germ
    moment = _moment_weights(expansion.distributions, germ)
    shape = (-1,) + (1,) * linear.ndim
    return np.where(linear, moment.reshape(shape), weights.reshape(shape)), None


def held_out_placed(
    distribution: Distribution, design_germ: ArrayLike, count: int
) -> tuple[NodeSet, NDArray[np.float64]]:
    """``count`` held-out inputs of a one-input design placed, not drawn: the weighted Leja
    points that extend its (N,) germ nodes (``design_germ``; with earlier held-out points
    after them, the points that extend those), so that nodes and held-out runs together
    interpolate the response far better than the nodes alone (:func:`placed_check`). The
    weights are 1: the points are not a sample."""
    start = np.asarray(design_germ, dtype=float).ravel()
    germ = leja_sequence(distribution.family, tuple(start), start.size + count)[start.size :]
    params = distribution.to_physical(germ)
    return NodeSet((distribution,), germ[:, None], params[:, None]), np.ones(count)


def element_importance(
    partition: Partition,
    design_germ: ArrayLike,
    where: NDArray[np.intp],
    values: Mapping[str, ArrayLike],
) -> NDArray[np.float64]:
    """(E,) how much each element of a one-input design may err: its probability times the
    largest |top coefficient| (:func:`top_layer`) of the interpolant through its nodes
    (``where``: each node's element; over outputs and times, each output over its runs'
    largest spread)."""
    distribution = partition.distributions[0]
    physical = distribution.to_physical(np.ravel(design_germ))
    importance = np.zeros(partition.size)
    for y in values.values():
        y = np.asarray(y, dtype=float).reshape(physical.size, -1)
        spread = float(np.nanmax(np.nanstd(y, axis=0), initial=0.0))
        finite = np.isfinite(y).all(axis=1)
        for e, (conditional,) in enumerate(partition.inputs):
            rows = (where == e) & finite
            if spread > 0 and rows.sum() > 1:
                local = conditional.to_germ(physical[rows])
                top, _ = top_layer(interpolated(conditional.family, local, y[rows] / spread))
                importance[e] = max(importance[e], partition.probability[e] * np.max(top))
    return importance


def held_out_placed_elements(
    partition: Partition,
    design_germ: ArrayLike,
    where: NDArray[np.intp],
    importance: ArrayLike,
    count: int,
) -> tuple[NodeSet, NDArray[np.float64]]:
    """``count`` held-out inputs of a one-input multi-element design, placed per element: two
    at a time (one where two do not fit) to the element of the largest ``importance``
    (:func:`element_importance`) over one plus its share so far, at most ``ELEMENT_POINTS``
    points (nodes and runs) per element; in each element the weighted Leja points
    extending its nodes in its own coordinate (its conditional density), kept a hair inside
    its interval so that they stay in it. ``where``: each node's element. Element by element;
    weights 1."""
    distribution = partition.distributions[0]
    physical = distribution.to_physical(np.ravel(design_germ))
    room = ELEMENT_POINTS - np.bincount(where[where >= 0], minlength=partition.size)
    importance = np.asarray(importance, dtype=float)
    shares = np.zeros(partition.size, dtype=int)
    while (left := count - shares.sum()) > 0:
        step = 2 if left > 1 and np.any(shares + 2 <= room) else 1
        fits = shares + step <= room
        if not fits.any():
            raise ValueError(f"{count} held-out runs do not fit in {partition.size} elements")
        shares[np.argmax(np.where(fits, importance / (1.0 + shares), -np.inf))] += step
    placed = []
    for e in np.flatnonzero(shares):
        (conditional,) = partition.inputs[e]
        start = conditional.to_germ(physical[where == e])
        local = leja_sequence(conditional.family, tuple(start), start.size + shares[e])
        low, high = conditional.family.support
        hair = 1e-9 * np.where(np.isfinite(high - low), high - low, 1.0)
        placed.append(
            conditional.to_physical(np.clip(local[start.size :], low + hair, high - hair))
        )
    params = np.concatenate(placed)
    germ = distribution.to_germ(params)
    return NodeSet((distribution,), germ[:, None], params[:, None]), np.ones(count)


@dataclass(frozen=True)
class HeldOut:
    """The held-out runs: K model runs at inputs drawn from their distribution.

    Attributes
    ----------
    seed:
        Seed of the draws.
    germ, params:
        (K, n) germ and physical values.
    values:
        Output name -> (K, T) model values (NaN rows where a run failed).
    ok:
        (K,) which runs succeeded.
    weights:
        (K,) importance weights of the draws (:func:`held_out_draws`; 1 when placed).
    placed:
        Whether the runs extend a one-input design's nodes (:func:`held_out_placed`, per
        element :func:`held_out_placed_elements`), or a tensor grid's along one input
        (:func:`~pcmb.analysis.diagnostics.line.held_out_line`), rather than being drawn: the
        check is then :func:`placed_check` (:func:`~pcmb.analysis.diagnostics.line.line_check`)
        (``/validation`` attribute ``placed``).
    batches:
        How many batches of draws the runs hold (``/validation`` attribute ``batches``): each
        is a Latin hypercube, and the second completes the first's (:func:`held_out_unit`)
        only without normal inputs and not always exactly, so with more than one the check's
        standard errors are those of independent draws (:func:`_standard_error`).
    """

    seed: int
    germ: NDArray[np.float64]
    params: NDArray[np.float64]
    values: dict[str, NDArray[np.float64]]
    ok: NDArray[np.bool_]
    weights: NDArray[np.float64]
    placed: bool = False
    batches: int = 1

    def joined(self, more: HeldOut) -> HeldOut:
        """These runs followed by ``more`` (a later batch of the same check; the seed is the
        first batch's)."""
        return HeldOut(
            self.seed,
            np.concatenate([self.germ, more.germ]),
            np.concatenate([self.params, more.params]),
            {name: np.concatenate([v, more.values[name]]) for name, v in self.values.items()},
            np.concatenate([self.ok, more.ok]),
            np.concatenate([self.weights, more.weights]),
            self.placed,
            self.batches + more.batches,
        )
