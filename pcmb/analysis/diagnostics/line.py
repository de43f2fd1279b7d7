"""The line check: a tensor grid of several inputs whose tail lies along one normal input,
against held-out runs placed along that input.

Where the outer layers' energy of the expansions lies almost all in the terms of one normal
input alone (:func:`tail_input`: a heavy tail along one axis, which a few drawn runs miss),
the held-out runs are the Leja points that extend the design's nodes along that input, the
others at their germ's centre (:func:`held_out_line`). :func:`line_check` compares the
expansion's mean and std with those of the expansion corrected along that line, the
correction carried to the other inputs by the profile of the expansion's own top layers along
the input (``docs/diagnostics.md``, "A tail along one axis").
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.check import CONFIDENCE, HeldOutCheck
from pcmb.analysis.diagnostics.decay import Expansion, coefficient_energies
from pcmb.analysis.diagnostics.draws import signed_residuals, widened_inputs
from pcmb.analysis.diagnostics.placed import PLACED_SPARE, converging, interpolated, larger_spread
from pcmb.chaos.basis import tail_terms
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nested import leja_sequence
from pcmb.chaos.nodes import NodeSet

#: A tail lies along one input where the terms of that input alone hold at least this share of
#: the energy of the outer layers' terms curved along some input (:func:`tail_input`): 0.90 to
#: 1 on the axis-aligned tails measured, at most 0.66 on tails along a direction, a factor odd
#: in another input or a phase drifting in two, where a line through the centre misreads.
LINE_SHARE = 0.8
#: A layer's value on the line below this share of its coefficients' norm carries no profile
#: (:func:`line_check`): the correction stays on the terms constant in the other inputs.
_UNSEEN_PROFILE = 1e-8


def _curved_tail(expansion: ChaosExpansion) -> NDArray[np.bool_]:
    """(S,) the outer layers' terms (:func:`~pcmb.chaos.basis.tail_terms`) of degree 2 or more
    along some input."""
    index = np.asarray(expansion.multi_index)
    return tail_terms(index) & np.any(index >= 2, axis=1)


def _alone(index: NDArray[np.int64], k: int) -> NDArray[np.bool_]:
    """(S,) the terms of input k alone (degree 0 in every other input)."""
    return ~np.any(np.delete(index, k, axis=1), axis=1)


def _scale(expansion: Expansion) -> float:
    """The expansion's largest std over time, 0 where none is finite."""
    std = expansion.std()
    finite = std[np.isfinite(std)]
    return float(finite.max()) if finite.size else 0.0


def tail_input(expansions: Iterable[Expansion]) -> int | None:
    """The normal input along which the held-out runs of a tensor grid of several inputs are
    placed (:func:`held_out_line`), or ``None`` (drawn): the one whose terms alone hold at
    least ``LINE_SHARE`` of the energy of the outer layers' terms curved along some input
    (over each expansion's largest std, summed over time) in every expansion that has such
    terms, where at least one has; the same input for all of them."""
    found = set()
    for expansion in expansions:
        scale = _scale(expansion)
        if not isinstance(expansion, ChaosExpansion) or not scale > 0:
            return None
        index = np.asarray(expansion.multi_index)
        energy = coefficient_energies(expansion, scale).reshape(index.shape[0], -1).sum(axis=1)
        tail = _curved_tail(expansion)
        total = float(np.sum(energy[tail]))
        if not total > 0:
            continue  # no tail to meet
        normal = np.flatnonzero(widened_inputs(expansion.distributions))
        shares = [np.sum(energy[tail & _alone(index, k)]) / total for k in normal]
        if index.shape[1] < 2 or not shares or max(shares) < LINE_SHARE:
            return None
        found.add(int(normal[int(np.argmax(shares))]))
    return found.pop() if len(found) == 1 else None


def _centres(distributions: Sequence[Distribution]) -> NDArray[np.float64]:
    """(n,) the germs' means, where the line check holds the other inputs."""
    return np.array([d.family.germ.mean() for d in distributions])


