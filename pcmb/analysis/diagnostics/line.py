"""The line check: a tensor grid of several inputs whose tail lies along one normal input,
against held-out runs placed along that input.

Where the outer layers' energy of the expansions lies almost all in the terms of one normal
input alone (:func:`tail_input`: a heavy tail along one axis, which a few drawn runs miss),
the held-out runs are the Leja points that extend the design's nodes along that input, the
others at their germ's centre (:func:`held_out_line`). :func:`line_check` compares the
expansion's mean and std with those of the expansion corrected along that line, the
correction carried to the other inputs by the profile of the expansion's own top layers along
the input (``docs/diagnostics.md``, "A tail along one input: placed along it").
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.analysis.diagnostics.check import CONFIDENCE, HeldOutCheck
from pcmb.analysis.diagnostics.decay import Expansion, coefficient_energies, largest_std
from pcmb.analysis.diagnostics.draws import (
    LINEAR_SHARE,
    held_out_placed,
    signed_residuals,
    widened_inputs,
)
from pcmb.analysis.diagnostics.placed import (
    PLACED_SPARE,
    converging,
    interpolated,
    placed_result,
    unseen_errors,
)
from pcmb.chaos.basis import tail_terms
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet

#: A tail lies along one input where the terms of that input alone hold at least this share of
#: the energy of the outer layers' terms curved along some input (:func:`tail_input`): 0.90 to
#: 1 on the axis-aligned tails measured, at most 0.66 on tails along a direction, a factor odd
#: in another input or a phase drifting in two, where a line through the centre misreads.
LINE_SHARE = 0.8
#: The largest share of an output's variance (summed over time) its terms constant along the
#: line's input may hold (:func:`tail_input`): a part additive in the other inputs, which the
#: line does not see and the profile does not carry (z1² + tanh(3 z2) at order 2, whose odd
#: tanh shows as z2 alone, with no curved term to say it errs); a whole error in that share
#: moves the std by at most half of it. 0.04 on exp(0.35 z1 t) (1 + 0.2 z2) (summed over
#: time: its late times), 0.29 on that sum.
OFF_LINE_SHARE = 0.05
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


def tail_input(expansions: Iterable[Expansion]) -> int | None:
    """The normal input along which the held-out runs of a tensor grid of several inputs are
    placed (:func:`held_out_line`), or ``None`` (drawn): the one whose terms alone hold at
    least ``LINE_SHARE`` of the energy of the outer layers' terms curved along some input
    (over each expansion's largest std, summed over time) in every expansion that has such
    terms (more than ``LINEAR_SHARE`` of its variance), where at least one has; the same input
    for all of them, where the line passes through the grid's nodes (:func:`_through_nodes`)
    and in every expansion that varies the terms constant along that input hold at most
    ``OFF_LINE_SHARE`` of its variance (what the line cannot see)."""
    found, varying = set(), []
    for expansion in expansions:
        index = np.asarray(expansion.multi_index)
        if not isinstance(expansion, ChaosExpansion) or index.shape[1] < 2:
            return None
        scale = largest_std(expansion.std())
        if not scale > 0:
            continue  # an output that does not vary has no tail
        energy = coefficient_energies(expansion, scale).reshape(index.shape[0], -1).sum(axis=1)
        varying.append((expansion, index, energy))
        tail = _curved_tail(expansion)
        total = float(np.sum(energy[tail]))
        if not total > LINEAR_SHARE * np.sum(energy[index.sum(axis=1) > 0]):
            continue  # no tail to meet: a polynomial of degree 1, to round-off
        normal = np.flatnonzero(widened_inputs(expansion.distributions))
        shares = [np.sum(energy[tail & _alone(index, k)]) / total for k in normal]
        if not shares or max(shares) < LINE_SHARE:
            return None
        found.add(int(normal[int(np.argmax(shares))]))
    if len(found) != 1:
        return None
    axis = found.pop()
    if not _through_nodes(varying[0][0], axis):
        return None
    for _, index, energy in varying:
        varies = index.sum(axis=1) > 0
        if np.sum(energy[varies & (index[:, axis] == 0)]) > OFF_LINE_SHARE * np.sum(energy[varies]):
            return None
    return axis


def _through_nodes(expansion: ChaosExpansion, axis: int) -> bool:
    """Whether the line along input ``axis`` through the other inputs' centres passes through
    the tensor grid's nodes (each other input's Gauss rule of its order has a node at its
    centre: an even order of a symmetric germ), so that the expansion interpolates the model
    there. At an odd order the line lies between the nodes, where the expansion errs by the
    other inputs' interpolation error, which the correction, pinned to 0 at the nodes, takes
    for the error along the line: exp(0.3 z1 t) (1 + 0.6 cos(2.5 z2)) at order 3 was flagged
    from t = 0 for a true crossing at 3.5."""
    index = np.asarray(expansion.multi_index)
    centres = _centres(expansion.distributions)
    for k, distribution in enumerate(expansion.distributions):
        if k != axis:
            nodes = distribution.family.gauss_rule(int(index[:, k].max()) + 1).nodes
            if not np.any(np.isclose(nodes, centres[k], rtol=0.0, atol=1e-12)):
                return False
    return True


def _centres(distributions: Sequence[Distribution]) -> NDArray[np.float64]:
    """(n,) the germs' means, where the line check holds the other inputs: each family's
    first monic recurrence coefficient (without importing scipy.stats)."""
    return np.array([d.family.recurrence(1)[0][0] for d in distributions])


def held_out_line(
    distributions: Sequence[Distribution], design_germ: ArrayLike, axis: int, count: int
) -> tuple[NodeSet, NDArray[np.float64]]:
    """``count`` held-out inputs of a tensor grid placed along input ``axis``: the weighted Leja
    points that extend the design's nodes along it (the distinct values of the (N, n)
    ``design_germ``'s column), every other input at its germ's centre. Weights 1."""
    nodes = np.unique(np.asarray(design_germ, dtype=float)[:, axis])
    line, _ = held_out_placed(distributions[axis], nodes, count)
    germ = np.tile(_centres(distributions), (count, 1))
    germ[:, axis] = line.nodes[:, 0]
    params = np.column_stack([d.to_physical(germ[:, k]) for k, d in enumerate(distributions)])
    return NodeSet(tuple(distributions), germ, params), np.ones(count)


def _line_axis(distributions: Sequence[Distribution], germ: ArrayLike) -> int:
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
    the estimated errors, the mean's plus the line interpolant's own error from the degrees
    beyond it (as :func:`placed_check`'s). Their standard errors are how far those move without
    the last ``PLACED_SPARE`` runs, shrunk by their rate of convergence, and, in quadrature,
    what the line does not see: the energy of the outer layers' terms curved along some input
    that are not of k alone, over the std (ΔV / σ). Runs that are not finite are left out;
    zeros if the scale is zero.
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
    axis = _line_axis(distributions, germ)
    layers, line, constant = _layers(expansion, axis, scale)
    top = layers.shape[0] - 1
    # Each degree of the correction takes the profile of the top layer of its parity.
    profiles = np.stack(
        [_profile(layers[layer], line[layer], constant) for layer in (top, top - 1)]
    )
    family = distributions[axis].family
    nodes = np.unique(np.asarray(node_germ, dtype=float)[:, axis])
    points = np.concatenate([nodes, germ[:, axis]])
    residual = signed_residuals(predicted[kept], observed[kept], scale)
    values = np.vstack([np.zeros((nodes.size, residual.shape[1])), residual])

    def errors(spare: int) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        """(T,) errors of the mean and std, L2 distance from the expansion, mean and std of
        the expansion corrected along the line without the last ``spare`` runs, over the
        scale."""
        size = max(nodes.size, points.size - spare)
        correction = interpolated(family, points[:size], values[:size])
        change = correction[:, None, :] * profiles[(top - np.arange(size)) % 2]
        total = np.zeros((max(size, top + 1), *layers.shape[1:]))
        total[: top + 1] = layers
        total[:size] += change
        rich_mean = total[0, constant].copy()
        total[0, constant] = 0.0  # the variance without it: no cancellation on a large mean
        rich_std = np.sqrt(np.sum(total**2, axis=(0, 1)))
        return (
            np.abs(rich_mean - mean / scale),
            np.abs(rich_std - std / scale),
            np.sqrt(np.sum(change**2, axis=(0, 1))),
            rich_mean,
            rich_std,
        )

    found = errors(0)
    mean_error, std_error, distance, rich_mean, rich_std = found
    # The line's own interpolant errs on the mean too, from the degrees beyond it, as a placed
    # check's (unseen_errors): a jump along the line that its rule misses.
    on_line = np.zeros((points.size, residual.shape[1]))
    on_line[: min(points.size, top + 1)] = line[: points.size]
    on_line += interpolated(family, points, values)
    unseen, _ = unseen_errors(family, points, on_line, std=False)
    mean_error = mean_error + unseen
    if count > PLACED_SPARE:
        fewer = errors(PLACED_SPARE)
        moves = [np.abs(found[i] - fewer[i]) for i in range(3)]
        if count > 2 * PLACED_SPARE:
            least = errors(2 * PLACED_SPARE)
            for i in range(2):
                moves[i] = converging(moves[i], np.abs(fewer[i] - least[i]))
        off = _off_line(expansion, axis, scale)
        mean_se = np.hypot(moves[0], off)
        std_se, moved = np.hypot(moves[1], off), moves[2]
    else:
        mean_se = std_se = moved = np.full(observed.shape[1], np.inf)
    return placed_result(
        (distance, mean_error, std_error),
        (moved, mean_se, std_se, mean_se + unseen),
        (rich_mean, rich_std),
        scale,
        count,
        confidence,
    )


def _layers(
    expansion: ChaosExpansion, axis: int, scale: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """The expansion's coefficients over the scale as layers along input ``axis``: (P + 1, B, T)
    by degree along it (P the top one) and the B multi-indices of the other inputs; the (P + 1,
    T) coefficients of the polynomial in ``axis`` it is on the line through the others'
    centres; and the row of B constant in the others."""
    index = np.asarray(expansion.multi_index)
    coefficients = expansion.coefficients.reshape(index.shape[0], -1) / scale
    others, where = np.unique(np.delete(index, axis, axis=1), axis=0, return_inverse=True)
    layers = np.zeros((int(index[:, axis].max()) + 1, others.shape[0], coefficients.shape[1]))
    layers[index[:, axis], where.ravel()] = coefficients
    on_line = np.ones(others.shape[0])
    centres = _centres(expansion.distributions)
    for column, k in enumerate(np.delete(np.arange(index.shape[1]), axis)):
        family = expansion.distributions[k].family
        on_line = on_line * family.evaluate(centres[k], others[:, column].max())[others[:, column]]
    constant = int(np.flatnonzero(~np.any(others, axis=1))[0])
    return layers, np.einsum("jbt,b->jt", layers, on_line), constant


def _profile(layer: NDArray[np.float64], on_line: NDArray[np.float64], constant: int) -> NDArray:
    """(B, T) a layer's (B, T) coefficients in the other inputs over its (T,) value ``on_line``:
    what a correction of its degree along the line is in the others; only the ``constant``
    row where the layer has no value on the line (``_UNSEEN_PROFILE`` of its norm)."""
    seen = np.abs(on_line) > _UNSEEN_PROFILE * np.sqrt(np.sum(layer**2, axis=0))
    fallback = np.zeros((layer.shape[0], 1))
    fallback[constant] = 1.0
    return np.where(seen, layer / np.where(seen, on_line, 1.0), fallback)


def _off_line(expansion: ChaosExpansion, axis: int, scale: float) -> NDArray[np.float64]:
    """(T,) what the line check along ``axis`` does not see, over the scale: the energy of the
    outer layers' terms curved along some input that are not of that input alone, over the
    expansion's std (ΔV / σ); 0 where it does not vary."""
    index = np.asarray(expansion.multi_index)
    energy = coefficient_energies(expansion, scale)
    off = np.sum(energy[_curved_tail(expansion) & ~_alone(index, axis)], axis=0).ravel()
    sigma = expansion.std().ravel() / scale
    return np.divide(off, sigma, out=np.zeros_like(off), where=sigma > 0)
