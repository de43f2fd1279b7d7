"""Order refinement of tensor collocation (``method.order: auto``).

Round l runs the tensor grid of level l in every input of the nested ``rule`` (``auto``:
Gauss–Patterson for uniform inputs, Genz–Keister for normal ones, Leja otherwise;
:mod:`pcmb.chaos.nested`), from level 1, and projects on the tensor basis of the degrees that
grid integrates exactly (its orders). The rules are nested, so each grid holds every node of
the one before: a round runs only the new nodes and no run is discarded. After each round the
estimated error of the mean and std, relative to the output's largest std over time (the
diagnostics' scale, ``docs/diagnostics.md``), is :func:`box_errors`' largest over the inputs:
the change d_k the grid's last level in input k makes (the grid against the grid one level
lower in k alone), carried to the grid's degree by the decay of the coefficients along k
(:func:`error_ratio`), or, where larger, what the squared coefficients past the grid's degree
in k add to its std (:func:`tail_share`). The first round (level 1) can so stop on its own.
The rounds end when it is below ``diagnostics.tolerance``, or, with an ``order-budget``
warning, when the next level's order would pass :data:`MAX_ORDER` (or its rule has no next
level) or its grid ``method.max_runs``; a failed node ends them with a ``nodes-failed`` record,
a value that is not finite at a node counted as run with a ``statistic-non-finite`` one (joined
to the statistics' record of that output).

All inputs are raised together (kind ``adaptive`` with ``basis: tensor`` raises the one with
the largest estimated error, one at a time).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.expansion import ChaosExpansion, root_sum_of_squares
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet
from pcmb.chaos.sparse import SparseGrid, box_index_set, find_rows
from pcmb.designs.adaptive import BLIND, DEFAULT_MAX_RUNS
from pcmb.designs.base import MethodSettings, Recovery, order_words
from pcmb.designs.collocation import CollocationSettings
from pcmb.designs.smolyak import GrowingGrid, nested_rules
from pcmb.result import (
    Design,
    NodeFailure,
    Placement,
    RecordReport,
    Refinement,
    StudyResult,
    WarningRecord,
)

__all__ = [
    "MAX_ORDER",
    "OrderRefinement",
    "RefinementReport",
    "box_errors",
    "error_ratio",
    "tail_share",
]

#: Highest order ``order: auto`` tries.
MAX_ORDER = 24
#: The fall of the estimate over the last level that says a response converges with order.
CONVERGING = 10.0
#: Degrees past a grid's own over which :func:`tail_share` sums the extrapolated norms.
TAIL_DEGREES = 80
#: Steepest fall of the norms' ratios per log of the degree still read as an entire
#: function's (exp's ratios fall like 1/q: 1); a steeper one is a lucky small norm at the top.
MAX_STEEPENING = 1.5


def box_errors(grid: SparseGrid, values: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n,) the estimated error of the mean and std left in each input of a tensor ``grid``
    (a box of levels L_k) from its (N, outputs, T) ``values``, relative to each output's
    largest std over time: d_k times :func:`error_ratio` along k, with d_k the largest change
    of the mean and std between the box and the box one level lower in input k (the lower
    box's error in k), or, where larger, the std's truncation along k: what the squared norms
    past the box's degree in k (:func:`tail_share`) add to its std.
    """
    distributions, rules = grid.distributions, grid.rules
    coefficients = grid.project(values)
    degree = grid.multi_index
    mean, std = _moments(coefficients, grid)
    spread = std.max(axis=-1)
    levels = grid.index_set.max(axis=0)
    errors = np.zeros(levels.size)
    for k, (rule, top) in enumerate(zip(rules, levels, strict=True)):
        lower = SparseGrid(
            distributions, box_index_set(levels - np.eye(levels.size, dtype=int)[k]), rules
        )
        low_mean, low_std = _moments(
            lower.project(values[find_rows(grid.node_ids, lower.node_ids)]), lower
        )
        change = np.maximum(np.abs(mean - low_mean), np.abs(std - low_std)).max(axis=-1)
        relative = np.divide(change, spread, out=np.zeros_like(change), where=spread > 0)
        norms = [
            float(root_sum_of_squares(coefficients[degree[:, k] == p]).max())
            for p in range(int(degree[:, k].max()) + 1)
        ]
        ratio = error_ratio(norms, rule.projection_degree(int(top) - 1))
        # The std's truncation: sqrt(std² + the squared norms past the top degree) - std.
        missing = math.sqrt(tail_share(norms)) * root_sum_of_squares(
            coefficients[degree[:, k] == len(norms) - 1]
        )
        truncation = (np.hypot(std, missing) - std).max(axis=-1)
        truncated = np.divide(truncation, spread, out=np.zeros_like(truncation), where=spread > 0)
        errors[k] = max(relative.max() * ratio, truncated.max())
    return errors


