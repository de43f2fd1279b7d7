"""Order refinement of tensor collocation (``method.order: auto``).

Round l runs the tensor grid of level l in every input of the nested ``rule`` (``auto``:
Gauss–Patterson for uniform inputs, Genz–Keister for normal ones, Leja otherwise;
:mod:`pcmb.chaos.nested`), from level 1, and projects on the tensor basis of the degrees that
grid integrates exactly (its orders). The rules are nested, so each grid holds every node of
the one before: a round runs only the new nodes and no run is discarded. From the second
round on, d_l is the largest difference, over outputs and times, of the mean and std from the
previous round's (the first round's from the centre run's, level 0, std 0), relative to the
output's largest std over time (the diagnostics' scale, ``docs/diagnostics.md``): the error
of the coarser grid. A round doubles the points per input, so the finer grid's error is far
smaller: :func:`extrapolated_error` carries the decay per degree observed over the last two
changes to the finer grid's degree (the smallest over inputs).
The rounds end when it is below ``diagnostics.tolerance``, or, with an ``order-budget``
warning, when the next level's order would pass :data:`MAX_ORDER` or its grid
``method.max_runs``, or a node failed.

All inputs are raised together: the estimate compares whole levels and does not say which
input holds the error (kind ``adaptive`` with ``basis: tensor`` raises one input at a time).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet
from pcmb.chaos.sparse import SparseGrid, box_index_set, find_rows
from pcmb.designs.adaptive import DEFAULT_MAX_RUNS
from pcmb.designs.base import MethodSettings, Recovery, order_words
from pcmb.designs.collocation import CollocationSettings
from pcmb.designs.smolyak import GrowingGrid, nested_rules
from pcmb.result import Design, DesignReport, Refinement, ReportFile, StudyResult, WarningRecord

__all__ = [
    "MAX_ORDER",
    "OrderRefinement",
    "RefinementReport",
    "extrapolated_error",
    "order_indicator",
]

#: Highest order ``order: auto`` tries.
MAX_ORDER = 24

Statistics = dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]


def order_indicator(lower: Statistics, higher: Statistics) -> float:
    """The largest difference over outputs and times of the (mean, std) of two orders,
    relative to each output's largest std over time at the higher order."""
    worst = 0.0
    for name, (mean, std) in higher.items():
        low_mean, low_std = lower[name]
        gap = float(np.max(np.maximum(np.abs(mean - low_mean), np.abs(std - low_std))))
        scale = float(np.max(std))
        worst = max(worst, gap / scale if scale > 0 else (0.0 if gap == 0 else math.inf))
    return worst


def extrapolated_error(changes: list[float], degrees: list[int]) -> float:
    """The estimated error of the last grid from the changes d_1..d_l of the mean and std
    between successive grids (levels 0..l) of degrees 0 = p_0 < p_1 < ... < p_l: the error
    falls geometrically in the degree, by ρ = min(1, d_l / d_{l-1})^(1 / (p_{l-1} - p_{l-2}))
    per degree as observed last, so the last grid's is d_l ρ^(p_l - p_{l-1}) (d_1 alone)."""
    if len(changes) < 2 or changes[-2] <= 0:
        return changes[-1]
    rate = min(1.0, changes[-1] / changes[-2]) ** (1.0 / (degrees[-2] - degrees[-3]))
    return changes[-1] * rate ** (degrees[-1] - degrees[-2])


