"""Multi-element collocation: a tensor Gauss grid in every element, recovered element by element.

``method: {kind: ..., order, basis, elements, max_elements, element_threshold}``:

- ``elements: {x0: [0.0]}`` cuts input x0 at the physical value 0 (a tensor partition of all
  the inputs' cuts); ``elements: auto`` refines adaptively (:func:`refine`); no ``elements``
  is one element, plain collocation.
- Each element runs the (P_k + 1)-point Gauss grid of its own conditional inputs and is
  recovered by projection (least squares over its survivors when some failed); the
  expansions are :class:`~pcmb.chaos.elements.PiecewiseExpansion` s.

The decay indicator of an element (Wan & Karniadakis, J. Comput. Phys. 209 (2005)) is the
share η_e of its variance in the outer two degree layers of its basis (two, because a
response even about the element's centre has zero odd coefficients), at the worst time and
output; weighted by the element's probability, P_e η_e above ``element_threshold`` marks an
element whose chaos has not converged. ``auto`` splits such elements, along the inputs that
hold at least half the largest per-input share of that energy, until none is above the
threshold or ``max_elements`` is reached; :meth:`MultiElementCollocation.recover` warns
(``element-decay``) about every output left above it. A response chaotic in its inputs (the
Lorenz attractor) has no smooth piece to find: splitting only exhausts the budget, and the
warning stays.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.elements import Partition, PiecewiseExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, TensorGrid
from pcmb.chaos.recovery import project_tensor
from pcmb.designs.base import (
    MethodSettings,
    Recovery,
    least_squares_recovery,
    statistics_warnings,
)
from pcmb.designs.collocation import TensorCollocation
from pcmb.result import Design, WarningRecord

__all__ = ["MultiElementCollocation", "Refinement", "decay_scores", "refine"]

#: Default largest weighted decay indicator P_e η_e accepted (``method.element_threshold``).
THRESHOLD = 1e-4
#: Default element budget of ``elements: auto`` (``method.max_elements``).
MAX_ELEMENTS = 16
#: Tail energies below this fraction squared of the mean square are round-off.
_RELATIVE_NOISE = 1e-12

#: A batch runner: (B, n) physical inputs -> output name -> (B, ...) values.
Runner = Callable[[NDArray[np.float64]], Mapping[str, NDArray[np.float64]]]


class MultiElementCollocation:
    """Tensor Gauss collocation in every element of a partition of the inputs' support.

    Parameters
    ----------
    inputs:
        Input name -> distribution, germ order.
    settings:
        The ``method:`` settings: ``orders``, ``basis``, ``fit`` as for collocation, and
        (read with ``getattr``) ``elements`` (a mapping input -> physical split points,
        ``"auto"`` or ``None``), ``max_elements`` and ``element_threshold``.
    partition:
        The elements to use instead of those the settings describe (e.g. from
        :func:`refine`).

    Raises
    ------
    ValueError
        ``method.<key>: ...`` for settings the design cannot use.
    """

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
        self.elements: Any = getattr(settings, "elements", None)
        self.max_elements = int(getattr(settings, "max_elements", MAX_ELEMENTS))
        self.threshold = float(getattr(settings, "element_threshold", THRESHOLD))
        if self.max_elements < 1:
            raise ValueError(f"method.max_elements: must be >= 1, got {self.max_elements}")
        if not self.threshold > 0:
            raise ValueError(f"method.element_threshold: must be > 0, got {self.threshold}")
        if self.elements == "auto" and max(self.orders) < 2:
            raise ValueError(
                "method.order: elements: auto needs order >= 2 (its decay indicator reads the "
                "top two degrees)"
            )
        self.partition = partition if partition is not None else self._partition()

    def _partition(self) -> Partition:
        if self.elements is None or self.elements == "auto":
            return Partition.whole(self.distributions)
        if not isinstance(self.elements, Mapping):
            raise ValueError("method.elements: expected auto or a mapping input -> split points")
        unknown = set(self.elements) - set(self.names)
        if unknown:
            raise ValueError(f"method.elements: unknown input(s) {sorted(unknown)}")
        cuts = [np.atleast_1d(self.elements.get(name, [])).tolist() for name in self.names]
        for name, dist, cut in zip(self.names, self.distributions, cuts, strict=True):
            try:
                Partition.from_splits([dist], [cut])
            except ValueError as error:
                raise ValueError(f"method.elements.{name}: {error}") from None
        return Partition.from_splits(self.distributions, cuts)

    # -- nodes ------------------------------------------------------------------------------

    @cached_property
    def grids(self) -> tuple[TensorGrid, ...]:
        """The Gauss grid of each element, in its conditional inputs."""
        return tuple(TensorGrid(inputs, self.orders) for inputs in self.partition.inputs)

    @property
    def runs(self) -> int:
        return self.partition.size * math.prod(order + 1 for order in self.orders)

    def nodes(self) -> NodeSet:
        """All elements' nodes, element by element; ``.nodes`` in the inputs' own germs."""
        params = np.concatenate([grid.params for grid in self.grids])
        germ = np.column_stack([d.to_germ(params[:, k]) for k, d in enumerate(self.distributions)])
        return NodeSet(self.distributions, germ, params)

    @cached_property
    def node_elements(self) -> NDArray[np.intp]:
        """(N,) the element of every node (``/nodes/element``)."""
        return np.repeat(np.arange(self.partition.size), [grid.size for grid in self.grids])

    def weights(self, nodes: NodeSet) -> NDArray[np.float64]:
        """(N,) P_e times the element's Gauss weights: a quadrature rule of the inputs' law."""
        probability = self.partition.probability
        return np.concatenate(
            [p * grid.weights for p, grid in zip(probability, self.grids, strict=True)]
        )

    def record(self) -> Design:
        return Design(
            kind=self.settings.kind,
            grid="element-gauss",
            basis=self.basis,
            orders=self.orders,
            elements=self.partition.size,
            fit="projection",
        )

    # -- recovery ---------------------------------------------------------------------------

    @cached_property
    def multi_index(self) -> NDArray[np.int64]:
        """(S, n) the terms of every element."""
        return self._collocation._index(self.grids[0])

    def recover(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        """Piecewise expansions of every output; a per-element least-squares fit where nodes of
        the element failed (reported), and ``element-decay`` warnings (see the module)."""
        index = self.multi_index
        position = {tuple(row): s for s, row in enumerate(index)}
        coefficients = {
            name: np.zeros((self.partition.size, index.shape[0], *y.shape[1:]))
            for name, y in values.items()
        }
        warnings: list[WarningRecord] = []
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
        expansions = {
            name: PiecewiseExpansion(self.partition, c, index, self.names)
            for name, c in coefficients.items()
        }
        warnings += self._decay_warnings(expansions)
        warnings += statistics_warnings(expansions, values, ok, times)
        return Recovery(expansions, tuple(warnings))

    def _decay_warnings(self, expansions: Mapping[str, PiecewiseExpansion]) -> list[WarningRecord]:
        records = []
        for name, expansion in expansions.items():
            scores, _ = decay_scores(
                self.partition, {name: expansion.coefficients}, self.multi_index
            )
            above = np.flatnonzero(scores > self.threshold)
            if above.size:
                worst = int(np.argmax(scores))
                records.append(
                    WarningRecord(
                        "element-decay",
                        f"the chaos has not converged in {above.size} of {scores.size} "
                        f"element(s): P_e·η_e up to {scores[worst]:.3g} (element {worst}) "
                        f"against the threshold {self.threshold:g}; more elements or a higher "
                        "order may help, unless the output is chaotic in its inputs, which no "
                        "partition fixes",
                        name,
                    )
                )
        return records


def _tails(multi_index: NDArray[np.int64]) -> NDArray[np.bool_]:
    """(n, S) the terms in input k's outer two degree layers: α_k >= 1 and α + 2 e_k outside
    the set."""
    present = {tuple(row) for row in multi_index}
    tails = np.zeros(multi_index.T.shape, dtype=bool)
    for k in range(multi_index.shape[1]):
        shifted = multi_index.copy()
        shifted[:, k] += 2
        outside = np.array([tuple(row) not in present for row in shifted])
        tails[k] = outside & (multi_index[:, k] >= 1)
    return tails


def decay_scores(
    partition: Partition,
    coefficients: Mapping[str, NDArray[np.float64]],
    multi_index: NDArray[np.int64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The weighted decay indicator of every element and where its tail energy lies.

    Parameters
    ----------
    partition:
        The E elements.
    coefficients:
        Output name -> (E, S, ...) coefficients.
    multi_index:
        (S, n) their terms.

    Returns
    -------
    scores, shares
        (E,) P_e η_e, η_e the largest share (over outputs and times) of the element's
        variance in its tail terms; (E, n) the tail energy of each input at that output and
        time. NaN where coefficients are not finite.
    """
    tails = _tails(multi_index)
    anywhere = tails.any(axis=0)
    zero = ~multi_index.any(axis=1)
    size, n = partition.size, multi_index.shape[1]
    eta, shares = np.zeros(size), np.zeros((size, n))
    for c in coefficients.values():
        squares = c.reshape(*c.shape[:2], -1) ** 2  # (E, S, P)
        variance = squares[:, ~zero].sum(axis=1)
        floor = _RELATIVE_NOISE**2 * (variance + squares[:, zero].sum(axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = squares[:, anywhere].sum(axis=1) / (variance + floor)
        ratio = np.where(variance + floor > 0, ratio, 0.0)
        worst = np.argmax(np.nan_to_num(ratio, nan=np.inf), axis=1)
        top = ratio[np.arange(size), worst]
        better = (top > eta) | np.isnan(top)  # a NaN stays
        eta = np.where(better, top, eta)
        energy = np.einsum("ks,es->ek", tails.astype(float), squares[np.arange(size), :, worst])
        shares = np.where(better[:, None], energy, shares)
    return partition.probability * eta, shares


@dataclass(frozen=True)
class Refinement:
    """What :func:`refine` found.

    Attributes
    ----------
    design:
        The design on the final partition; its :meth:`~MultiElementCollocation.nodes` are the
        rows of ``values``.
    values:
        Output name -> (N, ...) the runs of the final elements' nodes.
    runs:
        Model runs spent, including those of elements later split.
    exhausted:
        Whether elements above the threshold were left unsplit for lack of budget.
    """

    design: MultiElementCollocation
    values: dict[str, NDArray[np.float64]]
    runs: int
    exhausted: bool


def refine(design: MultiElementCollocation, run: Runner) -> Refinement:
    """Adaptive multi-element refinement (``elements: auto``).

    Starting from ``design``'s partition, run every element without runs in one batch, score
    the elements (:func:`decay_scores`) and split those above ``design.threshold``, the
    highest scores first, along the inputs holding at least half of the largest tail share,
    while the partition stays within ``design.max_elements``; repeat until no element is
    split. Elements whose runs are not all finite are not split (their scores are NaN);
    :meth:`MultiElementCollocation.recover` fits them from their survivors.

    Parameters
    ----------
    design:
        The starting design (its settings give the orders, basis, threshold and budget).
    run:
        Runs a batch: (B, n) physical inputs -> output name -> (B, ...) values; the only way
        the refinement reaches the model.
    """
    inputs = dict(zip(design.names, design.distributions, strict=True))
    runs: list[dict[str, NDArray[np.float64]] | None] = [None] * design.partition.size
    spent = 0
    while True:
        pending = [e for e, r in enumerate(runs) if r is None]
        if pending:
            grids = [design.grids[e] for e in pending]
            batch = run(np.concatenate([grid.params for grid in grids]))
            ends = np.cumsum([0, *(grid.size for grid in grids)])
            for e, start, stop in zip(pending, ends[:-1], ends[1:], strict=True):
                runs[e] = {name: np.asarray(y)[start:stop] for name, y in batch.items()}
            spent += int(ends[-1])
        coefficients = {
            name: np.stack(
                [
                    project_tensor(g, r[name], design.multi_index)
                    for g, r in zip(design.grids, runs, strict=True)
                ]
            )
            for name in runs[0]
        }
        scores, shares = decay_scores(design.partition, coefficients, design.multi_index)
        above = [int(e) for e in np.argsort(-np.nan_to_num(scores)) if scores[e] > design.threshold]
        size, chosen = design.partition.size, {}
        for e in above:
            along = np.flatnonzero(shares[e] >= 0.5 * shares[e].max())
            if size + 2**along.size - 1 <= design.max_elements:
                chosen[e] = along
                size += 2**along.size - 1
        if not chosen:
            values = {name: np.concatenate([r[name] for r in runs]) for name in runs[0]}
            return Refinement(design, values, spent, exhausted=bool(above))
        partition = design.partition
        for e in sorted(chosen, reverse=True):
            partition = partition.split(e, chosen[e].tolist())
            runs[e : e + 1] = [None] * 2 ** chosen[e].size
        design = MultiElementCollocation(inputs, design.settings, partition)