def held_out_line(
    distributions: Sequence[Distribution], design_germ: ArrayLike, axis: int, count: int
) -> tuple[NodeSet, NDArray[np.float64]]:
    """``count`` held-out inputs of a tensor grid placed along input ``axis``: the weighted Leja
    points that extend the design's nodes along it (the distinct values of the (N, n)
    ``design_germ``'s column), every other input at its germ's centre. Weights 1."""
    nodes = np.unique(np.asarray(design_germ, dtype=float)[:, axis])
    family = distributions[axis].family
    points = leja_sequence(family, tuple(nodes), nodes.size + count)[nodes.size :]
    germ = np.tile(_centres(distributions), (count, 1))
    germ[:, axis] = points
    params = np.column_stack([d.to_physical(germ[:, k]) for k, d in enumerate(distributions)])
    return NodeSet(tuple(distributions), germ, params), np.ones(count)


def line_axis(distributions: Sequence[Distribution], germ: ArrayLike) -> int:
    """The input the (K, n) ``germ`` of a line check's runs (:func:`held_out_line`) lies along:
    the one not held at its centre."""
    off = np.any(np.asarray(germ, dtype=float) != _centres(distributions), axis=0)
    if off.sum() > 1:
        raise ValueError("the held-out runs do not lie along one input")
    return int(np.argmax(off))


