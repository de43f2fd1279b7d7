"""Collocation on a Smolyak sparse grid, recovered by sparse pseudo-spectral projection."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nested import NestedRule, nested_rule
from pcmb.chaos.nodes import NodeSet
from pcmb.chaos.sparse import SparseGrid, find_rows
from pcmb.designs.base import (
    MethodSettings,
    Recovery,
    fit_of,
    least_squares_recovery,
    missing_keys,
    refuse,
    statistics_warnings,
)
from pcmb.designs.collocation import CollocationSettings
from pcmb.result import Design

__all__ = ["SparseCollocation", "sparse_recovery"]

#: Most level multi-indices a grid may combine: beyond, building even the index set is slow
#: (and the grid has far too many nodes to run).
MAX_TENSORS = 1_000_000


class SparseCollocation:
    """``method: {kind: ..., level, rule}``: the isotropic Smolyak grid of ``level`` on the
    nested ``rule`` (``auto``: Gauss–Patterson for uniform inputs, Genz–Keister for normal
    ones, weighted Leja otherwise; see :func:`pcmb.chaos.nested.nested_rule`).

    The expansion holds every term the grid recovers exactly (:attr:`SparseGrid.multi_index`).
    The quadrature weights sum to one but some are negative: they are a signed combination
    of tensor rules. A grid with failed nodes is no quadrature rule: its survivors are
    refitted by (unweighted) least squares, and the record of the last recovery says so
    (``fit: regression``).
    """

    Settings = CollocationSettings
    _fit = "projection"

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        level, rule = settings.level, settings.rule
        kind = settings.kind
        problems = missing_keys(f"kind {kind}", level=level)
        if settings.orders is not None:
            problems.append(("method.order", f"kind {kind} takes method.level, not an order"))
        refuse(problems)
        self.kind, self.level, self.rule = kind, int(level), rule
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        n = len(self.distributions)
        if math.comb(n + self.level, n) > MAX_TENSORS:
            raise ValueError(
                f"method.level: level {level} in {n} inputs combines more than {MAX_TENSORS} "
                "tensor rules: use a lower level"
            )
        nested_rules(inputs, rule)  # each input's rule exists
        try:
            self.grid = SparseGrid.smolyak(self.distributions, self.level, rule)
        except ValueError as error:
            raise ValueError(f"method.level: {error}") from None

    @property
    def runs(self) -> int:
        return self.grid.size

    def nodes(self) -> NodeSet:
        return NodeSet(self.distributions, self.grid.nodes, self.grid.params)

    def weights(self, nodes: NodeSet) -> NDArray[np.float64]:
        """(N,) the sparse quadrature weights: they sum to one, some are negative."""
        return self.grid.weights

    @cached_property
    def orders(self) -> tuple[int, ...]:
        """Highest degree per input in the recovered terms."""
        return tuple(int(p) for p in self.grid.multi_index.max(axis=0))

    def record(self) -> Design:
        rule = ", ".join(dict.fromkeys(rule.name for rule in self.grid.rules))
        return Design(
            kind=self.kind,
            grid="smolyak",
            basis="sparse",
            orders=self.orders,
            level=self.level,
            fit=self._fit,
            rule=rule,
            label=f"Smolyak level {self.level}, rule {rule}",
        )

    def recover(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        self._fit = fit_of(ok)
        return sparse_recovery(self.grid, self.names, values, ok, times)


def nested_rules(inputs: Mapping[str, Distribution], rule: str) -> tuple[NestedRule, ...]:
    """The nested 1-D rule ``rule`` (``method.rule``) of every input, in order.

    Raises
    ------
    ValueError
        At ``method.rule``, naming the input it has no rule for.
    """
    rules = []
    for name, dist in inputs.items():
        try:
            rules.append(nested_rule(dist.family, rule))
        except ValueError as error:
            raise ValueError(f"method.rule: input {name!r}: {error}") from None
    return tuple(rules)


class GrowingGrid:
    """What the designs that grow a nested sparse grid round by round share (``adaptive``,
    ``order: auto``): the grid so far, its node ids in run order (``_ids``), the new nodes a
    larger grid brings, its weights and its recovery in run order."""

    distributions: tuple[Distribution, ...]
    names: tuple[str, ...]
    _grid: SparseGrid
    _ids: NDArray[np.float64]
    #: The fit of the last recovery (:func:`fit_of`).
    _fit = "projection"

    def _order(self, nodes: NodeSet) -> NDArray[np.intp]:
        """Row of every grid node among ``nodes`` (in run order)."""
        if nodes.size != self._grid.size:
            raise ValueError(f"{nodes.size} nodes given, the grid so far has {self._grid.size}")
        return find_rows(self._ids, self._grid.node_ids)

    def _adopt(self, grid: SparseGrid) -> NodeSet:
        """Make ``grid`` (holding the one so far) the grid; the nodes it adds."""
        self._grid = grid
        new = find_rows(self._ids, grid.node_ids) < 0
        self._ids = np.vstack([self._ids, grid.node_ids[new]])
        return NodeSet(self.distributions, grid.nodes[new], grid.params[new])

    def weights(self, nodes: NodeSet) -> NDArray[np.float64]:
        """(N,) the grid's quadrature weights, in run order (they sum to one, some negative)."""
        weights = np.empty(nodes.size)
        weights[self._order(nodes)] = self._grid.weights
        return weights

    def _grid_recovery(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        """:func:`sparse_recovery` on the grid so far, of values given in run order."""
        order = self._order(nodes)
        on_grid = {name: y[order] for name, y in values.items()}
        self._fit = fit_of(ok)
        return sparse_recovery(self._grid, self.names, on_grid, ok[order], times)


def sparse_recovery(
    grid: SparseGrid,
    names: Sequence[str],
    values: Mapping[str, NDArray[np.float64]],
    ok: NDArray[np.bool_],
    times: NDArray[np.float64] | None = None,
) -> Recovery:
    """Expansions of every output from (N, T) values at ``grid.nodes``: sparse projection, or
    with failed nodes (``ok`` False) a least-squares refit of the survivors on terms up to the
    grid's degrees; with :func:`~pcmb.designs.base.statistics_warnings`."""
    names = tuple(names)
    index = grid.multi_index
    if ok.all():
        # All outputs in one pass over the tensor rules: (N, outputs, T).
        stacked = grid.project(np.stack(list(values.values()), axis=1))
        recovery = Recovery(
            {
                name: ChaosExpansion(stacked[:, k], index, grid.distributions, names)
                for k, name in enumerate(values)
            }
        )
    else:
        recovery = least_squares_recovery(
            grid.distributions,
            names,
            grid.nodes[ok],
            {name: y[ok] for name, y in values.items()},
            int(index.sum(axis=1).max()),
            caps=tuple(int(p) for p in index.max(axis=0)),
        )
    warnings = recovery.warnings + statistics_warnings(recovery.expansions, values, ok, times)
    return Recovery(recovery.expansions, warnings)