def error_ratio(norms: list[float], low: int) -> float:
    """The error along an input of a grid of degree p against that of the grid of degree
    ``low`` below it, from the norms n_0..n_p of the coefficients of degree 0..p in it.

    A grid of degree p integrates degree 2p + 1 exactly, so its error is carried by the
    coefficients from degree 2p + 2: the ratio is the product of the per-degree ratios
    r_q = n_q / n_(q-1) over degrees 2 low + 3 .. 2p + 2, extrapolated by :func:`_decay`'s
    r_q = ρ (p/q)^s. Where the norms of the top two degrees are round-off (:data:`BLIND` of the
    largest from degree 1), the grid holds a polynomial response exactly along k: their size.
    Else 1 where fewer than two norms are above round-off (the decay cannot be told).
    """
    resolved = _resolved(norms)
    if resolved is not None:
        return resolved
    decay = _decay(norms)
    if decay is None:
        return 1.0
    slope, steepening = decay
    top = len(norms) - 1
    first, last = 2 * low + 3, 2 * top + 2  # the degrees whose ratios the error falls by
    count = last - first + 1
    factorials = math.lgamma(last + 1) - math.lgamma(first) - count * math.log(top)
    log = slope * count - steepening * factorials
    return float(np.exp(min(0.0, log)))


