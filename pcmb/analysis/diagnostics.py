"""When polynomial chaos fails: per-time error indicators and a verdict per output.

Three kinds of evidence, each an array over time and each measured in units of the output's
*largest* standard deviation over time (the scale): an error that is small against the
output's typical spread is accepted even where the spread itself is small (near a fixed
initial state, or where a damped output settles), which is where a per-time normalisation
raises false alarms.

- **Spectral decay** (:func:`spectral_decay`): the share of the largest variance carried
  by the outer two layers of the index set (terms of degree >= 2 only) — the top two total
  degrees of a total basis, the top two degrees of each input of a tensor basis. An
  expansion that converges has little there; two layers rather than one, because a
  response even in a symmetric input has exactly zero odd coefficients, so its top shell
  alone can be empty while the expansion is far from converged.
- **Held-out check** (:func:`holdout_error`): the surrogate against K extra model runs at
  random inputs (:func:`held_out_draws`: a Latin hypercube of the inputs' distribution, normal
  inputs widened into their tails and weighted back, by moment weights where the surrogate is
  linear in them; K sized to the design,
  :func:`held_out_budget`): the RMS error of the surrogate and an upper confidence bound on
  it that fits K; and, with the surrogate as a control variate, the errors of the mean and
  of the standard deviation themselves (:func:`statistics_error`), which are what the error
  bars show, and the mean and std those runs correct. A grid of one input places its
  held-out runs instead (:func:`held_out_placed`: Leja points extending its nodes; per
  element, :func:`held_out_placed_elements`) and compares its mean and std with those of the
  interpolant through both, plus the mean's part beyond its degree (:func:`placed_check`).
- **Range checks** (:func:`range_checks`): a variance from the coefficients that is zero
  where the runs vary, and surrogate samples far outside the range of the run values.
- **Runs all equal**: where the design's runs are all equal while the held-out runs vary,
  the design saw none of the spread (nodes symmetric about a kink) and the verdict fails
  there, unless the held-out check says the error holds within the tolerance; without
  held-out runs, runs all equal at every time are reported (``runs-all-equal``, or
  ``output-constant`` when the nominal run equals them too).

:func:`diagnose` does all of it for one output: its estimated error is the larger of the
estimated errors of the mean and the std at each time (the decay where there are no held-out
runs), its verdict (:func:`verdict`) the first time that exceeds the tolerance by more than its
noise, explained in a ``chaos-unreliable`` record with a remedy that fits the failure; where
the noise is too large to tell, a ``chaos-undecided`` record says how many more held-out runs
would (:func:`more_runs`). A surrogate whose pointwise
error exceeds the tolerance while its statistics hold gets a ``surrogate-inaccurate`` record:
the PDFs, quantiles and Sobol' indices drawn from it are less accurate than the error bars;
:func:`pdf_outside_runs` flags a PDF with mass beyond every run made.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.statistics import draws_are_runs, nearest_indices
from pcmb.axes import OutputAxis
from pcmb.chaos.basis import tail_terms
from pcmb.chaos.elements import Partition, PiecewiseExpansion
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nested import interpolatory_weights, leja_sequence
from pcmb.chaos.nodes import NodeSet, TensorGrid, draw_germs, random_nodes
from pcmb.chaos.polynomials import Hermite, OrthonormalFamily
from pcmb.chaos.truncated import MAX_TERMS
from pcmb.result import StudyResult, WarningRecord
from pcmb.wording import plural

__all__ = [
    "CODES",
    "CONFIDENCE",
    "ELEMENT_POINTS",
    "FIRST_BATCH",
    "TOLERANCE",
    "HeldOut",
    "HeldOutCheck",
    "OutputDiagnostics",
    "diagnose",
    "diagnose_all",
    "element_importance",
    "held_out_budget",
    "held_out_draws",
    "held_out_placed",
    "held_out_placed_elements",
    "holdout_error",
    "linear_in_widened",
    "more_runs",
    "out_of_range",
    "pdf_outside_runs",
    "placed_check",
    "range_checks",
    "spectral_decay",
    "statistics_error",
    "verdict",
    "widened_inputs",
]

#: Codes of the warning records the diagnostics make.
CODES = frozenset(
    {
        "chaos-unreliable",
        "chaos-undecided",
        "surrogate-inaccurate",
        "variance-nonpositive",
        "surrogate-out-of-range",
        "runs-all-equal",
        "output-constant",
    }
)
#: By default the held-out check makes at most this many runs or this share of the design's
#: runs, the larger (:func:`held_out_budget`; ``method.validation: K`` fixes K instead) ...
HELD_OUT_FLOOR, HELD_OUT_SHARE = 8, 0.25
#: ... in a first batch of at most this many, and the rest only where the verdict is undecided.
FIRST_BATCH = 8
#: The fewest held-out runs whose standard error is read from neighbouring pairs
#: (:func:`_standard_error`); fewer are taken as independent draws.
PAIRED_FROM = 16
#: ... and the largest kurtosis of an input's pair differences, P Σ d⁴ / (Σ d²)² over its P
#: pairs, at which they stand (a normal's is 3; a few pairs carrying the sum push it to P).
PAIRED_KURTOSIS = 10.0
#: A placed check's noise: how far its richer surrogate's statistics move without its last
#: this many held-out runs (:func:`placed_check`); two, as Leja points come in pairs about
#: the centre.
PLACED_SPARE = 2
#: A placed check extrapolates its interpolant's spectrum up to this many times its degree
#: to estimate the mean's error beyond it (:func:`_unseen_mean_error`).
UNSEEN_DEGREES = 3
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
#: The standard normal distribution, whose quantiles scale standard errors to confidence bounds.
STANDARD_NORMAL = NormalDist()
#: Default accepted error, relative to the output's largest standard deviation.
TOLERANCE = 0.05
#: Confidence level of the held-out upper bound, and the one-sided level at which the verdict
#: calls an estimated error above (or below) the tolerance.
CONFIDENCE = 0.9
#: Surrogate draws of the range check, and its seed.
RANGE_DRAWS, RANGE_SEED = 4096, 0
#: A surrogate draw is "far outside" beyond this fraction of the run values' range past
#: their smallest or largest value ...
RANGE_MARGIN = 0.25
#: ... and the range check warns where more than this share of the draws is.
RANGE_SHARE = 0.01
#: Draws of an output that no run ever made negative are also far outside below 0 by more
#: than this fraction of the range.
RANGE_BELOW_ZERO = 0.01
#: A PDF's mass counts as beyond the runs past this fraction of their range
#: (:func:`pdf_outside_runs`): between the nodes a smooth surrogate may pass them a little.
PDF_MARGIN = 0.05
#: Run values whose std is below this fraction of their RMS do not vary (round-off).
_ROUND_OFF = 1e-12
#: A rule whose error on an orthonormal polynomial is below this integrates it exactly.
_EXACT = 1e-8
#: A top coefficient below this share of the one before is a parity's zero (a response even
#: or odd about an element's centre), not a converged tail.
_PARITY = 1e-8
#: A tail holding more than this share of its energy in one input is "concentrated".
_CONCENTRATED = 0.75
#: An error that ends above this multiple of its value where it first failed grows.
_GROWTH = 2.0
#: A tail holding at least this share of the energy of the two layers before it does not
#: decay as an analytic response's does, over the degrees the expansion has.
_FLAT = 0.5
#: The remedy reads the decay along every input holding at least this share of the tail.
_SHARED = 0.25
#: A held-out error whose weighted distance from the centre of an input's range
#: (:func:`_error_at_ends`) is at least this sits at its ends: a smooth response.
_AT_ENDS = 0.75
#: ... and where it is at most this, inside it: around a jump, kink or steep front.
_INSIDE = 0.4
#: The fewest degrees after the peak of an input's spectrum that tell its decay's shape.
_SHAPE_LAYERS = 3


# -- spectral decay ----------------------------------------------------------------------------


#: The expansions the diagnostics judge: one element, or a multi-element one.
Expansion = ChaosExpansion | PiecewiseExpansion


def _energies(expansion: Expansion, scale: float = 1.0) -> NDArray[np.float64]:
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
    return np.sum(_energies(expansion, scale)[tail_terms(expansion.multi_index)], axis=0)


def _rms_over_scale(differences: NDArray[np.float64], scale: float, count: float) -> NDArray:
    """√(Σ d² / count) / scale over the first axis, scaled before squaring (no overflow)."""
    if not scale > 0 or not np.isfinite(scale):
        return np.zeros(differences.shape[1:])
    return np.sqrt(np.sum((differences / scale) ** 2, axis=0) / count)


# -- held-out runs -----------------------------------------------------------------------------


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


def held_out_draws(
    distributions: Sequence[Distribution], count: int, seed: int
) -> tuple[NodeSet, NDArray[np.float64]]:
    """K held-out inputs and their importance weights.

    A Latin hypercube of the inputs' distribution (one run in each of K equal-probability
    slices of every input), except that each normal germ is drawn from N(0, λ²)
    (:func:`_tail_width`): the errors of a surrogate of a normal input sit in its tails (a
    lognormal response), which K plain draws rarely reach. The slices beyond ±``TAIL_BOUND``
    (a share P, :func:`_plain_share`) are drawn from N(0, 1) instead, their probabilities
    stretched onto (0, 1) in order: a parameter there is often meaningless and its weight
    nil. The density is q = φ_λ 1(|z| <= bound) + P φ, each run weighted by the ratio
    w = Π φ / q (at most 1/P). Without normal inputs the weights are 1.
    """
    batch = random_nodes(distributions, count, "lhs", seed)
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
    normal = widened_inputs(expansion.distributions)
    index = np.asarray(expansion.multi_index)
    if not normal.any() or not scale > 0 or not np.isfinite(scale):
        return np.zeros(expansion.shape, dtype=bool)
    energy = _energies(expansion, scale)
    curved = np.sum(energy[np.any(index[:, normal] >= 2, axis=1)], axis=0)
    return curved <= LINEAR_SHARE * np.sum(energy[index.sum(axis=1) > 0], axis=0)


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


def _judging_weights(
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
    largest |top coefficient| (:func:`_top_layer`) of the interpolant through its nodes
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
                top, _ = _top_layer(_interpolated(conditional.family, local, y[rows] / spread))
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


def _unseen_mean_error(
    family: OrthonormalFamily, points: NDArray[np.float64], coefficients: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(T,) estimated error of the mean of the interpolant of (M, T) ``coefficients`` through
    the (M,) germ ``points`` from the degrees beyond it: the error of its interpolatory rule
    on them. Where the design's own rule integrates every degree below M exactly, the two
    rules agree on every response, and this is the design mean's error itself.

    The energies of degrees 1 to M - 1 (neighbours averaged), from the spectrum's peak on
    (all of them with fewer than ``_SHAPE_LAYERS`` after it), are fitted by a line against p
    and against log p, each extrapolated up to degree ``UNSEEN_DEGREES`` × M, the larger
    kept, and weighted by the squared error of the rule on each degree; zeros with fewer than
    ``_SHAPE_LAYERS`` averages (M < 5: an element without placed runs, whose own three degrees
    once read flat extrapolated its 4-point rule's errors into a false alarm)."""
    first = coefficients.shape[0]
    last = UNSEEN_DEGREES * first
    # Degrees 1 to M - 1 make M - 2 neighbour averages; fewer than three cannot tell a shape.
    if first - 2 < _SHAPE_LAYERS:
        return np.zeros(coefficients.shape[1:])
    rule_errors = interpolatory_weights(family, points) @ family.evaluate(points, last)
    energy = coefficients[1:] ** 2
    paired = np.log(0.5 * (energy[:-1] + energy[1:]) + np.finfo(float).tiny)
    seen = np.arange(1.0, first - 1)
    fitted = np.arange(seen.size)[:, None] >= np.argmax(paired, axis=0)
    fitted[:, fitted.sum(axis=0) < _SHAPE_LAYERS] = True
    unseen = np.arange(first, last + 1.0)[:, None]
    tails = [
        _extrapolated(transform(seen), paired, fitted, transform(unseen))
        for transform in (np.asarray, np.log)
    ]
    return np.sqrt(np.sum(np.fmax(*tails) * rule_errors[first:, None] ** 2, axis=0))


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