class OrderRefinement(GrowingGrid):
    """``method: {kind: collocation, order: auto, rule, max_runs}``: tensor grids of nested
    rules, one level more in every input per round, until the estimated error meets
    ``diagnostics_tolerance`` (see the module); ``max_runs`` (default 1000) bounds the runs."""

    Settings = CollocationSettings

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        for key in ("tolerance", "max_samples", "level"):
            if getattr(settings, key) is not None:
                raise ValueError(
                    f"method.{key}: order auto refines to diagnostics.tolerance within "
                    "method.max_runs"
                )
        if settings.diagnostics_tolerance is None:
            raise ValueError("diagnostics.tolerance: required by method.order auto")
        if (settings.basis or "tensor") != "tensor":
            raise ValueError(
                f"method.basis: order auto projects on the tensor basis of its grid, got "
                f"{settings.basis!r}"
            )
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        self.rules = nested_rules(inputs, settings.rule)
        self.tolerance = float(settings.diagnostics_tolerance)
        self.max_runs = DEFAULT_MAX_RUNS if settings.max_runs is None else int(settings.max_runs)
        self._first = self._level(1)
        two = self._level(2).size
        if self.max_runs < two:
            raise ValueError(
                f"method.max_runs: {self.max_runs} runs do not allow one comparison: levels 1 "
                f"and 2 take {two} runs"
            )
        self._reset()

    def _level(self, level: int) -> SparseGrid:
        """The tensor grid of ``level`` in every input."""
        return SparseGrid(self.distributions, box_index_set((level,) * len(self.rules)), self.rules)

    def _orders(self, grid: SparseGrid) -> tuple[int, ...]:
        return tuple(int(p) for p in grid.multi_index.max(axis=0))

    def _reset(self) -> None:
        """The state of the first round: the grid of level 1."""
        self._grid = self._first
        self._ids = self._first.node_ids
        self._statistics: Statistics | None = None
        self._changes: list[float] = []
        self._degrees = [0]
        self._history: list[tuple[tuple[int, ...], int, float]] = []
        self._stopped: str | None = None

    @property
    def runs(self) -> int:
        """Runs of the first round."""
        return self._first.size

    @property
    def budget(self) -> int:
        """Most runs of all rounds together."""
        return self.max_runs

    def nodes(self) -> NodeSet:
        return NodeSet(self.distributions, self._first.nodes, self._first.params)

    def record(self) -> Design:
        orders = self._orders(self._grid)
        return Design(
            kind="collocation",
            grid="tensor-nested",
            basis="tensor",
            orders=orders,
            fit="projection",
            rule=", ".join(dict.fromkeys(rule.name for rule in self.rules)),
            samples=self._grid.size,
            tolerance=self.tolerance,
            max_runs=self.max_runs,
            label=f"chaos {order_words(orders, 'tensor')} (order auto to {self.tolerance:g}, "
            f"{self._grid.size} runs)",
        )

    def more(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The new nodes of the next level's grid while the estimated error exceeds the
        tolerance and the budget allows, else ``None``."""
        if nodes.size == self.runs:  # the first round of a (new) run
            self._reset()
        order = self._order(nodes)
        level = int(self._grid.index_set.max())
        if not ok[order].all():
            self._stopped = (
                f"{int(np.sum(~ok[order]))} node(s) of level {level} failed, and a round "
                "needs every node: see the failures"
            )
            return None
        if self._statistics is None:  # level 0: the centre run, in every grid
            self._statistics = self._statistics_on(self._level(0), nodes, values)
        statistics = self._statistics_on(self._grid, nodes, values)
        self._changes.append(order_indicator(self._statistics, statistics))
        self._degrees.append(min(self._orders(self._grid)))
        estimate = extrapolated_error(self._changes, self._degrees)
        self._statistics = statistics
        self._history.append((self._orders(self._grid), nodes.size, estimate))
        if estimate < self.tolerance:
            return None
        last = any(rule.max_level is not None and level >= rule.max_level for rule in self.rules)
        grid = None if last else self._level(level + 1)
        if grid is None or max(self._orders(grid)) > MAX_ORDER:
            self._stopped = (
                f"the next level passes order {MAX_ORDER}, the highest order auto tries "
                "(pcmb.designs.refine.MAX_ORDER), or its rule's last level, so more runs would "
                "not help: order alone may not converge (a steep, discontinuous or chaotic "
                "response), follow the diagnostics' remedy"
            )
            return None
        if grid.size > self.max_runs:
            self._stopped = (
                f"level {level + 1} would take {grid.size - nodes.size} more runs, past the "
                "budget: raise method.max_runs, or follow the diagnostics' remedy (order alone "
                "may not converge for a steep, discontinuous or chaotic response)"
            )
            return None
        return self._adopt(grid)

    def _statistics_on(
        self, grid: SparseGrid, nodes: NodeSet, values: Mapping[str, NDArray[np.float64]]
    ) -> Statistics:
        """The mean and std of every output on ``grid``, whose nodes have all run."""
        rows = find_rows(self._ids, grid.node_ids)
        projected = grid.project(np.stack([y[rows] for y in values.values()], axis=1))
        statistics = {}
        for k, name in enumerate(values):
            expansion = ChaosExpansion(projected[:, k], grid.multi_index, self.distributions)
            statistics[name] = (expansion.mean(), expansion.std())
        return statistics

    def recover(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        recovery = self._grid_recovery(nodes, values, ok, times)
        history = self._history
        refinement = Refinement(
            orders=np.array([h[0] for h in history], dtype=np.int64).reshape(
                -1, len(self.distributions)
            ),
            runs=np.array([h[1] for h in history], dtype=np.int64),
            indicator=np.array([h[2] for h in history], dtype=float),
        )
        warnings = recovery.warnings
        if self._stopped is not None:
            reached = f"{history[-1][2]:.3g}" if history else "unknown"
            warnings += (
                WarningRecord(
                    "order-budget",
                    f"order refinement ended at order {max(self._orders(self._grid))} after "
                    f"{nodes.size} of {self.max_runs} runs (method.max_runs), the estimated "
                    f"error {reached} above the tolerance {self.tolerance:g} "
                    f"(diagnostics.tolerance): {self._stopped}",
                ),
            )
        return Recovery(recovery.expansions, warnings, RefinementReport(refinement))


@dataclass(frozen=True)
class RefinementReport(DesignReport):
    """The rounds of ``order: auto`` (:class:`~pcmb.result.Refinement`), stored as
    ``/refinement/orders`` (R, n), ``runs`` and ``indicator`` (R,)."""

    key: ClassVar[str] = "refinement"

    refinement: Refinement

    def write(self, file: ReportFile) -> None:
        rounds = self.refinement
        file.dataset("refinement/orders", rounds.orders, None, "input")
        file.dataset("refinement/runs", rounds.runs)
        file.dataset("refinement/indicator", rounds.indicator)

    @classmethod
    def read(cls, file: ReportFile) -> RefinementReport | None:
        found = {key: file.read(f"refinement/{key}") for key in ("orders", "runs", "indicator")}
        return None if found["orders"] is None else cls(Refinement(**found))

    def summary(self, result: StudyResult) -> list[tuple[str, str]]:
        """Per round: the order and its indicator."""
        rounds = ", ".join(
            f"{int(orders.max())}: {error:.2g}"
            for orders, error in zip(self.refinement.orders, self.refinement.indicator, strict=True)
        )
        return [("refined", f"order: indicator per round {rounds}")]
