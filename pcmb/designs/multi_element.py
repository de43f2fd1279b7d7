"""Multi-element collocation: a tensor Gauss grid in every element, recovered element by element.

``method: {kind: collocation, order, basis, elements, max_elements}``:

- ``elements: {x0: [0.0]}`` cuts input x0 at the physical value 0 (a tensor partition of all
  the inputs' cuts); ``elements: auto`` refines adaptively, in rounds
  (:meth:`MultiElementCollocation.more`); no ``elements`` is one element, plain collocation.
- Each element runs the (P_k + 1)-point Gauss grid of its own conditional inputs and is
  recovered by projection (least squares over its survivors when some failed); the
  expansions are :class:`~pcmb.chaos.elements.PiecewiseExpansion` s.

``elements: auto`` stops on what ``diagnostics.tolerance`` names, the error of the mean and
std relative to the output's largest std, as estimated from the elements' tails
(:func:`element_errors`: the decay of each element's outer degree layers, continued
geometrically, converts to the error of its mean and of the std, each split checks the
model on the parent against what its children changed, and each element's expansion is
checked at the runs of its split ancestors inside it; ``docs/multi_element.md`` has the
derivation and its calibration). ``auto`` starts from one element and, after each
round, while the estimate exceeds the tolerance, splits the elements of largest share, the
fewest whose shares leave the rest within the tolerance, along the inputs that hold at least
half the largest per-input share of their tail energy (the largest shares first, as many as
``max_elements`` leaves room for); the split elements' nodes leave the recovery
(``/nodes/element`` -1) and the children's nodes are the next round.
:meth:`MultiElementCollocation.recover` records (``element-decay``) every output whose
estimate is left above the tolerance, and (``element-budget``) that ``max_elements``
stopped the refinement. A response chaotic in its inputs (the Lorenz attractor) has no
smooth piece to find: splitting only exhausts the budget, and the records stay.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.basis import tail_terms
from pcmb.chaos.elements import Partition, PiecewiseExpansion
from pcmb.chaos.expansion import power_of_two, root_sum_of_squares
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, TensorGrid
from pcmb.chaos.recovery import project_tensor
from pcmb.designs.base import (
    MethodSettings,
    Recovery,
    fit_of,
    least_squares_recovery,
    order_words,
    statistics_warnings,
)
from pcmb.designs.collocation import CollocationSettings, TensorCollocation
from pcmb.result import Design, DesignReport, ReportFile, StudyResult, WarningRecord

__all__ = ["ElementReport", "MultiElementCollocation", "TailErrors", "element_errors"]

#: Largest decay read from an element's tail, per two degrees or per degree
#: (:func:`element_errors`; at it, the energy beyond the tail is taken to be the tail's own: no
#: decay seen).
DECAY_CAP = 0.5
#: A degree layer whose energy is below this fraction squared of its element's mean square is
#: round-off (as a parity's zeros are): it reads no decay.
_ROUND_OFF = 1e-12


class MultiElementCollocation:
    """Tensor Gauss collocation in every element of a partition of the inputs' support.

    The design runs in rounds (:class:`~pcmb.designs.base.AdaptiveDesign`): :meth:`nodes`
    starts a run on the starting partition, :meth:`more` refines it (``elements: auto``),
    and :attr:`partition`, :attr:`node_elements`, :meth:`weights`, :meth:`record` and
    :meth:`recover` describe the partition reached.

    Parameters
    ----------
    inputs:
        Input name -> distribution, germ order.
    settings:
        The ``method:`` settings: ``orders``, ``basis``, ``fit`` as for collocation,
        ``elements`` (a mapping input -> increasing physical split points, ``"auto"`` or
        ``None``) and ``max_elements``.
    partition:
        The starting elements instead of those the settings describe.

    Raises
    ------
    ValueError
        ``method.<key>: ...`` for settings the design cannot use.
    """

    Settings = CollocationSettings

    def __init__(
        self,
        inputs: Mapping[str, Distribution],
        settings: MethodSettings,
        partition: Partition | None = None,
    ):
        self._collocation = TensorCollocation(inputs, settings)  # checks order, basis, fit
        self.settings = settings
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        self.orders, self.basis = self._collocation.orders, self._collocation.basis
        self.elements = settings.elements
        self.max_elements = settings.max_elements
        self.tolerance = settings.diagnostics_tolerance
        if self.elements == "auto" and max(self.orders) < 2:
            raise ValueError(
                "method.order: elements: auto needs order >= 2 (its error estimate reads the "
                "top two degrees)"
            )
        if self.elements == "auto" and self.tolerance is None:
            raise ValueError("diagnostics.tolerance: required by method.elements auto")
        self.start = partition if partition is not None else self._partition()
        self.multi_index = self._collocation._index(TensorGrid(self.distributions, self.orders))
        self.nodes()  # the state of the first round

    def _partition(self) -> Partition:
        if self.elements is None or self.elements == "auto":
            return Partition.whole(self.distributions)
        if not isinstance(self.elements, Mapping):
            raise ValueError("method.elements: expected auto or a mapping input -> split points")
        for name in self.elements:
            if name not in self.names:
                raise ValueError(
                    f"method.elements.{name}: names no input (inputs: {', '.join(self.names)})"
                )
        cuts = [np.atleast_1d(self.elements.get(name, [])).tolist() for name in self.names]
        for name, dist, cut in zip(self.names, self.distributions, cuts, strict=True):
            if np.any(np.diff(cut) <= 0):
                raise ValueError(
                    f"method.elements.{name}: split points must be strictly increasing, got {cut}"
                )
            try:
                Partition.from_splits([dist], [cut])
            except ValueError as error:
                raise ValueError(f"method.elements.{name}: {error}") from None
        return Partition.from_splits(self.distributions, cuts)

    # -- nodes ------------------------------------------------------------------------------

    @property
    def _per_element(self) -> int:
        return math.prod(order + 1 for order in self.orders)

    @property
    def runs(self) -> int:
        """Runs of the first round: every starting element's grid."""
        return self.start.size * self._per_element

    @property
    def budget(self) -> int:
        """Most runs over all rounds: with at most ``max_elements`` elements at the end, at
        most ``max_elements - 1`` elements were split on the way."""
        if self.elements != "auto":
            return self.runs
        return (2 * self.max_elements - 1) * self._per_element

    def nodes(self) -> NodeSet:
        """The first round: every starting element's nodes, element by element (a run starts
        here, so this forgets the refinement of an earlier run); ``.nodes`` in the inputs' own
        germs."""
        self.exhausted, self.estimate, self._fit = False, math.nan, "projection"
        self.factors, self._splits = np.full(self.start.size, np.nan), []
        self.floors: dict[str, NDArray[np.float64]] = {}
        self.node_weights = np.zeros(0)
        return self._grow(self.start, np.zeros(0, dtype=np.intp), np.arange(self.start.size))

    def _grow(self, partition: Partition, kept: NDArray[np.intp], new: NDArray[np.intp]) -> NodeSet:
        """Move to ``partition``, the nodes run so far in its elements ``kept`` (-1: left out),
        and return the nodes of its elements ``new``, which join the run (:attr:`node_weights`
        gains their elements' P_e times Gauss weights)."""
        self.partition = partition
        self.grids = tuple(TensorGrid(inputs, self.orders) for inputs in partition.inputs)
        grids = [self.grids[e] for e in new]
        self.node_elements = np.concatenate([kept, np.repeat(new, [g.size for g in grids])])
        self.node_weights = np.concatenate(
            [self.node_weights, *(partition.probability[e] * self.grids[e].weights for e in new)]
        )
        params = np.concatenate([grid.params for grid in grids])
        germ = np.column_stack([d.to_germ(params[:, k]) for k, d in enumerate(self.distributions)])
        return NodeSet(self.distributions, germ, params)

    def more(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The next round of ``elements: auto``: the nodes of the children of every element
        split (see the module), or ``None`` when none is. The estimate is that of the
        coefficients :meth:`recover` makes: an element with failed nodes is judged by the fit
        of its survivors."""
        if self.elements != "auto":
            return None
        coefficients, _ = self._coefficients(values, ok)
        self._check_splits(coefficients)
        missed = self._missed(coefficients, nodes, values, ok)
        errors = element_errors(
            self.partition, coefficients, self.multi_index, self.factors, self.floors, missed
        )
        self.estimate = errors.estimate()
        if not self.estimate > self.tolerance:
            return None
        size, chosen, refused = self.partition.size, {}, False
        left = np.ones(size, dtype=bool)
        each = errors.of_each()
        for e in np.argsort(-np.nan_to_num(each, nan=-1.0)):
            if not errors.estimate(left) > self.tolerance or not each[e] > 0:
                break
            along = errors.along[e]
            cut = np.flatnonzero(along >= 0.5 * along.max())
            # The inputs of largest share first, as many as max_elements leaves room for.
            room = (self.max_elements - size + 1).bit_length() - 1
            cut = np.sort(cut[np.argsort(-along[cut], kind="stable")][:room])
            if cut.size:
                chosen[int(e)] = cut.tolist()
                size += 2**cut.size - 1
                left[e] = False
            else:
                refused = True
        self.exhausted = refused and not chosen
        if not chosen:
            return None
        parents = self._parent_statistics(coefficients, missed)
        # Children replace their parent in place; the others keep their nodes.
        bounds, renumber, children = [], np.full(self.partition.size, -1), []
        for e in range(self.partition.size):
            if e in chosen:
                split = self.partition.split(e, chosen[e]).bounds[e : e + 2 ** len(chosen[e])]
                family = np.arange(len(bounds), len(bounds) + len(split))
                self._splits.append((family, parents[e]))
                children += family.tolist()
                bounds += list(split)
            else:
                renumber[e] = len(bounds)
                bounds.append(self.partition.bounds[e])
        kept = np.where(self.node_elements >= 0, renumber[self.node_elements], -1)
        factors = np.full(len(bounds), np.nan)
        factors[renumber[renumber >= 0]] = self.factors[renumber >= 0]
        floors = {
            name: np.zeros((len(bounds), *decay.shape)) for name, decay in parents[0].decay.items()
        }
        for name, floor in floors.items():
            if name in self.floors:
                floor[renumber[renumber >= 0]] = self.floors[name][renumber >= 0]
            for family, parent in self._splits:
                floor[family] = parent.decay[name] / 4
        self.factors, self.floors = factors, floors
        return self._grow(Partition(self.distributions, bounds), kept, np.array(children))

    def _parent_statistics(
        self,
        coefficients: Mapping[str, NDArray[np.float64]],
        missed: Mapping[str, NDArray[np.float64]],
    ) -> list[_Parent]:
        """Every element as the parent :meth:`_check_splits` compares its children with."""
        size = self.partition.size
        parents = [_Parent({}, {}, {}) for _ in range(size)]
        for name, c in coefficients.items():
            flat = c.reshape(*c.shape[:2], -1)
            errors = element_errors(
                self.partition, {name: flat}, self.multi_index, np.ones(size), self.floors, missed
            )
            if not errors.mean:
                continue
            unit = _unit(flat)
            scaled = flat / unit
            scale = np.nanmax(PiecewiseExpansion(self.partition, scaled, self.multi_index).std())
            moments = _moments(self.partition.probability, scaled)
            for e, parent in enumerate(parents):
                model = scale * np.fmax(errors.mean[0][e], errors.std[0][e])
                parent.outputs[name] = (moments[0][e], moments[1][e], model)
                parent.decay[name] = errors.decay[0][e]
                parent.units[name] = unit
        return parents

    def _check_splits(self, coefficients: Mapping[str, NDArray[np.float64]]) -> None:
        """Sets the factor of the children of every split since the last call: how many times
        the change of the mean and std from their parent to them exceeds what the checked
        model estimated of the parent's errors (at least 1)."""
        for children, parent in self._splits:
            factor = 1.0
            for name, (mean, square, model) in parent.outputs.items():
                flat = coefficients[name].reshape(*coefficients[name].shape[:2], -1)
                flat = flat / parent.units[name]
                expansion = PiecewiseExpansion(self.partition, flat, self.multi_index)
                moments = _moments(self.partition.probability, flat)
                shift = moments[0][children].sum(axis=0) - mean
                spread = moments[1][children].sum(axis=0) - square - 2 * expansion.mean() * shift
                sigma = expansion.std()
                with np.errstate(divide="ignore", invalid="ignore"):
                    shown = np.fmax(abs(shift), np.where(sigma > 0, abs(spread) / (2 * sigma), 0))
                if np.max(model) > 0:
                    factor = max(factor, float(np.nanmax(shown) / np.max(model)))
            self.factors[children] = factor
        self._splits = []

    def _missed(
        self,
        coefficients: Mapping[str, NDArray[np.float64]],
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> dict[str, NDArray[np.float64]]:
        """Output name -> (E, ...) the root mean square by which every element's expansion
        misses the runs at the nodes of split elements inside it, weighted by their split
        elements' quadrature (0 where there are none): runs its fit did not use. Summed as
        root_sum_of_squares does, so that outputs near 1e300 do not overflow."""
        retired = (self.node_elements < 0) & ok
        if not retired.any():
            size = self.partition.size
            return {name: np.zeros((size, *values[name].shape[1:])) for name in coefficients}
        theta = nodes.params[retired]
        inside = self.partition.locate(theta)[None, :] == np.arange(self.partition.size)[:, None]
        inside = inside * self.node_weights[retired]
        count = np.where(inside.any(axis=1), inside.sum(axis=1), 1.0)
        missed = {}
        for name, c in coefficients.items():
            miss = values[name][retired] - PiecewiseExpansion(self.partition, c, self.multi_index)(
                theta
            )
            # (R, E, ...): each run's miss, weighted for each element it counts in.
            share = np.sqrt(inside / count[:, None]).T.reshape(
                *inside.shape[::-1], *[1] * (miss.ndim - 1)
            )
            missed[name] = root_sum_of_squares(share * miss[:, None])
        return missed

    def weights(self, nodes: NodeSet) -> NDArray[np.float64]:
        """(N,) P_e times the element's Gauss weights (0 at the nodes of split elements): a
        quadrature rule of the inputs' law."""
        return np.where(self.node_elements >= 0, self.node_weights, 0.0)

    def record(self) -> Design:
        auto = self.elements == "auto"
        return Design(
            kind=self.settings.kind,
            grid="element-gauss",
            basis=self.basis,
            orders=self.orders,
            elements=self.partition.size,
            fit=self._fit,
            tolerance=self.tolerance if auto else None,
            label=f"chaos {order_words(self.orders, self.basis)}"
            + (f" (elements auto to {self.tolerance:g})" if auto else ""),
        )

    # -- recovery ---------------------------------------------------------------------------

    def recover(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        """Piecewise expansions of every output from the nodes of the current elements; a
        per-element least-squares fit where nodes of the element failed (reported), and
        ``element-decay`` and ``element-budget`` warnings (see the module)."""
        coefficients, warnings = self._coefficients(values, ok)
        expansions = {
            name: PiecewiseExpansion(self.partition, c, self.multi_index, self.names)
            for name, c in coefficients.items()
        }
        if self.exhausted:
            warnings.append(
                WarningRecord(
                    "element-budget",
                    f"elements: auto stopped at {self.partition.size} of {self.max_elements} "
                    f"elements (method.max_elements) after {nodes.size} runs, with an estimated "
                    f"error {self.estimate:.3g} above the tolerance {self.tolerance:g} "
                    "(diagnostics.tolerance): splitting the elements that hold it would pass "
                    "method.max_elements; raise it or the order, unless an output is chaotic in "
                    "its inputs",
                )
            )
        if self.tolerance is not None:
            missed = self._missed(coefficients, nodes, values, ok)
            warnings += self._decay_warnings(expansions, missed)
        warnings += statistics_warnings(expansions, values, ok, times)
        return Recovery(expansions, tuple(warnings), ElementReport(self.node_elements.copy()))

    def _coefficients(
        self, values: Mapping[str, NDArray[np.float64]], ok: NDArray[np.bool_]
    ) -> tuple[dict[str, NDArray[np.float64]], list[WarningRecord]]:
        """Output name -> (E, S, ...) every current element's coefficients: its projection, or
        where nodes of it failed a least-squares fit of its survivors (reported, and recorded:
        :func:`~pcmb.designs.base.fit_of`)."""
        index = self.multi_index
        position = {tuple(row): s for s, row in enumerate(index)}
        coefficients = {
            name: np.zeros((self.partition.size, index.shape[0], *y.shape[1:]))
            for name, y in values.items()
        }
        warnings: list[WarningRecord] = []
        self._fit = fit_of(ok[self.node_elements >= 0])
        for e, grid in enumerate(self.grids):
            rows = self.node_elements == e
            kept = ok[rows]
            if kept.all():
                for name, y in values.items():
                    coefficients[name][e] = project_tensor(grid, y[rows], index)
                continue
            fitted = least_squares_recovery(
                grid.distributions,
                self.names,
                grid.nodes[kept],
                {name: y[rows][kept] for name, y in values.items()},
                max(self.orders),
                weights=grid.weights[kept],
                caps=self.orders,
            )
            for name, expansion in fitted.expansions.items():
                terms = [position[tuple(row)] for row in expansion.multi_index]
                coefficients[name][e][terms] = expansion.coefficients
            warnings += [
                WarningRecord(w.code, f"element {e}: {w.message}", w.output, w.time_range)
                for w in fitted.warnings
            ]
        return coefficients, warnings

    def _decay_warnings(
        self,
        expansions: Mapping[str, PiecewiseExpansion],
        missed: Mapping[str, NDArray[np.float64]],
    ) -> list[WarningRecord]:
        """``element-decay`` for every output whose estimated error (:func:`element_errors`)
        is above the tolerance; sets :attr:`estimate` to the largest over outputs."""
        records, self.estimate = [], 0.0
        for name, expansion in expansions.items():
            errors = element_errors(
                self.partition,
                {name: expansion.coefficients},
                self.multi_index,
                self.factors,
                self.floors,
                missed,
            )
            estimate, each = errors.estimate(), errors.of_each()
            self.estimate = max(self.estimate, estimate)
            if estimate > self.tolerance:
                worst = int(np.nanargmax(each))
                records.append(
                    WarningRecord(
                        "element-decay",
                        f"the error of the mean and std that the elements' outer degree "
                        f"layers indicate is {estimate:.3g} of the largest std, above the "
                        f"tolerance {self.tolerance:g} (diagnostics.tolerance; most of it in "
                        f"element {worst}, {each[worst]:.3g} alone); elements: auto "
                        f"{'splits' if self.elements == 'auto' else 'would split'} on it; an "
                        "indicator, not a verdict: the held-out check judges the mean and std",
                        name,
                    )
                )
        return records


@dataclass
class _Parent:
    """An element as split: per output name its P_e μ_e, P_e E_e[y²] and the errors of the
    mean and std the checked model (:func:`element_errors`, factor 1) estimates for it, (P,)
    each, in a unit of the output (a power of two, ``units``: squares of outputs near 1e300
    do not overflow), and its checked decay per degree."""

    outputs: dict[str, tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]]
    decay: dict[str, NDArray[np.float64]]
    units: dict[str, float]


def _moments(
    probability: NDArray[np.float64], coefficients: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(E, P) each element's P_e μ_e and P_e E_e[y²] from its (E, S, P) coefficients (the mean
    term first, the basis orthonormal)."""
    weight = probability[:, None]
    return weight * coefficients[:, 0], weight * (coefficients**2).sum(axis=1)


def _unit(coefficients: NDArray[np.float64]) -> float:
    """A power of two near the largest finite coefficient (1 if none): its unit."""
    finite = np.abs(coefficients[np.isfinite(coefficients)])
    largest = float(np.max(finite, initial=0.0))
    return float(power_of_two(largest)) if largest > 0 else 1.0


def _tails(multi_index: NDArray[np.int64]) -> NDArray[np.bool_]:
    """(n, S) the terms in input k's outer two degree layers: α_k >= 1 and α + 2 e_k
    outside the set."""
    present = {tuple(row) for row in multi_index}
    tails = np.zeros(multi_index.T.shape, dtype=bool)
    for k in range(multi_index.shape[1]):
        shifted = multi_index.copy()
        shifted[:, k] += 2
        outside = np.array([tuple(row) not in present for row in shifted])
        tails[k] = outside & (multi_index[:, k] >= 1)
    return tails


@dataclass(frozen=True)
class TailErrors:
    """The error of the mean and std that the elements' tails indicate (:func:`element_errors`).

    Attributes
    ----------
    mean, std:
        Per output, (E, P) each element's contribution to the error of the mean and of the
        std at every time, over the output's largest std (NaN where the element's
        coefficients are not finite).
    along:
        (E, n) each element's tail energy along each input, at its worst output and time.
    decay:
        Per output, (E, P) each element's decay per degree as read (before ``floors``; no
        decay over a zero layer), which floors its children.
    """

    mean: tuple[NDArray[np.float64], ...]
    std: tuple[NDArray[np.float64], ...]
    along: NDArray[np.float64]
    decay: tuple[NDArray[np.float64], ...]

    def estimate(self, among: NDArray[np.bool_] | slice = slice(None)) -> float:
        """The estimated error of the mean and std, the largest over outputs and times, from
        the tails of the elements ``among`` (all by default; the others' taken as resolved):
        the elements' mean errors in quadrature (their signs unknown), their std errors
        summed."""
        return max(
            (
                float(
                    np.max(
                        np.fmax(
                            np.sqrt(np.nansum(m[among] ** 2, axis=0)), np.nansum(s[among], axis=0)
                        )
                    )
                )
                for m, s in zip(self.mean, self.std, strict=True)
            ),
            default=0.0,
        )

    def of_each(self) -> NDArray[np.float64]:
        """(E,) the estimate from each element's tail alone (NaN: not finite)."""
        each = [np.maximum(m, s).max(axis=1) for m, s in zip(self.mean, self.std, strict=True)]
        return np.max(each, axis=0) if each else np.zeros(self.along.shape[0])


def _decay(tail: NDArray[np.float64], before: NDArray[np.float64]) -> NDArray[np.float64]:
    """The decay ``tail / before``, at most :data:`DECAY_CAP` (at it where nothing is before),
    0 where the tail is empty, NaN where it is not finite."""
    with np.errstate(divide="ignore", invalid="ignore"):
        decay = np.minimum(tail / before, DECAY_CAP)
    decay = np.where(tail > 0, np.nan_to_num(decay, nan=DECAY_CAP), 0.0)
    return np.where(np.isfinite(tail), decay, np.nan)


def element_errors(
    partition: Partition,
    coefficients: Mapping[str, NDArray[np.float64]],
    multi_index: NDArray[np.int64],
    factors: NDArray[np.float64] | None = None,
    floors: Mapping[str, NDArray[np.float64]] | None = None,
    missed: Mapping[str, NDArray[np.float64]] | None = None,
) -> TailErrors:
    """The error of the mean and std that the elements' tails indicate (``docs/multi_element.md``).

    Each element e, of probability P_e, misses energy M_e of its variance and errs its mean by
    a coefficient of energy A_e, both continued geometrically from its tail:

    - an element no split has checked (``factors`` NaN, the default): T the energy of the
      outer two degree layers, ρ the decay per two degrees, the slower of the two parities'
      (each its outer layer over the one two degrees before; a parity with no layer before,
      the even one at order 3 and both at order 2, the two outer layers over the two before,
      per layer), at most :data:`DECAY_CAP`; M = T ρ / (1 - ρ) and A = T ρ² / (1 - ρ), the
      decay carried two layers only, since a kink's first degrees mimic a fast one;
    - an element whose parent's split measured what this model missed on it (``factors``
      f >= 1, :meth:`MultiElementCollocation.more`): ρ the decay per degree, the square
      root of the slower parity's decay per two degrees where both parities have a layer two
      degrees below their outer one (a response's halves alternate per degree), else the
      slower of the last two ratios (a kink's coefficients oscillate), the cap over a zero
      layer, and at least ``floors`` (a quarter of its parent's at the same time, read with
      no decay over a zero layer: faster is a parity, not a decay), T the energy of the
      outer layer, of degree p (at least ρ times the layer before), M = f T ρ / (1 - ρ) and
      √A = f √T ρ^((p+2)/2), the coefficient of degree 2p + 2, the first its Gauss rule does
      not integrate.

    M is at least the square of ``missed``, the root mean square by which the element's
    expansion misses the runs of its split ancestors inside it: what one ratio cannot tell (at
    order 2, an element odd about a jump has no degree-2 term, and reads a parity as a fast
    decay), runs it did not fit
    measure.

    With σ the piecewise surrogate's std: mean error (Σ_e (P_e √A_e)²)^½ (their signs
    unknown), std error Σ_e P_e M_e / (2σ).

    Parameters
    ----------
    partition:
        The E elements.
    coefficients:
        Output name -> (E, S, ...) coefficients.
    multi_index:
        (S, n) their terms.
    factors:
        (E,) each element's factor f, NaN where no split checked it.
    floors:
        Output name -> (E, ...) each element's least decay per degree (default 0).
    missed:
        Output name -> (E, ...) each element's root mean square miss at runs it did not fit,
        in the output's units (default 0).
    """
    tails = _tails(multi_index)
    two = tails.any(axis=0)
    outer = tail_terms(multi_index, 1, lowest=1)
    second = tail_terms(multi_index, 2, lowest=1) & ~outer
    third = tail_terms(multi_index, 3, lowest=1) & ~outer & ~second
    fourth = tail_terms(multi_index, 4, lowest=1) & ~outer & ~second & ~third
    # The outer layer's degree in one input (the least of the inputs that vary): the tensor
    # Gauss rule first misses the term of degree 2p + 2 in one input.
    orders = multi_index.max(axis=0, initial=0)
    degree = int(min(orders[orders >= 1], default=0))
    size, n = partition.size, multi_index.shape[1]
    factors = np.full(size, np.nan) if factors is None else factors
    checked = np.isfinite(factors)[:, None]
    floors = {} if floors is None else floors
    means, stds, decays, along = [], [], [], np.zeros((size, n))
    for name, c in coefficients.items():
        flat = c.reshape(*c.shape[:2], -1)  # (E, S, P)
        sigma = PiecewiseExpansion(partition, flat, multi_index).std()
        scale = float(np.max(sigma[np.isfinite(sigma)], initial=0.0))
        if not scale > 0:
            continue
        squares = (flat / scale) ** 2
        tail = squares[:, two].sum(axis=1)
        last, previous = squares[:, outer].sum(axis=1), squares[:, second].sum(axis=1)
        # Each parity's decay per two degrees, its outer layer over the one two degrees before
        # (round-off reads as nothing); a parity with no layer before (the even one at order 3,
        # both at order 2) reads the outer two layers over the two before, per layer.
        noise = _ROUND_OFF**2 * squares.sum(axis=1)
        before = squares[:, third].sum(axis=1), squares[:, fourth].sum(axis=1)
        layer = [np.where(e > noise, e, 0.0) for e in (last, previous, *before)]
        block = _decay(tail / 2, (layer[2] + layer[3]) / max(third.any() + fourth.any(), 1))
        decay = np.zeros_like(tail)
        for upper, lower, readable in ((0, 2, third.any()), (1, 3, fourth.any())):
            read = _decay(layer[upper], layer[lower]) if readable else block
            decay = np.fmax(decay, np.where(layer[upper] > 0, read, 0.0))
        decay = np.where(np.isfinite(tail), decay, np.nan)
        missing = tail * decay / (1 - decay)
        aliased = np.sqrt(tail * decay**2 / (1 - decay))
        # The decay per degree: each parity's per two degrees where both parities have a layer
        # two degrees below their outer one (order >= 4), else the slower of the last two
        # ratios (one at order 2). Over a zero layer ``fall`` reads the cap, no decay seen (a
        # step between nodes symmetric about it zeroes the even layers); ``seen``, the decay
        # that floors the children, reads none: a parity is not a decay.
        if fourth.any():
            pairs, power = ((0, 2), (1, 3)), 0.5
        else:
            pairs, power = ((0, 1), (1, 2)) if third.any() else ((0, 1),), 1.0
        fall, seen = np.zeros_like(tail), np.zeros_like(tail)
        for upper, lower in pairs:
            read = np.minimum(_decay(layer[upper], layer[lower]) ** power, DECAY_CAP)
            fall = np.fmax(fall, read)
            seen = np.fmax(seen, np.where(layer[lower] > 0, read, 0.0))
        fall, seen = (np.where(np.isfinite(tail), f, np.nan) for f in (fall, seen))
        decays.append(seen)
        fall = np.fmax(fall, floors[name].reshape(size, -1) if name in floors else 0.0)
        last = np.fmax(last, previous * fall)
        factor = np.nan_to_num(factors, nan=1.0)[:, None]
        missing = np.where(checked, factor * last * fall / (1 - fall), missing)
        if missed is not None and name in missed:
            missing = np.fmax(missing, (missed[name].reshape(size, -1) / scale) ** 2)
        aliased = np.where(checked, factor * np.sqrt(last) * fall ** ((degree + 2) / 2), aliased)
        weight = partition.probability[:, None]
        means.append(weight * aliased)
        with np.errstate(divide="ignore", invalid="ignore"):
            stds.append(np.where(sigma > 0, weight * missing * scale / (2 * sigma), 0.0))
        worst = np.argmax(np.nan_to_num(tail, nan=np.inf), axis=1)
        energy = np.einsum("ks,es->ek", tails.astype(float), squares[np.arange(size), :, worst])
        larger = energy.sum(axis=1) > along.sum(axis=1)
        along = np.where(larger[:, None], energy, along)
    return TailErrors(tuple(means), tuple(stds), along, tuple(decays))


@dataclass(frozen=True)
class ElementReport(DesignReport):
    """The element of every node, stored as ``/nodes/element`` (N,): -1 for the nodes of
    elements split by ``elements: auto`` (run, kept, not used by the recovery). The elements
    themselves are the expansions' partition (``/elements``)."""

    key: ClassVar[str] = "elements"

    node_elements: NDArray[np.intp]

    def write(self, file: ReportFile) -> None:
        file.dataset("nodes/element", self.node_elements, "node")

    @classmethod
    def read(cls, file: ReportFile) -> ElementReport | None:
        found = file.read("nodes/element")
        return None if found is None else cls(found)

    def summary(self, result: StudyResult) -> list[tuple[str, str]]:
        partition = result.partition
        return [] if partition is None else [("elements", partition.describe(result.input_names))]