def _interpolated(
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
    (:func:`_converging`; infinite with no more runs than that), plus in quadrature the next
    coefficient of each element without held-out runs (:func:`_unchecked`: nothing checks it), the
    spread that of the larger estimate (the corrected mean's adds the unseen error); the surrogate
    error is the L2 distance of the two surrogates (their coefficients' difference), its upper bound
    that plus how far it moves.
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

    def moments(spare: int) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        found = [_placed_moments(*piece, scale, spare) for piece in pieces]
        means, stds, errors, unseen = (np.array(column) for column in zip(*found, strict=True))
        rich_mean = np.sum(probability * means, axis=0)
        variance = np.sum(probability * (stds**2 + (means - rich_mean) ** 2), axis=0)
        return (
            rich_mean,
            np.sqrt(variance),
            np.sqrt(np.sum(probability * errors**2, axis=0)),
            np.sum(probability * unseen, axis=0),
        )

    rich_mean, rich_std, error, unseen = moments(0)
    # The elements without held-out runs, which nothing checks, add their next coefficients.
    unchecked = np.sqrt(
        sum(
            (p * _unchecked(own / scale)) ** 2
            for p, (_, points, _, nodes, own) in zip(probability[:, 0], pieces, strict=True)
            if points.size == nodes
        )
    )
    mean_error, std_error = (
        np.abs(rich_mean - mean / scale) + unseen,
        np.abs(rich_std - std / scale),
    )
    if count > PLACED_SPARE:
        fewer_mean, fewer_std, fewer_error, fewer_unseen = moments(PLACED_SPARE)
        fewer_mean_error = np.abs(fewer_mean - mean / scale) + fewer_unseen
        # The unseen mean's noise, like the rest, is how far the estimate holding it moves (its
        # size is a bias, which the corrected mean, leaving it out, adds to that noise); the
        # elements without runs, which nothing checks, add their next coefficients.
        mean_moved, std_moved = np.abs(mean_error - fewer_mean_error), np.abs(rich_std - fewer_std)
        if count > 2 * PLACED_SPARE:
            least_mean, least_std, _, least_unseen = moments(2 * PLACED_SPARE)
            least_mean_error = np.abs(least_mean - mean / scale) + least_unseen
            mean_moved = _converging(mean_moved, np.abs(fewer_mean_error - least_mean_error))
            std_moved = _converging(std_moved, np.abs(fewer_std - least_std))
        mean_se = np.hypot(mean_moved, unchecked)
        std_se = np.hypot(std_moved, unchecked)
        moved = np.abs(error - fewer_error)
    else:
        mean_se = std_se = moved = np.full(observed.shape[1], np.inf)
    return HeldOutCheck(
        error,
        error + moved,
        mean_error,
        std_error,
        np.where(mean_error >= std_error, mean_se, std_se),
        rich_mean * scale,
        rich_std * scale,
        (mean_se + unseen) * scale,
        std_se * scale,
        count,
        confidence,
    )


def _converging(moved: NDArray[np.float64], before: NDArray[np.float64]) -> NDArray[np.float64]:
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
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(T,) mean, std, L2 distance from ``own`` (the expansion's coefficients) and unseen
    mean error (:func:`_unseen_mean_error`; where the design's rule is not exact on the
    interpolant's degrees, at most its mean's difference from the design's) of the interpolant
    through an element's nodes and held-out runs (its first ``nodes`` points are its nodes)
    without its last ``spare`` held-out runs, over the scale."""
    kept = max(nodes, points.size - spare)
    own = own / scale
    coefficients = _interpolated(family, points[:kept], values[:kept] / scale)
    missed = np.sum((coefficients - own[:kept]) ** 2, axis=0)
    unseen = _unseen_mean_error(family, points[:kept], coefficients)
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
    )


def _top_layer(coefficients: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
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


def _unchecked(coefficients: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T,) |the next coefficient| beyond an element's (M, T) expansion, what nothing checks
    where no held-out run is: its top one times their ratio to the one before of its parity
    (at most 1; :func:`_top_layer`)."""
    top, ratio = _top_layer(coefficients)
    return top * ratio


# -- range checks ------------------------------------------------------------------------------


def out_of_range(
    expansion: Expansion,
    node_values: ArrayLike,
    draws: int = RANGE_DRAWS,
    seed: int = RANGE_SEED,
    node_germ: ArrayLike | None = None,
    margin: float = RANGE_MARGIN,
) -> NDArray[np.float64]:
    """(T,) share of surrogate draws far outside the range of the run values.

    With ``node_germ`` ((N, n) germ of the runs), only draws inside the box the runs span are
    counted: beyond it (the tails of an unbounded input) a smooth response leaves the runs'
    range by itself, which says nothing about the surrogate.

    "Far" is beyond ``margin`` times the range (max - min of the runs) past the
    smallest or largest run value; where the runs or the expansion do not vary beyond
    round-off (:meth:`~pcmb.chaos.expansion.ChaosExpansion.varies`) the share is 0. An
    output that is never negative in any run and at any time (a distance, an energy) is
    also held to be non-negative: draws below 0 by more than ``RANGE_BELOW_ZERO`` times the
    range count too.
    """
    germ, samples = _surrogate_draws(expansion, draws, seed)
    values = np.asarray(node_values, dtype=float)
    return _outside_sides(expansion, values, margin, samples, _in_box(germ, node_germ)).sum(axis=0)


def _surrogate_draws(
    expansion: Expansion, draws: int, seed: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(D, n) germ drawn from the inputs' distribution and (D, T) the surrogate there."""
    germ = draw_germs(expansion.distributions, draws, np.random.default_rng(seed))
    return germ, expansion.evaluate_germ(germ)


def _in_box(germ: NDArray[np.float64], node_germ: ArrayLike | None) -> NDArray[np.bool_]:
    """(D,) whether each draw lies inside the box the (N, n) ``node_germ`` spans (all of them
    without it)."""
    if node_germ is None:
        return np.ones(germ.shape[0], dtype=bool)
    box = np.asarray(node_germ, dtype=float)
    return np.all((germ >= box.min(axis=0)) & (germ <= box.max(axis=0)), axis=1)


def _outside_sides(
    expansion: Expansion,
    values: NDArray[np.float64],
    margin: float,
    samples: NDArray[np.float64],
    kept: NDArray[np.bool_],
) -> NDArray[np.float64]:
    """(2, T) the shares of :func:`out_of_range` below and above the (N, T) runs' range,
    among the (D, T) surrogate ``samples`` where ``kept``."""
    if not kept.any():
        return np.zeros((2, values.shape[1]))
    floor, ceiling = _far_bounds(values, margin)
    samples = samples[kept]
    sides = np.stack([(samples < floor).mean(axis=0), (samples > ceiling).mean(axis=0)])
    return np.where(expansion.varies() & (ceiling > floor), sides, 0.0)


def _far_bounds(values: NDArray[np.float64], margin: float) -> tuple[NDArray, NDArray]:
    """(T,) bounds below and above which a value is far outside the (N, T) runs ``values``
    (:func:`out_of_range`)."""
    low, high = np.nanmin(values, axis=0), np.nanmax(values, axis=0)
    reach = margin * (high - low)
    floor = low - reach
    if np.nanmin(values) >= 0:
        floor = np.maximum(floor, -RANGE_BELOW_ZERO * (high - low))
    return floor, high + reach


def _table_mass_beyond(
    value: NDArray[np.float64], density: NDArray[np.float64], floor: float, ceiling: float
) -> NDArray[np.float64]:
    """(2,) mass of a tabulated density (linear between its points) below ``floor`` and
    above ``ceiling``, over its whole mass."""

    def mass(start: float, stop: float) -> float:
        inner = value[(value > start) & (value < stop)]
        points = np.concatenate([[start], inner, [stop]])
        return float(np.trapezoid(np.interp(points, value, density), points))

    whole = float(np.trapezoid(density, value))
    below = mass(value[0], floor) if floor > value[0] else 0.0
    above = mass(ceiling, value[-1]) if ceiling < value[-1] else 0.0
    return np.array([below, above]) / whole


def pdf_outside_runs(result: StudyResult) -> tuple[WarningRecord, ...]:
    """``pdf-outside-runs`` records (notes): a PDF stored at one of ``analysis.pdf_times`` with
    more of its mass than :func:`_pdf_allowance` on one side beyond the range of every run
    made (design, held-out and nominal) by more than ``PDF_MARGIN`` of that range. The mass
    is the stored density's (its kernel may smear the draws past a hard bound) or, where
    larger, the share of the surrogate's draws inside the box the design's nodes span
    (:func:`out_of_range`); the record names the cause: the surrogate inside that box, its
    draws from outside it, or the kernel."""
    analysis, ok = result.analysis, result.ok
    if analysis is None or not ok.any():
        return ()
    records = []
    for name, expansion in result.expansions.items():
        if name not in analysis.outputs or draws_are_runs(result, name):
            continue
        runs = [result.values[name][ok]]
        if result.held_out is not None:
            runs.append(result.held_out.values[name][result.held_out.ok])
        if name in result.nominal:
            runs.append(np.reshape(result.nominal[name], (1, -1)))
        made = _finite_rows(np.vstack(runs))
        pdf = analysis.outputs[name].pdf
        points = nearest_indices(result.grid(name), pdf.at)
        germ, samples = _surrogate_draws(expansion, RANGE_DRAWS, RANGE_SEED)
        drawn = _outside_sides(expansion, made, PDF_MARGIN, samples, _in_box(germ, result.germ[ok]))
        anywhere = _outside_sides(expansion, made, PDF_MARGIN, samples, _in_box(germ, None))
        floor, ceiling = _far_bounds(made, PDF_MARGIN)
        allowed = _pdf_allowance(made.shape[0])
        axis = result.axis(name)
        where = "" if axis is None else f"{axis.name} = "
        for row, (t, k) in enumerate(zip(pdf.at, points, strict=True)):
            stored = np.zeros(2)
            if np.isfinite(pdf.bandwidth[row]) and ceiling[k] > floor[k]:
                stored = _table_mass_beyond(pdf.value[row], pdf.density[row], floor[k], ceiling[k])
            if max(stored.max(), drawn[:, k].max()) <= allowed:
                continue
            if drawn[:, k].max() > allowed:
                cause = "the surrogate overshoots (see its held-out error)"
            elif 2 * anywhere[:, k].sum() >= stored.sum():
                cause = (
                    "the surrogate's draws go there from outside the box the design's nodes "
                    "span, where it extrapolates and no run checks it"
                )
            else:
                smears = f"its kernel (bandwidth {pdf.bandwidth[row]:.3g}) smears"
                cause = f"{smears} the draws past them"
            records.append(
                WarningRecord(
                    "pdf-outside-runs",
                    f"the PDF at {where}{t:g} puts {_percent(stored.sum())} of its mass "
                    f"({_percent(drawn[:, k].sum())} of the surrogate's draws) beyond "
                    f"[{np.min(made[:, k]):.4g}, {np.max(made[:, k]):.4g}], the range of all "
                    f"{made.shape[0]} runs made (design, held-out and nominal), by more than "
                    f"{_percent(PDF_MARGIN)} of that range: no run went there, {cause}",
                    name,
                    (float(t), float(t)) if result.on_time(name) else None,
                )
            )
    return tuple(records)


def _pdf_allowance(runs: int) -> float:
    """The share of a PDF's mass on one side beyond the range of ``runs`` runs that is not
    noted: ``RANGE_SHARE`` plus 1/(runs + 1), the mass a correct PDF leaves beyond the largest
    of ``runs`` exchangeable draws of its output on average."""
    return RANGE_SHARE + 1.0 / (runs + 1)


def range_checks(
    output: str,
    expansion: Expansion,
    node_values: ArrayLike,
    times: ArrayLike,
    out_of_range_share: NDArray[np.float64] | None = None,
) -> list[WarningRecord]:
    """Warnings where the expansion's values cannot be right, whatever its convergence.

    - ``variance-nonpositive``: the variance from the coefficients is zero (or not finite)
      where the runs vary — the basis misses what varies (e.g. a total basis that drops
      the interaction the output consists of).
    - ``surrogate-out-of-range``: more than ``RANGE_SHARE`` of the surrogate's draws lie
      far outside the run values (:func:`out_of_range`): its PDF puts mass where no run
      went (Gibbs or Runge overshoot of a steep response).

    Parameters
    ----------
    output:
        The output's name, for the records.
    expansion:
        Its (S, T) expansion.
    node_values:
        (N, T) the runs it was recovered from (non-finite rows are ignored).
    times:
        (T,) the grid.
    out_of_range_share:
        (T,) :func:`out_of_range` when already computed.
    """
    values = _finite_rows(node_values)
    times = np.asarray(times, dtype=float)
    varies = _varies(values, times.size)
    records = []
    std = expansion.std()  # overflow-safe, where the variance of 1e200 would not be
    empty = varies & ~(np.isfinite(std) & (std > 0))
    if empty.any():
        records.append(
            WarningRecord(
                "variance-nonpositive",
                f"the variance from the chaos coefficients is zero or not finite at "
                f"{_count(empty)} where the runs vary: the basis misses the variation",
                output,
                _span(times, empty),
            )
        )
    share = out_of_range(expansion, values) if out_of_range_share is None else out_of_range_share
    far = share > RANGE_SHARE
    if far.any():
        records.append(
            WarningRecord(
                "surrogate-out-of-range",
                f"up to {_percent(share.max())} of the surrogate's values lie far outside the "
                f"range of the runs (at {_count(far)}): its PDF has mass where no run went",
                output,
                _span(times, far),
            )
        )
    return records


def _finite_rows(values: ArrayLike) -> NDArray[np.float64]:
    """The (N, T) runs without the rows holding a value that is not finite (failed runs)."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    return values[np.isfinite(values).all(axis=1)]


def _varies(values: NDArray[np.float64], points: int) -> NDArray[np.bool_]:
    """(T,) where (N, T) finite runs differ by more than round-off (never with one run)."""
    if values.shape[0] < 2:
        return np.zeros(points, dtype=bool)
    # Ranges, not squares: outputs near 1e200 must not overflow.
    return np.ptp(values, axis=0) > _ROUND_OFF * np.max(np.abs(values), axis=0)


def _count(where: NDArray[np.bool_]) -> str:
    return f"{int(where.sum())} of {where.size} times"


def _span(times: NDArray[np.float64], where: NDArray[np.bool_]) -> tuple[float, float]:
    found = np.flatnonzero(where)
    return float(times[found[0]]), float(times[found[-1]])


def _percent(share: float) -> str:
    """A share in percent, two significant digits ("5.6 %", "12 %", "110 %")."""
    percent = 100 * share
    return f"{percent:.0f} %" if abs(percent) >= 100 else f"{percent:.2g} %"


# -- the verdict -------------------------------------------------------------------------------


def verdict(
    times: ArrayLike, estimate: ArrayLike, tolerance: float = TOLERANCE, noise: ArrayLike = 0.0
) -> float:
    """The first time at which the estimated error exceeds the tolerance by more than its
    ``noise`` (NaN if never)."""
    lower = np.asarray(estimate, dtype=float) - np.asarray(noise, dtype=float)
    above = np.flatnonzero(lower > tolerance)
    return float(np.asarray(times, dtype=float)[above[0]]) if above.size else float("nan")


def _flag_margin(checked: HeldOutCheck, tolerance: float) -> NDArray[np.float64]:
    """(T,) how far the held-out estimate must pass the tolerance to be flagged: m times its
    standard error s, where an error at the tolerance itself, estimated as ê ~ N(tolerance,
    s²), has a sign-free |ê| beyond tolerance + m s with probability Φ(-m) + Φ(-m - 2
    tolerance / s) = 1 - confidence. m is the one-sided quantile (1.28 at 90 %) where s is
    small against the tolerance, the two-sided one (1.64) where it is large: there |ê| passes
    the tolerance by 1.28 s on either side of a truth near zero, twice as often as the
    confidence allows. Found by bisection; infinite where s is unknown (NaN)."""
    tail = np.frompyfunc(lambda x: 0.5 * math.erfc(x / math.sqrt(2.0)), 1, 1)
    miss = 1.0 - checked.confidence
    spread = np.where(np.isnan(checked.spread), np.inf, checked.spread)
    edge = np.divide(2.0 * tolerance, spread, out=np.full(spread.shape, np.inf), where=spread > 0)
    low = np.full(spread.shape, STANDARD_NORMAL.inv_cdf(1.0 - miss))
    high = np.full(spread.shape, STANDARD_NORMAL.inv_cdf(1.0 - miss / 2.0))
    for _ in range(40):
        middle = 0.5 * (low + high)
        beyond = (tail(middle) + tail(middle + edge)).astype(float) > miss
        low, high = np.where(beyond, middle, low), np.where(beyond, high, middle)
    return high * spread


@dataclass(frozen=True)
class OutputDiagnostics:
    """How far one output's chaos expansion can be trusted, time by time.

    Attributes
    ----------
    output:
        The output's name.
    scale:
        Its largest standard deviation over time, the unit of every indicator.
    decay:
        (T,) :func:`spectral_decay`, a share of the largest variance.
    holdout:
        The held-out check (:class:`HeldOutCheck`), ``None`` without held-out runs.
    out_of_range:
        (T,) :func:`out_of_range`, a share of surrogate draws.
    estimate:
        (T,) the estimated error: the larger of the held-out estimates of the errors of the
        mean and the std (:attr:`HeldOutCheck.statistics`), or the decay without held-out runs.
    noise:
        (T,) how far the estimate may be off at the held-out check's confidence
        (:attr:`HeldOutCheck.noise`; 0 for the decay).
    undecided:
        (T,) the times before ``failing_from`` where the estimate lies within its noise of
        the tolerance: more held-out runs would tell.
    tolerance:
        The accepted error, relative to the scale.
    failing_from:
        :func:`verdict` of the estimate: the first time it exceeds the tolerance by more than
        its noise, or where the design's runs are all equal while the held-out runs vary and
        do not show the error within the tolerance; NaN if never.
    warnings:
        ``chaos-unreliable`` (when ``failing_from`` is a time), ``chaos-undecided`` (where
        the noise is too large to tell) and the range checks' records (:func:`range_checks`).
    """

    output: str
    scale: float
    decay: NDArray[np.float64]
    holdout: HeldOutCheck | None
    out_of_range: NDArray[np.float64]
    estimate: NDArray[np.float64]
    noise: NDArray[np.float64]
    undecided: NDArray[np.bool_]
    tolerance: float
    failing_from: float
    warnings: tuple[WarningRecord, ...]

    @property
    def reliable(self) -> bool:
        """Whether no time is flagged (the estimate never exceeds the tolerance by more than
        its noise)."""
        return bool(np.isnan(self.failing_from))

    @property
    def vouched(self) -> bool:
        """Whether the check vouches for every time: none flagged, none undecided."""
        return self.reliable and not self.undecided.any()


def diagnose(
    output: str,
    expansion: Expansion,
    node_values: ArrayLike,
    times: ArrayLike,
    holdout: tuple[ArrayLike, ArrayLike] | None = None,
    tolerance: float = TOLERANCE,
    node_germ: ArrayLike | None = None,
    axis: str = "t",
    nominal: ArrayLike | None = None,
    budgets: Collection[str] = (),
    holdout_germ: ArrayLike | None = None,
    weights: ArrayLike | None = None,
    placed: bool = False,
    design_error: float | None = None,
    stratified: bool = True,
) -> OutputDiagnostics:
    """Every check of one output's expansion, its verdict and its warnings.

    Parameters
    ----------
    output:
        The output's name.
    expansion:
        Its (S, T) expansion.
    node_values:
        (N, T) the runs it was recovered from.
    times:
        (T,) the grid.
    holdout:
        ``(predicted, observed)``, each (K, T): the surrogate and the model at K inputs
        drawn at random from the inputs' distribution (not the nodes), or ``None``.
    tolerance:
        Accepted error relative to the output's largest standard deviation.
    node_germ:
        (N, n) germ of the runs, which bounds where the range check looks (see
        :func:`out_of_range`).
    axis:
        Name of the axis ``times`` are points of, for the message (``"t"``; ``""`` for a
        scalar output, whose ``times`` is ``[0.]``: ``failing_from`` is then 0 when it fails,
        NaN when it passes).
    nominal:
        (T,) the run at the nominal parameters, or ``None``: without held-out runs, whether
        it differs from design runs that are all equal tells a design that missed the spread
        (``runs-all-equal``, a warning) from an output that looks constant
        (``output-constant``, a note).
    budgets:
        Codes of the design's budget records (``order-budget``, ``element-budget``): the
        refinements that ran out, which the remedy does not ask for again.
    holdout_germ:
        (K, n) germ of the held-out runs, a Latin hypercube: it tells the remedy where along
        each input the surrogate's error sits (:func:`_error_at_ends`), and the check's
        standard errors (:func:`_standard_error`; default: taken as independent draws).
    weights:
        (K,) importance weights of the held-out runs (:func:`held_out_draws`; default: 1).
    placed:
        Whether the held-out runs extend the nodes of a one-input expansion
        (:func:`held_out_placed`): judged by :func:`placed_check` instead.
    stratified:
        Whether the drawn held-out runs are one Latin hypercube, whose standard errors
        :func:`_standard_error` reads from neighbouring pairs; several batches joined are
        not (their neighbours, from different hypercubes, understate the spread).
    design_error:
        The design's own calibrated estimate of the statistics' error
        (:meth:`pcmb.result.DesignReport.statistics_error`), or ``None``: without held-out
        runs, where it meets the tolerance it bounds the decay's reading.
    """
    times = np.asarray(times, dtype=float)
    std = expansion.std()
    finite = std[np.isfinite(std)]
    scale = float(finite.max()) if finite.size else 0.0
    runs = _finite_rows(node_values)
    equal = ~_varies(runs, times.size)
    # Where the design's runs are all equal and the held-out runs are not, the design saw
    # none of the spread (nodes symmetric about a kink): no expansion can learn it.
    blind = np.zeros(times.size, dtype=bool)
    if holdout is not None:
        observed = _finite_rows(holdout[1])
        blind = equal & _varies(observed, times.size)
        if not scale > 0 and blind.any():  # the held-out runs' spread is the only scale
            size = float(np.max(np.abs(observed)))  # scaled before squaring: outputs near 1e200
            scale = size * float(np.max(np.std(observed / size, axis=0)))
    decay = spectral_decay(expansion, scale)
    checked = None
    if holdout is not None and placed:
        checked = placed_check(expansion, node_germ, node_values, holdout_germ, holdout[1], scale)
    elif holdout is not None:
        judged, paired = _judging_weights(expansion, scale, weights, holdout_germ)
        paired = paired if stratified else None
        checked = holdout_error(*holdout, expansion.mean(), std, scale, weights=judged, germ=paired)
    # The held-out runs measure the errors of the statistics themselves; the decay only hints
    # at them (it is large for a response that is exactly a polynomial of the expansion's
    # order), so it decides only where there are no held-out runs.
    estimate = decay if checked is None else checked.statistics
    # Without them, a design that measured its own convergence (an adaptive grid, order:
    # auto) outweighs the decay, which reads an exact polynomial's top terms (or a sparse
    # set's edge) as a tail.
    if checked is None and design_error is not None and design_error <= tolerance:
        estimate = np.minimum(decay, design_error)
    noise = (
        np.zeros(times.size)
        if checked is None
        else np.where(np.isnan(checked.noise), np.inf, checked.noise)
    )
    failing_from = verdict(
        times, estimate, tolerance, noise if checked is None else _flag_margin(checked, tolerance)
    )
    # A blind time fails unless the held-out runs, which saw the spread there, say it holds
    # beyond their noise (a switch the nodes have not reached yet, its spread still small).
    blind &= estimate + noise > tolerance
    if blind.any():
        failing_from = float(np.fmin(failing_from, times[blind][0]))
    # Without held-out runs, design runs all equal at every time say nothing: where the
    # nominal run differs the design missed the spread (it fails), else none can tell.
    missed, spread = (
        _all_equal(output, runs, times, nominal)
        if holdout is None and runs.shape[0] > 1 and equal.all()
        else (None, False)
    )
    if spread:
        failing_from = float(times[0])
    share = out_of_range(expansion, node_values, node_germ=node_germ)
    records = range_checks(output, expansion, node_values, times, share)
    holding = ~(times >= failing_from)  # every time where the verdict never fails
    undecided = ((estimate + noise > tolerance) | (spread is None)) & holding
    if checked is not None:
        records.extend(_inaccurate(output, checked, times, tolerance, holding, undecided))
    if missed is not None:
        records.append(missed)
    if not np.isnan(failing_from):
        failing = times >= failing_from
        where = f" from {axis} = {failing_from:.4g}" if axis else ""
        evidence = _evidence(decay, checked, failing)
        ends, by_element = None, ""
        if holdout is not None and holdout_germ is not None:
            predicted, observed = (np.atleast_2d(a) for a in holdout)
            kept = np.isfinite(observed).all(axis=1)
            germ, residual = np.asarray(holdout_germ)[kept], observed[kept] - predicted[kept]
            ends = _error_at_ends(germ, residual, failing)
            if isinstance(expansion, PiecewiseExpansion):
                by_element = _element_errors(expansion, germ, residual, failing)
        if blind.any():
            evidence = (
                f"the design's {runs.shape[0]} runs are all equal at {_count(blind)} while the "
                f"{checked.count} held-out runs vary there, which no expansion can learn "
                f"from; {evidence}"
            )
        elif spread:
            evidence = (
                f"the design's {runs.shape[0]} runs are all equal at every time while the "
                "nominal run differs, which no expansion can learn from"
            )
        # The remedy reads the times from where the estimate passes the tolerance, which
        # the flag, waiting for the noise, may follow late.
        passing = times >= times[np.argmax((estimate > tolerance) | failing)]
        message = (
            f"polynomial chaos unreliable{where} ({evidence}); consider "
            f"{_remedy(expansion, estimate, passing, share, budgets, ends, by_element)}"
        )
        span = (failing_from, float(times[-1]))
        records.insert(0, WarningRecord("chaos-unreliable", message, output, span))
    found = OutputDiagnostics(
        output,
        scale,
        decay,
        checked,
        share,
        estimate,
        noise,
        undecided,
        tolerance,
        failing_from,
        (),
    )
    if found.undecided.any():
        records.append(_undecided(found, times, axis))
    if axis != "t":  # a record's time_range is in time: off time, the message says where
        records = [dataclasses.replace(record, time_range=None) for record in records]
    return dataclasses.replace(found, warnings=tuple(records))


def more_runs(found: OutputDiagnostics) -> int:
    """How many held-out runs, beyond those made, would decide every undecided time of
    ``found`` but those whose estimate is within a tenth of the tolerance of it (0 when none is
    undecided, at least 1 otherwise): the noise falls as 1/√K. Too few runs to measure any
    noise (one): the first batch."""
    if not found.undecided.any():
        return 0
    count = found.holdout.count  # a time is undecided only by a held-out check's noise
    needed = _runs_needed(found)
    if not np.isfinite(needed):
        return max(FIRST_BATCH - count, 1)
    return max(int(np.ceil(needed)) - count, 1)


def _runs_needed(found: OutputDiagnostics) -> float:
    """Held-out runs in all whose noise would decide every undecided time of ``found``, those
    within a tenth of the tolerance of it to that tenth (:func:`more_runs`)."""
    undecided = found.undecided
    margin = np.abs(found.estimate - found.tolerance)[undecided]
    margin = np.maximum(margin, found.tolerance / 10)
    return found.holdout.count * float(np.max(found.noise[undecided] / margin)) ** 2


def _undecided(found: OutputDiagnostics, times: NDArray[np.float64], axis: str) -> WarningRecord:
    """The ``chaos-undecided`` record: where the held-out check cannot tell whether the
    statistics hold, the estimate at the worst such time and the runs that would decide, or,
    where the runs made resolve every such time to a tenth of the tolerance, that the
    estimate sits at the tolerance itself."""
    undecided = found.undecided
    worst = int(np.flatnonzero(undecided)[np.argmax(found.estimate[undecided])])
    holdout = found.holdout
    where = f" at {axis} = {times[worst]:.4g}" if axis else ""
    count = holdout.count
    if _runs_needed(found) <= count:
        decide = (
            "its estimate lies within a tenth of the tolerance of it there, at the tolerance "
            "itself, which more held-out runs resolve only slowly"
        )
    else:
        more = more_runs(found)
        decide = f"about {more} more held-out runs would decide (method.validation: {count + more})"
    return WarningRecord(
        "chaos-undecided",
        f"the held-out check cannot tell whether mean and std hold within the tolerance "
        f"{_percent(found.tolerance)} of the largest std at {_count(undecided)}: estimated "
        f"error {_percent(found.estimate[worst])} ± {_percent(found.noise[worst])}{where} "
        f"({_percent(holdout.confidence)} confidence, {count} held-out runs); {decide}",
        found.output,
        _span(times, undecided),
    )


def _evidence(
    decay: NDArray[np.float64], holdout: HeldOutCheck | None, failing: NDArray[np.bool_]
) -> str:
    """The indicators where the verdict fails, e.g. "mean off by an estimated 12 % of the
    largest std (± 2 % from 32 held-out runs), surrogate error 25 % of std, decay 5.6 %"."""
    found = [f"decay {_percent(np.nanmax(decay[failing]))}"]
    if holdout is None:
        return ", ".join(found)
    worst = int(np.flatnonzero(failing)[np.nanargmax(holdout.statistics[failing])])
    which = "mean" if holdout.mean_error[worst] >= holdout.std_error[worst] else "std"
    judged = (
        f"{which} off by an estimated {_percent(holdout.statistics[worst])} of the largest "
        f"std (± {_percent(holdout.spread[worst])} from {holdout.count} held-out runs)"
    )
    surrogate = f"surrogate error {_percent(np.nanmax(holdout.error[failing]))} of std"
    return ", ".join([judged, surrogate, *found])


def _all_equal(
    output: str,
    runs: NDArray[np.float64],
    times: NDArray[np.float64],
    nominal: ArrayLike | None,
) -> tuple[WarningRecord, bool | None]:
    """The record of an output whose (N, T) runs are all equal at every time and that no
    held-out run checks: ``output-constant`` when the nominal run equals them too, else
    ``runs-all-equal``; and whether the nominal run saw a spread the design missed (``None``:
    nothing else was run to tell)."""
    span = _span(times, np.ones(times.size, dtype=bool))
    unchecked = "no held-out run checks it (method.validation is 0)"
    if nominal is not None and np.size(nominal) == runs.shape[1]:
        with_nominal = np.vstack([runs, np.reshape(nominal, (1, -1))])
        if np.all(np.isfinite(with_nominal)) and not _varies(with_nominal, times.size).any():
            constant = WarningRecord(
                "output-constant",
                f"all {runs.shape[0]} runs of the design and the nominal run are equal at "
                f"every time: the output looks constant, and {unchecked}",
                output,
                span,
            )
            return constant, False
        seen, spread = "the nominal run differs, so the design missed the spread", True
    else:
        seen, spread = "nothing else was run to compare", None
    record = WarningRecord(
        "runs-all-equal",
        f"all {runs.shape[0]} runs of the design are equal at every time: its std 0 says "
        f"nothing about the spread (nodes placed symmetric about a kink see none); {seen}, "
        f"and {unchecked}",
        output,
        span,
    )
    return record, spread


def _inaccurate(
    output: str,
    holdout: HeldOutCheck,
    times: NDArray[np.float64],
    tolerance: float,
    holding: NDArray[np.bool_],
    undecided: NDArray[np.bool_],
) -> list[WarningRecord]:
    """A ``surrogate-inaccurate`` record where the surrogate's pointwise error exceeds the
    tolerance at the times where the statistics hold (``holding``: before the verdict fails),
    saying so of the ``undecided`` ones among them."""
    above = (holdout.error > tolerance) & holding
    if not above.any():
        return []
    statistics = (
        f"its mean and std are not flagged there (undecided at {_count(above & undecided)})"
        if (above & undecided).any()
        else "its mean and std hold there"
    )
    return [
        WarningRecord(
            "surrogate-inaccurate",
            f"the surrogate is off by up to {_percent(np.nanmax(holdout.error[above]))} of std "
            f"at {holdout.count} held-out runs ({_count(above)}) while {statistics} (estimated "
            f"error at most {_percent(np.nanmax(holdout.statistics[above]))}): PDFs, quantiles "
            "and Sobol' indices drawn from it are less accurate than its error bars",
            output,
            _span(times, above),
        )
    ]


def _decay_shape(
    energy: NDArray[np.float64], multi_index: NDArray[np.int64], k: int
) -> tuple[str, float, int, int] | None:
    """How the chaos coefficients' energy along input k falls with its degree p, from the
    spectrum's peak to the top degree: ``("algebraic", s, first, top)`` with energy ~ p^-s (a
    jump: s ≈ 2, a kink: s ≈ 4; a higher order resolves it slowly), or ``("geometric", r,
    first, top)`` with energy ~ r^p (an analytic response: a higher order resolves it);
    ``None`` when fewer than ``_SHAPE_LAYERS`` degrees follow the peak.

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
    if centres.size < _SHAPE_LAYERS:
        return None
    fits = {}
    for shape, x in (("geometric", centres), ("algebraic", np.log(centres))):
        slope, intercept = np.polyfit(x, logs, 1)
        fits[shape] = (float(np.sum((slope * x + intercept - logs) ** 2)), slope)
    shape = min(fits, key=lambda name: fits[name][0])
    slope = fits[shape][1]
    rate = float(-slope) if shape == "algebraic" else float(np.exp(slope))
    return shape, rate, peak + 1, int(degrees.max())


def _remedy(
    expansion: Expansion,
    estimate: NDArray[np.float64],
    failing: NDArray[np.bool_],
    out_of_range_share: NDArray[np.float64],
    budgets: Collection[str],
    ends: NDArray[np.float64] | None = None,
    by_element: str = "",
) -> str:
    """What may help (:func:`_cause_remedy`), turned away from a refinement that already ran
    out (``budgets``: the codes of the design's budget records), with where a multi-element
    surrogate's error sits (``by_element``, :func:`_element_errors`) and what was tried: the
    order, the elements and the refinement's end."""
    action, inputs, cause = _cause_remedy(expansion, estimate, failing, out_of_range_share, ends)
    orders = expansion.multi_index.max(axis=0)
    order = int(orders.max())
    elements = expansion.partition.size if isinstance(expansion, PiecewiseExpansion) else 1
    shown = f"order {order}" if orders.min() == order else f"orders {'x'.join(map(str, orders))}"
    tried = [f"{shown}, {plural(elements, 'element')}"]
    along = f" along {inputs}" if inputs else ""
    if "order-budget" in budgets:
        tried.append(f"order: auto ended at order {order} (order-budget)")
    if "element-budget" in budgets:
        tried.append(f"elements: auto ended at {elements} elements (element-budget)")
    if action == "sampling":
        remedy = f"sampling (method.kind: montecarlo, lhs or sobol): {cause}"
    elif action == "order" and "order-budget" in budgets:
        remedy = (
            f"multi-element chaos{along} (method.elements) or an order above {order} set by "
            f"hand (method.order): {cause}"
        )
    elif action == "order":
        remedy = f"raising the order{' of ' + inputs if inputs else ''} (method.order): {cause}"
    elif isinstance(expansion, PiecewiseExpansion):
        more = "raise method.max_elements" if "element-budget" in budgets else "finer cuts, or auto"
        remedy = f"more elements{along} (method.elements: {more}): {cause}"
    else:
        remedy = f"multi-element chaos{along} (method.elements): {cause}"
    if by_element:
        remedy = f"{remedy}; {by_element}"
    return f"{remedy}; tried: {'; '.join(tried)}"


def _error_at_ends(
    germ: NDArray[np.float64], residual: NDArray[np.float64], failing: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """(n,) where along each input the (K, T) held-out residual sits over the failing times:
    the mean of |2u - 1|, u the runs' ranks along the input in (0, 1), weighted by the
    squared residual; 0.5 for an error spread evenly, near 1 for one at the ends of the
    range (a smooth response converging slowly), lower for one around a point inside it."""
    ranks = np.argsort(np.argsort(germ, axis=0), axis=0)
    distance = np.abs(2 * (ranks + 0.5) / germ.shape[0] - 1)
    size = np.max(np.abs(residual[:, failing]))
    if not size > 0 or not np.isfinite(size):
        return np.full(germ.shape[1], 0.5)
    weight = np.sum((residual[:, failing] / size) ** 2, axis=1)
    return weight @ distance / weight.sum()


def _element_errors(
    expansion: PiecewiseExpansion,
    germ: NDArray[np.float64],
    residual: NDArray[np.float64],
    failing: NDArray[np.bool_],
) -> str:
    """Which element holds the largest share of the (K, T) held-out squared error over the
    failing times, with its box and probability: an error far above the element's
    probability sits around a jump or kink there, one in proportion to it is spread."""
    partition = expansion.partition
    size = np.max(np.abs(residual[:, failing]))
    if partition.size < 2 or not size > 0 or not np.isfinite(size):
        return ""
    theta = np.column_stack(
        [d.to_physical(germ[:, k]) for k, d in enumerate(expansion.distributions)]
    )
    where = partition.locate(theta)
    weight = np.sum((residual[:, failing] / size) ** 2, axis=1)
    inside = where >= 0
    shares = np.bincount(where[inside], weights=weight[inside], minlength=partition.size)
    shares = shares / weight.sum()
    e = int(np.argmax(shares))
    support = np.array([d.physical.support() for d in expansion.distributions], dtype=float)
    bounds = zip(expansion.names, partition.bounds[e], support, strict=True)
    box = ", ".join(
        f"{name} in [{low:.4g}, {high:.4g}]"
        for name, (low, high), whole in bounds
        if low > whole[0] or high < whole[1]
    )
    return (
        f"element {e} ({box}) holds {_percent(shares[e])} of the held-out squared error "
        f"where the verdict fails, for {_percent(partition.probability[e])} of the probability"
    )


def _decay_read(name: str, kind: str, rate: float, first: int, last: int) -> str:
    """The decay of the chaos coefficients along one input (:func:`_decay_shape`) in words."""
    if kind == "geometric":
        return (
            f"the chaos coefficients along {name} fall geometrically (energy × {rate:.2g} per "
            f"degree, degrees {first} to {last}), as those of a smooth response, which a "
            "higher order resolves"
        )
    return (
        f"the chaos coefficients along {name} fall algebraically (energy ~ p^-{rate:.2g}, "
        f"degrees {first} to {last}), as those of a jump or a kink, which a higher order "
        "resolves only slowly"
    )


def _cause_remedy(
    expansion: Expansion,
    estimate: NDArray[np.float64],
    failing: NDArray[np.bool_],
    out_of_range_share: NDArray[np.float64],
    ends: NDArray[np.float64] | None,
) -> tuple[str, str, str]:
    """What may help, read from where the tail's energy sits over the failing times:
    ``(action, inputs, cause)``, the action ``"sampling"``, ``"order"`` or ``"elements"``
    along the named inputs (``""``: all), the cause in words.

    - energy spread over several inputs and an error that grows (more than doubles from
      the first failing time to the end): chaotic or long-horizon dynamics, which no
      order fixes — sampling;
    - else, along every input that holds at least ``_SHARED`` of the tail (each failing
      time weighing the same), the decay of the coefficients (:func:`_decay_shape`):
      algebraic along any, as those of a jump or kink — multi-element chaos along those;
      geometric along all, as those of an analytic response — a higher order, unless the
      held-out error sits inside the input's range (at most ``_INSIDE``, below), as a
      kink's does whose first degrees look geometric — multi-element chaos;
    - too few degrees to tell: a higher order when the held-out error sits at the ends of
      the input's range (``ends``, :func:`_error_at_ends`, at least ``_AT_ENDS``), as that
      of a smooth response; multi-element chaos when it sits inside (at most ``_INSIDE``),
      around a jump or kink; else, with the error over the range, steep, oscillating or
      discontinuous when the spectrum does not decay (the outer two layers hold at least
      half the energy of the layers before them, the linear ones at order 3, the response's
      structure still rising at the top degree when they hold more) or, below order 3, the
      surrogate overshoots the runs — multi-element chaos; otherwise a higher order. The
      message says that the order was too low to tell.
    """
    index = expansion.multi_index
    tail = tail_terms(index)
    # The two layers before the tail, the linear terms among them up to order 4 (at order 3
    # they are the only layer before it).
    before = tail_terms(index, 4, lowest=1) & ~tail
    # Each failing time weighs the same: its energies as shares of its own variance.
    energies = _energies(expansion)[:, failing]
    variance = energies[np.any(index > 0, axis=1)].sum(axis=0)
    varies = np.isfinite(variance) & (variance > 0)
    energy = np.nansum(energies[:, varies] / variance[varies], axis=1)
    by_input = (index[tail] > 0).T.astype(float) @ energy[tail]
    total = by_input.sum()
    top = int(np.argmax(by_input))
    name = expansion.names[top]
    if total <= 0:
        return "order", "", "the outer two layers of the expansion carry no energy to read"
    grows = estimate[-1] > _GROWTH * estimate[np.argmax(failing)]
    if expansion.n > 1 and by_input[top] < _CONCENTRATED * total and grows:
        return (
            "sampling",
            "",
            "the error grows with time and spreads over the inputs, as in chaotic or "
            "long-horizon dynamics, which a higher order does not fix",
        )
    holders = [int(k) for k in np.argsort(-by_input) if by_input[k] >= _SHARED * total]
    shapes = {k: _decay_shape(energy, index, k) for k in holders}
    read = [k for k in holders if shapes[k] is not None]  # too few degrees: not read
    place = ""
    if ends is not None:
        place = (
            f"the range of {name} (mean |2u - 1| of their ranks u along it, weighted by the "
            f"squared error: {ends[top]:.2f}; 0.5 if spread evenly)"
        )
    if top in read:
        reads = "; ".join(_decay_read(expansion.names[k], *shapes[k]) for k in read)
        jumps = [expansion.names[k] for k in read if shapes[k][0] == "algebraic"]
        if jumps:
            return "elements", " and ".join(jumps), reads
        if place and ends[top] <= _INSIDE:  # a kink's first degrees may look geometric
            return (
                "elements",
                name,
                f"{reads}, but the surrogate's error at the held-out runs sits inside {place}, "
                "around a kink or steep front there",
            )
        return "order", " and ".join(expansion.names[k] for k in read), reads
    order = int(index[:, top].max())
    unknown = (
        f"; at order {order} too few degrees follow the peak of the spectrum along {name} "
        "to tell a jump or kink from a slowly converging smooth response by it"
    )
    previous = energy[before].sum()
    if place and ends[top] >= _AT_ENDS:
        return (
            "order",
            name,
            f"the surrogate's error at the held-out runs sits at the ends of {place}, as "
            f"that of a smooth response converging slowly{unknown}",
        )
    if place and ends[top] <= _INSIDE:
        return (
            "elements",
            name,
            f"the surrogate's error at the held-out runs sits inside {place}, around a "
            f"jump, kink or steep front there{unknown}",
        )
    if previous > 0:
        ratio = energy[tail].sum() / previous
        steep = ratio >= _FLAT
        read = (
            f"the outer two layers of its spectrum hold {ratio:.2g} times the energy of the "
            "layers before them"
        )
    else:  # order 2: no layer before the tail, the overshoot tells
        steep = bool(np.any(out_of_range_share[failing] > RANGE_SHARE))
        read = f"the surrogate {'leaves' if steep else 'stays within'} the runs' range"
    if not steep:
        return "order", name, f"{read}: a smooth response converging slowly{unknown}"
    spread = ", with the surrogate's error over the range, not at its ends" if place else ""
    return (
        "elements",
        name,
        f"the response is steep, oscillating or discontinuous in {name}: {read}{spread}{unknown}",
    )


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
        element :func:`held_out_placed_elements`) rather than being drawn: the check is then
        :func:`placed_check` (``/validation`` attribute ``placed``).
    batches:
        How many batches of draws the runs hold (``/validation`` attribute ``batches``): each
        is a Latin hypercube, their union is not one, so with more than one the check's
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


def diagnose_all(
    expansions: Mapping[str, object],
    germ: NDArray[np.float64],
    values: Mapping[str, NDArray[np.float64]],
    ok: NDArray[np.bool_],
    times: ArrayLike,
    held_out: HeldOut | None,
    tolerance: float = TOLERANCE,
    axes: Mapping[str, OutputAxis | None] | None = None,
    nominal: Mapping[str, NDArray[np.float64]] | None = None,
    budgets: Collection[str] = (),
    design_error: float | None = None,
) -> dict[str, OutputDiagnostics]:
    """:func:`diagnose` every output with a chaos expansion (one element or several), each on
    its own points: ``times``, or per ``axes`` (:class:`pcmb.result.StudyResult`) the points
    of its axis or ``[0.]`` for a scalar.

    ``germ`` and ``values`` are the (N, n) and (N, T) runs of the design and ``ok`` the (N,)
    nodes that succeeded; the held-out check uses the successful held-out runs; ``nominal``
    holds the run at the nominal parameters (output name -> (T,)), when one succeeded;
    ``budgets`` the codes of the design's budget records and ``design_error`` its own
    estimate of the statistics' error (:func:`diagnose`).
    """
    found = {}
    for name, expansion in expansions.items():
        if not isinstance(expansion, ChaosExpansion | PiecewiseExpansion):
            continue
        holdout = None
        if held_out is not None and held_out.ok.any():
            predicted = expansion.evaluate_germ(held_out.germ[held_out.ok])
            holdout = (predicted, held_out.values[name][held_out.ok])
        grid, label = times, "t"
        if axes is not None and name in axes:
            axis = axes[name]
            grid, label = (np.zeros(1), "") if axis is None else (axis.values, axis.name)
        found[name] = diagnose(
            name,
            expansion,
            values[name][ok],
            grid,
            holdout,
            tolerance,
            germ[ok],
            label,
            None if nominal is None else nominal.get(name),
            budgets,
            None if holdout is None else held_out.germ[held_out.ok],
            None if holdout is None else held_out.weights[held_out.ok],
            held_out is not None and held_out.placed,
            design_error,
            held_out is None or held_out.batches == 1,
        )
    return found
