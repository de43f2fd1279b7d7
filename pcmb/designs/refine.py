"""Order refinement of tensor collocation (``method.order: auto``).

Round k runs the tensor Gauss grid of order k in every input, from order 1. From the second
round on, the indicator compares the round's statistics with the previous order's: the largest
difference, over outputs and times, of the mean and of the std, relative to the output's
largest std over time (the diagnostics' scale, ``docs/diagnostics.md``: on the paper cases
this indicator fired no later than the true error in every output and order measured, where
per-time normalisations raise false alarms). The rounds end when it is below
``diagnostics.tolerance``, or, with an ``order-budget`` warning, when the next order would
pass :data:`MAX_ORDER` or ``method.max_runs``, or a node failed.

All inputs are raised together: the indicator compares whole orders and does not say which
input holds the error, and the grid of the next order must be run anyway, as Gauss rules are
not nested. For the same reason few runs are reused: a node of an earlier round is reused
only where the new grid has the very same node, which for Gauss rules of symmetric inputs
(uniform, normal) is the centre, shared by every even order; the orders in between share
none. Nested rules (``pcmb.chaos.nested``) would reuse every run, but their grids are not
Gauss grids and they grow in levels, not orders (kind ``adaptive`` refines that way); here
the final expansion is exactly the tensor collocation of the order reached.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, TensorGrid
from pcmb.designs.adaptive import DEFAULT_MAX_RUNS
from pcmb.designs.base import MethodSettings, Recovery
from pcmb.designs.collocation import CollocationSettings, TensorCollocation
from pcmb.result import Design, Refinement, WarningRecord

__all__ = ["MAX_ORDER", "OrderRefinement", "order_indicator"]

#: Highest order ``order: auto`` tries.
MAX_ORDER = 12

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


class OrderRefinement:
    """``method: {kind: collocation, order: auto, basis, max_runs}``: tensor Gauss grids of
    orders 1, 2, ... until the order indicator meets ``diagnostics_tolerance`` (see the
    module); ``max_runs`` (default 1000) bounds the runs of all rounds together."""

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
        self.inputs = dict(inputs)
        self.distributions = tuple(inputs.values())
        self.settings = settings
        self.tolerance = float(settings.diagnostics_tolerance)
        self.max_runs = DEFAULT_MAX_RUNS if settings.max_runs is None else int(settings.max_runs)
        self._first = self._collocation(1)  # checks basis and fit
        two = 2 ** len(self.distributions) + 3 ** len(self.distributions)
        if self.max_runs < two:
            raise ValueError(
                f"method.max_runs: {self.max_runs} runs do not allow one comparison: orders 1 "
                f"and 2 take {two} runs"
            )
        self._reset()

    def _collocation(self, order: int) -> TensorCollocation:
        orders = (order,) * len(self.distributions)
        return TensorCollocation(self.inputs, dataclasses.replace(self.settings, orders=orders))

    def _reset(self) -> None:
        """The state of the first round: the grid of order 1."""
        self._grid = TensorGrid(self.distributions, self._first.orders)
        self._rows = np.arange(self._grid.size)
        self._known = {row.tobytes(): k for k, row in enumerate(self._grid.nodes)}
        self._statistics: Statistics | None = None
        self._history: list[tuple[tuple[int, ...], int, float]] = []
        self._stopped: str | None = None

    @property
    def runs(self) -> int:
        """Runs of the first round."""
        return self._first.runs

    @property
    def budget(self) -> int:
        """Most runs of all rounds together."""
        n = len(self.distributions)
        return min(self.max_runs, sum((p + 1) ** n for p in range(1, MAX_ORDER + 1)))

    def nodes(self) -> TensorGrid:
        return self._grid

    def weights(self, nodes: TensorGrid | NodeSet) -> NDArray[np.float64]:
        """(N,) the Gauss weights of the last grid at its nodes, 0 at the other runs."""
        weights = np.zeros(nodes.size)
        weights[self._rows] = self._grid.weights
        return weights

    def record(self) -> Design:
        found = self._collocation(self._grid.orders[0]).record()
        return dataclasses.replace(
            found,
            samples=len(self._known),
            tolerance=self.tolerance,
            max_runs=self.max_runs,
            label=f"{found.label} (order auto to {self.tolerance:g}, {len(self._known)} runs)",
        )

    def more(
        self,
        nodes: TensorGrid | NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The new nodes of the next order's grid while the indicator exceeds the tolerance
        and the budget allows, else ``None``."""
        if nodes.size == self.runs:  # the first round of a (new) run
            self._reset()
        order = self._grid.orders[0]
        if not ok[self._rows].all():
            self._stopped = (
                f"{int(np.sum(~ok[self._rows]))} node(s) of order {order} failed, and a round "
                "needs every node: see the failures"
            )
            return None
        on_grid = {name: y[self._rows] for name, y in values.items()}
        found = self._collocation(order).recover(self._grid, on_grid, ok[self._rows])
        statistics = {name: (e.mean(), e.std()) for name, e in found.expansions.items()}
        indicator = (
            math.nan if self._statistics is None else order_indicator(self._statistics, statistics)
        )
        self._statistics = statistics
        self._history.append((self._grid.orders, nodes.size, indicator))
        if indicator < self.tolerance:
            return None
        if order == MAX_ORDER:
            self._stopped = (
                f"order {MAX_ORDER} is the highest order auto tries "
                f"(pcmb.designs.refine.MAX_ORDER), so more runs would not help: order alone "
                "may not converge (a steep, discontinuous or chaotic response), follow the "
                "diagnostics' remedy"
            )
            return None
        grid = TensorGrid(self.distributions, (order + 1,) * len(self.distributions))
        rows = np.array([self._known.get(row.tobytes(), -1) for row in grid.nodes])
        new = rows < 0
        if nodes.size + int(new.sum()) > self.max_runs:
            self._stopped = (
                f"order {order + 1} would take {int(new.sum())} more runs, past the budget: "
                "raise method.max_runs, or follow the diagnostics' remedy (order alone may not "
                "converge for a steep, discontinuous or chaotic response)"
            )
            return None
        rows[new] = nodes.size + np.arange(int(new.sum()))
        self._known.update(
            (row.tobytes(), k) for row, k in zip(grid.nodes[new], rows[new], strict=True)
        )
        self._grid, self._rows = grid, rows
        return NodeSet(self.distributions, grid.nodes[new], grid.params[new])

    def recover(
        self,
        nodes: TensorGrid | NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        rows = self._rows
        on_grid = {name: y[rows] for name, y in values.items()}
        recovery = self._collocation(self._grid.orders[0]).recover(
            self._grid, on_grid, ok[rows], times
        )
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
                    f"order refinement ended at order {self._grid.orders[0]} after "
                    f"{nodes.size} of {self.max_runs} runs (method.max_runs), the last "
                    f"indicator {reached} above the tolerance {self.tolerance:g} "
                    f"(diagnostics.tolerance): {self._stopped}",
                ),
            )
        return Recovery(recovery.expansions, warnings, refinement=refinement)