def tail_share(norms: list[float]) -> float:
    """Σ_(q > p) n_q² / n_p²: the squared norms past the grid's degree p, which its std
    misses, against the top one's, from the norms n_0..n_p of the coefficients of degree
    0..p along an input. They are extrapolated as r_q = r_p (p/q)^s from the last ratio r_p of
    the upper envelope of the upper half of the degrees (s: :func:`_decay`'s steepening) over
    :data:`TAIL_DEGREES` degrees; 0 where the grid holds the response exactly, the decay
    cannot be told or the top norm does not fall.
    """
    decay = _decay(norms)
    if _resolved(norms) is not None or decay is None:
        return 0.0
    top = len(norms) - 1
    upper = np.maximum.accumulate(np.array(norms[max(1, top // 2) :])[::-1])[::-1]
    if not 0.0 < upper[-1] < upper[-2]:
        return 0.0
    degrees = np.arange(top + 1, top + 1 + TAIL_DEGREES)
    logs = 2 * (math.log(upper[-1] / upper[-2]) - decay[1] * np.log(degrees / top))
    return float(np.exp(np.cumsum(logs)).sum())


def _resolved(norms: list[float]) -> float | None:
    """The size of the norms of the top two degrees against the largest from degree 1 where
    they are round-off (a polynomial response of lower degree along the input, held
    exactly), else ``None``."""
    variation, last = max(norms[1:], default=0.0), max(norms[-2:])
    if len(norms) > 2 and variation > 0.0 and last <= BLIND * variation:
        return last / variation
    return None


def _decay(norms: list[float]) -> tuple[float, float] | None:
    """(log ρ, s) of the norms' decay r_q = ρ (p/q)^s, read from the upper half of the degrees
    (p/2 <= q <= p, q >= 1) of the norms above round-off (:data:`BLIND` of the largest: a
    symmetry that zeroes every other degree does not fool it), through their upper envelope
    (max over degrees >= q: nor does a lucky small norm): ρ = exp of the least-squares slope
    of log n_q (at most 1); s, the steepening, in [0, 1] the ratios' least fall per log of the
    degree where each ratio is below the one before (faster than geometric, as an entire
    function's, whose r_q fall like 1/q), else 0 (so from a single ratio, or where a fall
    passes :data:`MAX_STEEPENING`: a lucky small norm at the top). ``None`` where fewer than
    two norms are above round-off."""
    top = len(norms) - 1
    degrees = np.arange(max(1, top // 2), top + 1)
    found = np.array(norms)[degrees]
    kept = found > BLIND * found.max()
    degrees = degrees[kept]
    found = np.maximum.accumulate(found[kept][::-1])[::-1]  # the upper envelope
    if degrees.size < 2:
        return None
    slope = min(0.0, np.polyfit(degrees, np.log(found), 1)[0])
    logs = np.log(found[1:] / found[:-1])  # log r_q at degrees[1:]
    falls = -np.diff(logs) / np.diff(np.log(degrees[1:]))
    entire = (
        falls.size > 0
        and bool(np.all(np.diff(degrees) == 1))
        and falls.min() > 0.0
        and falls.max() <= MAX_STEEPENING
    )
    return slope, min(float(falls.min()), 1.0) if entire else 0.0


def _moments(
    coefficients: NDArray[np.float64], grid: SparseGrid
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(outputs, T) the mean and std of the expansion of ``coefficients`` on ``grid``."""
    expansion = ChaosExpansion(coefficients, grid.multi_index, grid.distributions)
    return expansion.mean(), expansion.std()


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
        if self.max_runs < self._first.size:
            raise ValueError(
                f"method.max_runs: {self.max_runs} runs do not allow one round: level 1 in "
                f"every input takes {self._first.size} runs"
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
        self._history: list[tuple[tuple[int, ...], int, float]] = []
        # The record of what ended the rounds before the tolerance was met.
        self._stopped: tuple[WarningRecord, ...] = ()

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
            fit=self._fit,
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
                self._ended(
                    "nodes-failed",
                    f"{nodes.size} runs, as {int(np.sum(~ok[order]))} node(s) of level {level} "
                    "failed",
                    "a round needs every node: see the failures",
                ),
            )
            return None
        on_grid = np.stack([y[order] for y in values.values()], axis=1)
        finite = np.isfinite(on_grid).all(axis=-1)  # (N, outputs)
        if not finite.all():
            self._stopped = tuple(
                self._ended(
                    "statistic-non-finite",
                    f"{nodes.size} runs, as output {name!r} is not finite at "
                    + self._named(nodes, order[~finite[:, k]]),
                    "its error estimate is undefined, so no round can meet the tolerance",
                    name,
                )
                for k, name in enumerate(values)
                if not finite[:, k].all()
            )
            return None
        estimate = float(box_errors(self._grid, on_grid).max())
        self._history.append((self._orders(self._grid), nodes.size, estimate))
        if estimate < self.tolerance:
            return None
        last = [
            rule.name
            for rule in self.rules
            if rule.max_level is not None and level >= rule.max_level
        ]
        grid = None if last else self._level(level + 1)
        if grid is None or max(self._orders(grid)) > MAX_ORDER:
            limit = (
                f"level {level} is the last of rule {last[0]}"
                if last
                else f"the next level's order {max(self._orders(grid))} passes {MAX_ORDER}, the "
                "highest order auto tries (pcmb.designs.refine.MAX_ORDER)"
            )
            self._stopped = (
                self._ended("order-budget", f"{nodes.size} runs, as {limit}", self._top_advice()),
            )
            return None
        if grid.size > self.max_runs:
            fell = self._fell()
            advice = (
                f"raise method.max_runs: {fell}: the response converges with order"
                if fell
                else "raise method.max_runs, or follow the diagnostics' remedy (order alone may "
                "not converge for a steep, discontinuous or chaotic response)"
            )
            self._stopped = (
                self._ended(
                    "order-budget",
                    f"{nodes.size} of {self.max_runs} runs (method.max_runs), as level {level + 1} "
                    f"would take {grid.size - nodes.size} more",
                    advice,
                ),
            )
            return None
        return self._adopt(grid)

    def _fell(self) -> str:
        """``the estimate fell from A to B with the last level`` where the last level cut it by
        :data:`CONVERGING` or more (the response converges with order: an analytic one), else
        ""."""
        if len(self._history) < 2:
            return ""
        before, last = self._history[-2][2], self._history[-1][2]
        if last * CONVERGING > before:
            return ""
        return f"the estimate fell from {before:.3g} to {last:.3g} with the last level"

    def _top_advice(self) -> str:
        """What to do at the highest order: elements or the tolerance for a response that
        converges with order (:meth:`_fell`), else order alone may not converge."""
        if fell := self._fell():
            return (
                f"{fell}: the response converges with order, but not within the highest; split "
                "it into elements (method.elements: auto) or loosen diagnostics.tolerance"
            )
        return (
            "more runs would not help: order alone may not converge (a steep, discontinuous or "
            "chaotic response), follow the diagnostics' remedy"
        )

    def _named(self, nodes: NodeSet, rows: NDArray[np.intp], shown: int = 5) -> str:
        """``node 3 (a=0.5, b=2), ...``: the first ``shown`` of ``nodes``' ``rows``."""
        named = [
            NodeFailure(
                int(row), dict(zip(self.names, map(float, nodes.params[row]), strict=True)), ""
            ).node
            for row in rows[:shown]
        ]
        rest = f" and {rows.size - shown} more" if rows.size > shown else ""
        return ", ".join(named) + rest

    def _ended(
        self, code: str, limit: str, advice: str, output: str | None = None
    ) -> WarningRecord:
        """The record of rounds that ``limit`` ended with the estimate above the tolerance."""
        # The last estimate is of the last round that ran whole: a lower order than the grid
        # recovered when a node of the next round failed.
        reached = "no error estimate yet against"
        if self._history:
            orders, _, estimate = self._history[-1]
            reached = f"the estimated error of order {max(orders)} {estimate:.3g} above"
        message = (
            f"order refinement ended at order {max(self._orders(self._grid))} after {limit}; "
            f"{reached} the tolerance {self.tolerance:g} (diagnostics.tolerance): {advice}"
        )
        return WarningRecord(code, message, output)

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
        return Recovery(
            recovery.expansions,
            _folded(recovery.warnings, self._stopped),
            RefinementReport(refinement),
        )


def _folded(
    found: tuple[WarningRecord, ...], ended: tuple[WarningRecord, ...]
) -> tuple[WarningRecord, ...]:
    """``found`` and the records of what ended the rounds, each of these joined to the record
    of its code and output found already (the statistics' ``statistic-non-finite`` of an
    output that ended them): one record per problem."""
    records = list(found)
    for record in ended:
        keys = [(w.code, w.output) for w in records]
        if (record.code, record.output) in keys:
            i = keys.index((record.code, record.output))
            records[i] = replace(records[i], message=f"{records[i].message}; {record.message}")
        else:
            records.append(record)
    return tuple(records)


@dataclass(frozen=True)
class RefinementReport(RecordReport):
    """The rounds of ``order: auto`` (:class:`~pcmb.result.Refinement`), stored as
    ``/refinement/orders`` (R, n), ``runs`` and ``indicator`` (R,)."""

    key: ClassVar[str] = "refinement"
    GROUP: ClassVar[str] = "refinement"
    RECORD: ClassVar[type] = Refinement
    LAYOUT: ClassVar[dict[str, Placement]] = {
        "orders": (None, "input"),
        "runs": (),
        "indicator": (),
    }

    refinement: Refinement

    #: The estimate fell to 0.15 of the true error on smooth responses (docs/methods.md).
    UNDERSTATES: ClassVar[float] = 1.0 / 0.15

    def statistics_error(self, result: StudyResult, output: str) -> float | None:
        """The last round's estimated error, the same for every output (``None`` before any
        round)."""
        last = self.refinement.indicator[-1:]
        return float(last[0]) if last.size and np.isfinite(last[0]) else None

    def summary(self, result: StudyResult) -> list[tuple[str, str]]:
        """Per round: the order and its indicator."""
        rounds = ", ".join(
            f"{int(orders.max())}: {error:.2g}"
            for orders, error in zip(self.refinement.orders, self.refinement.indicator, strict=True)
        )
        return [("refined", f"order: indicator per round {rounds}")]