def line_check(
    expansion: ChaosExpansion,
    node_germ: ArrayLike,
    germ: ArrayLike,
    predicted: ArrayLike,
    observed: ArrayLike,
    scale: float,
    confidence: float = CONFIDENCE,
) -> HeldOutCheck:
    """The held-out check of a tensor grid by K runs placed along one input k
    (:func:`held_out_line`), the others at their centre.

    Along that line the expansion is a polynomial in k; the polynomial through it at the
    design's nodes along k and the K runs (degree N + K - 1, as :func:`placed_check`'s) differs
    from it by a correction d(z_k), the polynomial through 0 at the nodes and the runs'
    residuals (model ``observed`` - surrogate ``predicted``, each (K, T); 0 where round-off of
    the run's size). The correction is carried to the other inputs by the
    profile of the expansion's top layer along k of the same parity (its coefficients over
    its value on the line), which is exact where the response is a product of a function of
    k and one of the others; the corrected expansion's mean and std (exact, from its
    coefficients) are the corrected mean and std, and their differences from the expansion's
    the estimated errors. Their standard errors are how far those move without the last
    ``PLACED_SPARE`` runs, shrunk by their rate of convergence, and, in quadrature, what the
    line does not see: the energy of the outer layers' terms curved along some input that are
    not of k alone, over the std (ΔV / σ). Runs that are not finite are left out; zeros if the
    scale is zero.
    """
    observed = np.atleast_2d(np.asarray(observed, dtype=float))
    predicted = np.atleast_2d(np.asarray(predicted, dtype=float))
    kept = np.isfinite(observed).all(axis=1)
    count = int(kept.sum())
    mean, std = expansion.mean().ravel(), expansion.std().ravel()
    if not scale > 0 or not np.isfinite(scale):
        zeros = np.zeros(observed.shape[1:])
        return HeldOutCheck(*[zeros] * 5, mean, std, zeros, zeros, count, confidence)
    distributions = expansion.distributions
    germ = np.asarray(germ, dtype=float)[kept]
    axis = line_axis(distributions, germ)
    index = np.asarray(expansion.multi_index)
    coefficients = expansion.coefficients.reshape(index.shape[0], -1) / scale
    top = int(index[:, axis].max())
    # The terms as (degree along k, the others' degrees): the layers along k.
    others, where = np.unique(np.delete(index, axis, axis=1), axis=0, return_inverse=True)
    layers = np.zeros((top + 1, others.shape[0], coefficients.shape[1]))
    layers[index[:, axis], where.ravel()] = coefficients
    on_line = np.ones(others.shape[0])
    for column, k in enumerate(np.delete(np.arange(index.shape[1]), axis)):
        values = distributions[k].family.evaluate(_centres(distributions)[k], others[:, column].max())
        on_line = on_line * values[others[:, column]]
    line = np.einsum("jbt,b->jt", layers, on_line)
    constant = np.flatnonzero(~np.any(others, axis=1))[0]
    profiles = []
    for layer in (top, top - 1):  # each degree takes the profile of the top layer of its parity
        norm = np.sqrt(np.sum(layers[max(layer, 0)] ** 2, axis=0))
        seen = np.abs(line[max(layer, 0)]) > _UNSEEN_PROFILE * norm
        fallback = np.zeros((others.shape[0], 1))
        fallback[constant] = 1.0
        ratio = layers[max(layer, 0)] / np.where(seen, line[max(layer, 0)], 1.0)
        profiles.append(np.where(seen, ratio, fallback))
    family = distributions[axis].family
    nodes = np.unique(np.asarray(node_germ, dtype=float)[:, axis])
    points = np.concatenate([nodes, germ[:, axis]])
    residual = signed_residuals(predicted[kept], observed[kept], scale)
    values = np.vstack([np.zeros((nodes.size, residual.shape[1])), residual])

    def corrected(spare: int) -> tuple[NDArray, NDArray, NDArray]:
        """(T,) mean, std and L2 distance from the expansion of the expansion corrected along
        the line without the last ``spare`` runs, over the scale."""
        size = max(nodes.size, points.size - spare)
        correction = interpolated(family, points[:size], values[:size])
        change = correction[:, None, :] * np.stack(profiles)[(top - np.arange(size)) % 2]
        total = np.zeros((max(size, top + 1), *layers.shape[1:]))
        total[: top + 1] = layers
        total[:size] += change
        rich_mean = total[0, constant].copy()
        total[0, constant] = 0.0  # the variance without it: no cancellation on a large mean
        variance = np.sum(total**2, axis=(0, 1))
        distance = np.sqrt(np.sum(change**2, axis=(0, 1)))
        return rich_mean, np.sqrt(np.maximum(variance, 0.0)), distance

    rich_mean, rich_std, distance = corrected(0)
    mean_error, std_error = np.abs(rich_mean - mean / scale), np.abs(rich_std - std / scale)
    unseen = _off_line(expansion, axis, scale)
    if count > PLACED_SPARE:
        fewer_mean, fewer_std, fewer_distance = corrected(PLACED_SPARE)
        mean_moved = np.abs(mean_error - np.abs(fewer_mean - mean / scale))
        std_moved = np.abs(std_error - np.abs(fewer_std - std / scale))
        if count > 2 * PLACED_SPARE:
            least_mean, least_std, _ = corrected(2 * PLACED_SPARE)
            before_mean = np.abs(np.abs(fewer_mean - mean / scale) - np.abs(least_mean - mean / scale))
            before_std = np.abs(np.abs(fewer_std - std / scale) - np.abs(least_std - std / scale))
            mean_moved, std_moved = converging(mean_moved, before_mean), converging(std_moved, before_std)
        mean_se, std_se = np.hypot(mean_moved, unseen), np.hypot(std_moved, unseen)
        moved = np.abs(distance - fewer_distance)
    else:
        mean_se = std_se = moved = np.full(observed.shape[1], np.inf)
    return HeldOutCheck(
        distance,
        distance + moved,
        mean_error,
        std_error,
        larger_spread(mean_error, mean_se, std_error, std_se, confidence),
        rich_mean * scale,
        rich_std * scale,
        mean_se * scale,
        std_se * scale,
        count,
        confidence,
    )


def _off_line(expansion: ChaosExpansion, axis: int, scale: float) -> NDArray[np.float64]:
    """(T,) what the line check along ``axis`` does not see, over the scale: the energy of the
    outer layers' terms curved along some input that are not of that input alone, over the
    expansion's std (ΔV / σ); 0 where it does not vary."""
    index = np.asarray(expansion.multi_index)
    energy = coefficient_energies(expansion, scale)
    off = np.sum(energy[_curved_tail(expansion) & ~_alone(index, axis)], axis=0).ravel()
    sigma = expansion.std().ravel() / scale
    return np.divide(off, sigma, out=np.zeros_like(off), where=sigma > 0)
