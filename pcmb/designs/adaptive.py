"""Dimension-adaptive generalized sparse grids (Gerstner & Griebel, Computing 71, 2003).

The index set grows from the level-0 index by forward neighbours, where the runs show that
it pays: each index i carries an error indicator g_i, the largest norm over outputs and
times of the coefficients its tensor difference Δ_i adds (:meth:`SparseGrid.surplus`),
relative to the output's largest std over time. The indices not refined yet are the active
ones. Each round refines the active indices with the largest indicators — the fewest that
hold :data:`BULK` of the active indicators' sum (bulk marking, so a round has several indices'
nodes to run in parallel) — by adding their admissible forward neighbours (those whose
backward neighbours are all refined), until the estimate meets the tolerance or the next
refinement would pass the budget of runs.

The estimate is of what ``tolerance`` names: the error of the mean and std relative to the
output's largest std. The surpluses bound the surrogate's L2 error, 10^2–10^5 times the
statistics' on smooth functions, so they only mark. After round k, d_k is the largest change,
over outputs and times, of the mean and std that the active indices make (the whole grid
against the grid of the refined indices, whose nodes it holds), relative to the largest std:
the error of the coarser grid. The estimate is the changes to come, a geometric tail: with ρ
the reduction per round of the largest of the last :data:`GUARDED` changes, measured over
:data:`GUARDED` rounds, g_k the largest of the last three changes each carried to round k by ρ
per round of its age (a lucky small change is not believed, a steady fall is; on fewer
inputs than :data:`GUARDED`, one round per input, as a round refines every direction there
is), and the whole grid about :data:`ROUNDS_AHEAD` rounds ahead of the refined one, it is
g_k ρ² / (1 - ρ) (:func:`estimated_error`; while a change :data:`FOUND` times the one before it
is among the last four, a part of the response just found, ρ is at least :data:`AFTER_FOUND`).
Chosen once on the stopping rounds of OTL circuit, Piston, Wing
weight, lognormal6, exp8 and genz_oscillatory together (``scripts/calibrate_adaptive.py``,
``docs/methods.md``: there the estimate is within 10x of the true error in 29 of 30 cases,
OTL at 1e-2 11x careful) and checked on functions it was not chosen on. The extrapolation
assumes a smooth response: where an input's axis surpluses fall like a power of the degree no
faster than a kink's, and so do the changes of the mean they make (a jump or a kink; on an
analytic response near a singularity these fall geometrically first), an ``adaptive-nonsmooth``
warning names it, and the estimate is the largest of the last three changes alone. The estimate
is at least the error no refinement can lower, beyond a rule's last level; the rounds end once
the error refining can lower is below it, and where it exceeds the tolerance, an
``adaptive-budget`` warning names the input. Each round's figures are kept as an
:class:`AdaptiveRound` (:attr:`AdaptiveCollocation.rounds`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pcmb.chaos.expansion import ChaosExpansion, root_sum_of_squares
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nested import RULES
from pcmb.chaos.nodes import NodeSet
from pcmb.chaos.sparse import SparseGrid, find_rows
from pcmb.config.types import PositiveInt, PositiveReal
from pcmb.designs.base import MethodSection, MethodSettings, Recovery
from pcmb.designs.smolyak import GrowingGrid, nested_rules
from pcmb.result import AdaptiveFit, Design, Placement, RecordReport, StudyResult, WarningRecord

__all__ = [
    "AdaptiveCollocation",
    "AdaptiveReport",
    "AdaptiveRound",
    "AdaptiveSettings",
    "estimated_error",
]

#: Share of the refinable indicators' sum a round refines (bulk marking).
BULK = 0.5
#: Indicator below which a surplus is zero to round-off (relative to the std).
BLIND = 1e-12
#: Indicator below which a surplus is too near round-off to tell how it decays.
ROUND_OFF = 1e-10
#: Steepest algebraic decay p^-a of the axis surpluses that a kink or jump gives: the
#: surpluses' norm falls like p^-1/2 across a jump, p^-3/2 across a kink (the G-function's
#: measured 1.45); an analytic response not yet in its geometric regime may also fall steadily
#: over three levels, but steeper (Piston p^-3.9, Wing weight p^-6 and steeper).
NONSMOOTH_DECAY = 2.5
#: Rounds the whole grid is ahead of the grid of its refined indices, whose difference the
#: estimate extrapolates: measured (``scripts/calibrate_adaptive.py``), the true error of the
#: whole grid is about the changes to come from d_k ρ² on the smooth functions there.
ROUNDS_AHEAD = 2
#: Rounds whose largest change the estimate starts from, and over which it measures the
#: reduction per round: the changes zig-zag as bulk marking moves between directions (the
#: median of three believed two small ones in a row: Piston at 1e-6, 28x over-confident).
GUARDED = 3
#: The slowest reduction per round the estimate's geometric tail assumes: a guarded change
#: that does not fall counts 0.9² / (1 - 0.9) = 8.1 times.
SLOWEST = 0.9
#: A change this many times the one before it, among the last :data:`GUARDED` + 1: a part of
#: the response the grid had not reached (a probe's find, or an interaction behind blind
#: indices), whose decay the rounds before it cannot tell.
FOUND = 100.0
#: The reduction per round the estimate assumes at least while such a change is among the last
#: :data:`GUARDED` + 1: the error after a find measured 0.012–0.94 of its change
#: (``docs/methods.md``), and ρ² / (1 - ρ) = 1/12 lies within 10x of each.
AFTER_FOUND = 0.25
#: How far a predicted surplus must exceed the tolerance before a blind index is refined for it:
#: surpluses run 10²–10⁵ times the statistics' error on smooth functions.
SURPLUS_MARGIN = 100.0
#: ``method.max_runs`` when not given.
DEFAULT_MAX_RUNS = 1000
#: What to do where an input's rule has no further level (the sparse and tensor grids').
LAST_LEVEL_REMEDY = "use rule clenshaw-curtis or leja, or a larger tolerance"


class AdaptiveSettings(MethodSection):
    """``method: {kind: adaptive, tolerance, max_runs, rule, basis}``."""

    kind: Literal["adaptive"] = Field(description="how nodes are made (a registered design)")
    tolerance: PositiveReal | None = Field(
        default=None, description="refine until the estimated error meets it"
    )
    max_runs: PositiveInt | None = Field(
        default=None, description="most runs in all (default 1000)"
    )
    rule: Literal[RULES] = Field(default="auto", description="nested 1-D rule of every input")
    basis: Literal["tensor"] | None = Field(
        default=None,
        description="tensor: raise a tensor grid one input at a time (default: a sparse grid)",
    )

    @property
    def size_key(self) -> str:
        return self.budget_key

    @property
    def cost_key(self) -> str:
        return "tolerance"


@dataclass(frozen=True)
class AdaptiveRound:
    """What one round of :class:`AdaptiveCollocation` measured (see the module); errors are
    relative to the output's largest std.

    Attributes
    ----------
    runs:
        The grid's runs after the round.
    change:
        d_k, the largest change of the mean and std the active indices make.
    left:
        The error beyond the rules' last levels, which no refinement can lower.
    left_in:
        The inputs at their rule's last level that ``left`` is in.
    nonsmooth:
        The inputs whose axis surpluses fall algebraically, each with its exponent a (an
        ``adaptive-nonsmooth`` warning each).
    reducible:
        The estimated error that refining can lower (:func:`estimated_error`).
    estimate:
        The estimated error of the mean and std: the larger of ``reducible`` and ``left``
        (for :class:`~pcmb.designs.anisotropic.AnisotropicTensor`, the largest error left in
        an input instead).
    """

    runs: int
    change: float
    left: float
    left_in: tuple[str, ...]
    nonsmooth: tuple[tuple[str, float], ...]
    reducible: float
    estimate: float


class AdaptiveCollocation(GrowingGrid):
    """``method: {kind: adaptive, tolerance, max_runs, rule}``: a dimension-adaptive sparse grid
    on the nested ``rule`` (``auto``: Gauss–Patterson for uniform inputs, Genz–Keister for
    normal ones, Leja otherwise; one rule per input for all levels, so an input stops at its
    rule's last level), recovered by sparse pseudo-spectral projection.

    The first round runs the level-0 index and its forward neighbours; :meth:`more` then
    refines in rounds (see the module). ``tolerance`` bounds the estimated error of the mean
    and std, relative to each output's largest std; ``max_runs`` (default
    :data:`DEFAULT_MAX_RUNS`) the runs.
    """

    Settings = AdaptiveSettings

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        tolerance, max_runs, rule = settings.tolerance, settings.max_runs, settings.rule
        if tolerance is None:
            raise ValueError("method.tolerance: required key is missing (needed by kind adaptive)")
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        self.rules = nested_rules(inputs, rule)
        self.tolerance = float(tolerance)
        self._first = SparseGrid(self.distributions, self._first_indices(), self.rules)
        self.max_runs = DEFAULT_MAX_RUNS if max_runs is None else int(max_runs)
        if self.max_runs < self._first.size:
            raise ValueError(
                f"method.max_runs: {self.max_runs} runs do not allow one step: the first round "
                f"({self._FIRST}) needs {self._first.size} runs"
            )
        self._reset()

    #: What the first round runs, for messages.
    _FIRST = "the level-0 grid and its first refinement"

    def _first_indices(self) -> NDArray[np.int64]:
        """(K, n) the level multi-indices of the first round: 0 and its forward neighbours."""
        n = len(self.distributions)
        return np.vstack([np.zeros((1, n), dtype=np.int64), np.eye(n, dtype=np.int64)])

    def _reset(self) -> None:
        """The state of the first round: index 0 refined, its forward neighbours active."""
        self._grid = self._first
        self._index = [tuple(row) for row in self._first.index_set.tolist()]
        self._refined = {self._index[0]}
        self._ids = self._first.node_ids
        self._norms: dict[tuple[int, ...], NDArray[np.float64]] = {}
        self._indicators = np.full(len(self._index), np.nan)
        self._mean_changes = np.full(len(self._index), np.nan)
        self._changes: list[float] = []
        self._rounds: list[AdaptiveRound] = []
        self._stopped: str | None = None
        self._at_budget = False  # the rounds ended as the next would pass method.max_runs

    def _stop_at_budget(self, step: str) -> None:
        """End the rounds as ``step`` would pass ``method.max_runs``."""
        self._stopped = (
            f"{step} would pass method.max_runs: raise method.max_runs, or the tolerance"
        )
        self._at_budget = True

    @property
    def rounds(self) -> tuple[AdaptiveRound, ...]:
        """The rounds measured so far, in order (each call of :meth:`more` whose nodes all ran
        adds one)."""
        return tuple(self._rounds)

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
        return Design(
            kind="adaptive",
            grid="adaptive",
            basis="sparse",
            orders=tuple(int(p) for p in self._grid.multi_index.max(axis=0)),
            fit=self._fit,
            rule=", ".join(dict.fromkeys(rule.name for rule in self.rules)),
            samples=self._grid.size,
            tolerance=self.tolerance,
            max_runs=self.max_runs,
            label=f"adaptive sparse grid to {self.tolerance:g}, {self._grid.size} runs",
        )

    # -- the rounds --------------------------------------------------------------------------

    def more(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The nodes of the next refinement while the estimated error exceeds the tolerance and
        the budget allows, else ``None`` (every node must have run: a failed one ends the
        rounds)."""
        if not self._measure_round(nodes, values, ok):
            return None
        while True:
            active = np.flatnonzero(self._active())
            refinable = [k for k in active if self._forward(self._index[k], room=True)]
            # Refining lowers only the reducible error: below the error left beyond the rules'
            # last levels, more runs cannot lower the estimate.
            last = self._rounds[-1]
            converged = last.reducible <= max(self.tolerance, last.left)
            probes: list[tuple[int, ...]] = []
            if converged:
                refinable, probes = self._blind()
                if not refinable and not probes:
                    if last.left > self.tolerance:
                        self._stopped = (
                            f"{' and '.join(last.left_in)} reached the last level of its rule "
                            f"with an error of {last.left:.3g} left, which no refinement can "
                            f"lower: {LAST_LEVEL_REMEDY}"
                        )
                    return None
            elif not refinable:
                self._stopped = (
                    f"the nested rules have no further levels to refine with: {LAST_LEVEL_REMEDY}"
                )
                return None
            added = self._refine(refinable, bulk=not converged)
            probes = [level for level in probes if level not in (added or [])]
            if probes and self._size([*(added or []), *probes]) <= self.max_runs:
                added = [*(added or []), *probes]
            elif probes and not added:  # nothing else to refine: the probes end the rounds
                added = None
            if added is None:
                self._stop_at_budget(
                    "probing blind indices" if converged else "the next refinement"
                )
                return None
            if added:
                return self._grow(added)

    def _measure_round(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> bool:
        """Measure the indicators after a round and record the estimate; ``False`` (with the
        reason kept) when a node failed, as the surpluses need every node."""
        if nodes.size == self._first.size:  # the first round of a (new) run
            self._reset()
        order = self._order(nodes)
        if not ok.all():
            self._stopped = f"{int(np.sum(~ok))} node(s) failed, and the surpluses need all"
            return False
        self._measure(np.stack(list(values.values()), axis=1)[order])
        self._rounds.append(self._round())
        return True

    def _round(self) -> AdaptiveRound:
        """The record of the round just measured (see the module)."""
        left, names = self._left_at_last_levels()
        nonsmooth = tuple(self._nonsmooth())
        reducible = estimated_error(
            self._changes, geometric=not nonsmooth, guarded=min(GUARDED, len(self.distributions))
        )
        return AdaptiveRound(
            runs=self._grid.size,
            change=self._changes[-1],
            left=left,
            left_in=tuple(names),
            nonsmooth=nonsmooth,
            reducible=reducible,
            estimate=max(reducible, left),
        )

    def _measure(self, values: NDArray[np.float64]) -> None:
        """Surplus norms and mean changes of the indices new since the last round, both
        relative to each output's largest std over time on the grid so far (the indicators
        and :attr:`_mean_changes`), and the change of the mean and std the active indices
        make."""
        for level in self._index:
            if level not in self._norms:
                surplus = self._grid.surplus(level, values)  # row 0: degree 0, the mean
                self._norms[level] = np.stack(
                    [root_sum_of_squares(surplus).max(axis=-1), np.abs(surplus[0]).max(axis=-1)]
                )
        mean, std = self._statistics(self._grid, values)
        spread = std.max(axis=-1)
        # A std of 0 while the runs vary (a response even in every input, on rules whose first
        # level projects to degree 1) cannot measure what changed: that counts as 1, as the
        # first round's change of the std does.
        unmeasured = (spread <= 0) & (np.ptp(values, axis=0).max(axis=-1) > 0)
        norms = np.array([self._norms[level] for level in self._index])  # (K, 2, outputs)
        relative = _relative(norms, spread, unmeasured)
        self._indicators, self._mean_changes = relative.max(axis=-1).T
        old = SparseGrid(self.distributions, np.array(self._index)[~self._active()], self.rules)
        old_mean, old_std = self._statistics(
            old, values[find_rows(self._grid.node_ids, old.node_ids)]
        )
        change = np.maximum(np.abs(mean - old_mean), np.abs(std - old_std)).max(axis=-1)
        self._changes.append(float(_relative(change, spread, unmeasured).max()))

    def _statistics(
        self, grid: SparseGrid, values: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(outputs, times) the mean and std of the projection on ``grid``."""
        expansion = ChaosExpansion(grid.project(values), grid.multi_index, self.distributions)
        return expansion.mean(), expansion.std()

    def _blind(self) -> tuple[list[int], list[tuple[int, ...]]]:
        """Active indices whose surplus vanishes (below :data:`BLIND`) while they block a
        forward neighbour of a refined index whose indicator exceeds the tolerance, where that
        hides interactions: an index on an axis (Ishigami's 0.1 x3⁴ sin x1 vanishes on the x3
        axis through the centre, not off it), or one at level 0 in an input on whose centre
        plane the whole function vanishes (every index there is blind, as for the G-function's
        factor |4 x0 - 2|): every interaction with that input hides behind one. And the probes:
        the forward neighbours, in a set of inputs no index has yet, of an index in two or more
        inputs blind on their own axes, whose backward neighbours are all in the set, refined
        or blind (their product, zero on the centre planes, may multiply another input's effect:
        e^x1 x2 x3 vanishes on the planes of (1, 1, 0) and (1, 0, 1)), added alone, one per set
        of inputs (:meth:`_refine` carries a found one on). Any blind index is refined that alone
        blocks a neighbour whose surplus the indices below predict (:meth:`_face_surplus`) at
        :data:`SURPLUS_MARGIN` times the tolerance or more: sin(x0 + x1 x2)'s (1, 1, 2) behind
        the blind (1, 0, 2), its face (0, 1, 2) not blind."""
        position = {level: k for k, level in enumerate(self._index)}
        blind = self._indicators <= BLIND
        levels = np.array(self._index)
        null = [k for k in range(levels.shape[1]) if blind[levels[:, k] == 0].all()]
        seen = {_inputs(level) for level in self._index}
        hidden = self._hidden()
        found, probes = set(), {}
        for level in self._refined:
            if self._indicators[position[level]] <= self.tolerance:
                continue
            for child in self._forward(level, room=True):
                if (
                    len(_inputs(level) & hidden) > 1
                    and _inputs(child) not in seen
                    and all(
                        b in self._refined or (b in position and blind[position[b]])
                        for b in _backward(child)
                    )
                ):
                    probes.setdefault(_inputs(child), child)
                blockers = [
                    (parent, position[parent])
                    for parent in _backward(child)
                    if parent in position
                    and parent not in self._refined
                    and blind[position[parent]]
                ]
                if not blockers:
                    continue
                behind = self._face_surplus(level, child, position) > (
                    SURPLUS_MARGIN * self.tolerance
                )
                found.update(
                    k
                    for parent, k in blockers
                    if behind or len(_inputs(parent)) == 1 or any(parent[j] == 0 for j in null)
                )
        return sorted(found), list(probes.values())

    def _face_surplus(
        self,
        level: tuple[int, ...],
        child: tuple[int, ...],
        position: Mapping[tuple[int, ...], int],
    ) -> float:
        """The surplus of ``child``, a forward neighbour of ``level``, that the indices below
        predict as a product would: the largest over the inputs j of ``level`` of g_level
        g_(child - e_j) / g_(level - e_j), the step from level to child taken at the rate the
        same step had one level lower in j (for j the input child raises, the last step along it
        repeated), where both indices of that lower step have surpluses above :data:`BLIND` (0
        where none has)."""
        g, predicted = self._indicators, 0.0
        for j in _inputs(level):
            face, below = _lowered(child, j), _lowered(level, j)
            if face in position and below in position:
                step, base = g[position[face]], g[position[below]]
                if step > BLIND and base > BLIND:
                    predicted = max(predicted, g[position[level]] * step / base)
        return predicted

    def _active(self) -> NDArray[np.bool_]:
        return np.array([level not in self._refined for level in self._index])

    def _left_at_last_levels(self) -> tuple[float, list[str]]:
        """The error no refinement can lower, and the inputs it is in: the largest change of
        the mean (relative to the std) that an index at its rule's last level in an input
        made there, the error of the level below, which the changes no longer see once that
        index counts as refined."""
        left, names = 0.0, []
        for level, change in zip(self._index, self._mean_changes, strict=True):
            last = [
                name
                for name, rule, at in zip(self.names, self.rules, level, strict=True)
                if at == rule.max_level
            ]
            if last and change > left:
                left, names = float(change), last
        return left, names

    def _nonsmooth(self) -> list[tuple[str, float]]:
        """Inputs whose axis surpluses decay algebraically in the degree (like p^-a, a kink's
        spectrum) rather than geometrically (like e^-cp, an analytic response's), with a at
        most :data:`NONSMOOTH_DECAY`, and so do the changes of the mean they make (or those
        cannot be told): on an analytic response these, a quadrature's error, fall
        geometrically well before the norms do (Borehole's log r, near-singular, has norms
        falling like a kink's to degree 23, its mean changes 1.7e-4 to 4e-8 of the std)."""
        position = {level: k for k, level in enumerate(self._index)}
        found = []
        for k, (name, rule) in enumerate(zip(self.names, self.rules, strict=True)):
            axis = (
                tuple(at * (j == k) for j in range(len(self.names))) for at in itertools.count(1)
            )
            rows = [position[level] for level in itertools.takewhile(position.__contains__, axis)]
            degrees = [rule.projection_degree(at) for at in range(1, len(rows) + 1)]
            norms = _algebraic_decay(degrees, self._indicators[rows])
            if norms is None or norms > NONSMOOTH_DECAY:
                continue
            if _algebraic_decay(degrees, self._mean_changes[rows]) != math.inf:
                found.append((name, norms))
        return found

    def _forward(self, level: tuple[int, ...], room: bool = False) -> list[tuple[int, ...]]:
        """Forward neighbours of ``level`` within the rules' levels and not in the set: all of
        them (``room``), or those whose backward neighbours are all refined."""
        present = set(self._index)
        out = []
        for k, rule in enumerate(self.rules):
            up = (*level[:k], level[k] + 1, *level[k + 1 :])
            if up in present or (rule.max_level is not None and up[k] > rule.max_level):
                continue
            if room or all(b in self._refined for b in _backward(up)):
                out.append(up)
        return out

    def _refine(self, refinable: list[int], bulk: bool) -> list[tuple[int, ...]] | None:
        """Refine the indices marked in bulk (else all), largest indicator first, while the
        runs stay within the budget; the indices added (``None``: the first does not fit)."""
        strength = self._indicators[refinable]
        ranked = [refinable[k] for k in np.argsort(-strength, kind="stable")]
        marked = len(ranked)
        if bulk:
            cumulative = np.cumsum(np.sort(strength)[::-1])
            marked = int(np.searchsorted(cumulative, BULK * strength.sum())) + 1
        added: list[tuple[int, ...]] = []
        for count, k in enumerate(ranked[:marked]):
            level = self._index[k]
            # A probe found something: refine the blind indices it was added over first.
            below = [b for b in _backward(level) if b not in self._refined]
            refined = below or [level, *self._hiding(level)]
            self._refined.update(refined)
            children = list(dict.fromkeys(c for r in refined for c in self._forward(r)))
            children = [c for c in children if c not in added]
            if self._size(added + children) > self.max_runs:
                self._refined.difference_update(refined)
                return added if count else None
            added += children
        return added

    def _size(self, added: list[tuple[int, ...]]) -> int:
        """The runs of the grid with the indices ``added``."""
        return SparseGrid(self.distributions, np.array(self._index + added), self.rules).size

    def _hidden(self) -> set[int]:
        """The inputs blind on their own axes (level-1 axis surplus below :data:`BLIND`)."""
        n = len(self.distributions)
        position = {level: k for k, level in enumerate(self._index)}
        return {k for k in range(n) if self._indicators[position[_axis(k, n)]] <= BLIND}

    def _hiding(self, level: tuple[int, ...]) -> list[tuple[int, ...]]:
        """The blind active indices (below :data:`BLIND`) that alone block a forward neighbour
        of ``level`` in its own inputs that raises an input seen on its axis, where two or more
        of them are blind on their axes: the interaction goes on behind them (e^x1 x2 x3's
        (2, 1, 1) behind (2, 1, 0) and (2, 0, 1), zero on their planes)."""
        hidden = self._hidden()
        if len(_inputs(level) & hidden) < 2:
            return []
        position = {index: k for k, index in enumerate(self._index)}
        hiding: list[tuple[int, ...]] = []
        for child in self._forward(level, room=True):
            raised = next(k for k, (a, b) in enumerate(zip(child, level, strict=True)) if a != b)
            # Only the neighbours that raise an input seen on its own axis: raising a blind
            # input behind blind indices multiplies the runs for nothing new.
            if _inputs(child) != _inputs(level) or raised in hidden:
                continue
            blocking = [b for b in _backward(child) if b != level and b not in self._refined]
            if all(b in position and self._indicators[position[b]] <= BLIND for b in blocking):
                hiding += [b for b in blocking if b not in hiding]
        return hiding

    def _grow(self, added: list[tuple[int, ...]]) -> NodeSet:
        """Add indices to the set; the nodes they bring."""
        self._index += added
        self._indicators = np.append(self._indicators, np.full(len(added), np.nan))
        self._mean_changes = np.append(self._mean_changes, np.full(len(added), np.nan))
        return self._adopt(SparseGrid(self.distributions, np.array(self._index), self.rules))

    # -- recovery ----------------------------------------------------------------------------

    def recover(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        recovery = self._grid_recovery(nodes, values, ok, times)
        fit = AdaptiveFit(
            index_set=np.array(self._index, dtype=np.int64),
            indicators=self._indicators.copy(),
            active=self._active(),
            history=np.array([(r.runs, r.estimate) for r in self._rounds]).reshape(-1, 2),
            orders=self._grid.multi_index.max(axis=0),
        )
        warnings = recovery.warnings + tuple(
            WarningRecord(
                "adaptive-nonsmooth",
                f"the surpluses along {name} fall like degree^-{exponent:.2g} over its levels, "
                "not geometrically: the response is not smooth in it (a kink or jump) or not "
                "resolved yet, and the estimated error, which assumes a smooth, resolved "
                "response, may be far too small",
            )
            for name, exponent in (self._rounds[-1].nonsmooth if self._rounds else ())
        )
        if self._stopped is not None:
            reached = f"{self._rounds[-1].estimate:.3g}" if self._rounds else "unknown"
            # The budget is named only where it ended the rounds.
            limit = f" of {self.max_runs} runs (method.max_runs; " if self._at_budget else " runs ("
            warnings += (
                WarningRecord(
                    "adaptive-budget",
                    f"the refinement ended early, after {self._grid.size}{limit}estimated error "
                    f"{reached}, tolerance {self.tolerance:g}): {self._stopped}",
                ),
            )
        return Recovery(recovery.expansions, warnings, AdaptiveReport(fit))


def estimated_error(changes: list[float], geometric: bool, guarded: int = GUARDED) -> float:
    """The estimated error of the finer grid from the changes of the mean and std each round
    made (relative to the largest std; the last is the finest grid's against its
    predecessor's), where the decay is ``geometric``: the changes to come, a geometric tail
    g_k ρ^ROUNDS_AHEAD / (1 - ρ), with ρ = (G_k / G_{k-GUARDED})^(1/GUARDED) the reduction per
    round of the largest of the last :data:`GUARDED` changes G_k (at most :data:`SLOWEST`),
    and g_k the largest of the last :data:`GUARDED` changes, each carried to round k by ρ per
    round of its age (so one lucky small change is not believed, and a steady fall is), at least
    :data:`AFTER_FOUND` while a change :data:`FOUND` times its predecessor is among the last
    ``guarded`` + 1 (the fall before a find says nothing of the part found). An
    algebraic decay, a kink's, falls too slowly for that tail to be told: G_k alone (as before
    GUARDED + 1 rounds, when ρ cannot be measured yet). ``guarded`` rounds in place of
    :data:`GUARDED` where fewer directions can take turns (one per input)."""
    window = [max(changes[max(0, k - guarded + 1) : k + 1]) for k in range(len(changes))]
    if not geometric or len(window) <= guarded or window[-1 - guarded] <= 0:
        return window[-1]
    rate = min(SLOWEST, (window[-1] / window[-1 - guarded]) ** (1 / guarded))
    if any(
        later > FOUND * earlier for earlier, later in itertools.pairwise(changes[-guarded - 1 :])
    ):
        rate = max(rate, AFTER_FOUND)
    aged = max(change * rate**age for age, change in enumerate(reversed(changes[-guarded:])))
    return aged * rate**ROUNDS_AHEAD / (1 - rate)


def _algebraic_decay(degrees: list[int], sizes: NDArray[np.float64]) -> float | None:
    """The exponent a of sizes falling like degree^-a over their last three above
    :data:`ROUND_OFF`, where that fits steadier than e^-c·degree (``math.inf`` where it does
    not: geometric, or not falling), ``None`` with fewer than three such sizes."""
    points = [(p, g) for p, g in zip(degrees, sizes, strict=True) if g > ROUND_OFF][-3:]
    if len(points) < 3:
        return None
    degree, size = np.log(np.array(points, dtype=float)).T
    algebraic = -np.diff(size) / np.diff(degree)
    geometric = -np.diff(size) / np.diff(np.exp(degree))
    if np.all(algebraic > 0) and np.ptp(np.log(algebraic)) < np.ptp(np.log(geometric)):
        return float(algebraic[-1])
    return math.inf


def _relative(
    sizes: NDArray[np.float64], spread: NDArray[np.float64], unmeasured: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """``sizes`` (..., outputs) relative to each output's largest std ``spread``: 0 where the
    std is 0, but 1 for a nonzero size where the std, ``unmeasured``, cannot measure it."""
    relative = np.divide(sizes, spread, out=np.zeros_like(sizes), where=spread > 0)
    return np.where(unmeasured & (sizes > 0), 1.0, relative)


def _inputs(level: tuple[int, ...]) -> frozenset[int]:
    """The inputs a level multi-index is above level 0 in."""
    return frozenset(k for k, at in enumerate(level) if at > 0)


def _axis(k: int, inputs: int) -> tuple[int, ...]:
    """The level-1 index on input k's axis."""
    return tuple(int(j == k) for j in range(inputs))


def _lowered(level: tuple[int, ...], k: int) -> tuple[int, ...]:
    """``level`` one level lower in input k."""
    return (*level[:k], level[k] - 1, *level[k + 1 :])


def _backward(level: tuple[int, ...]) -> list[tuple[int, ...]]:
    """The backward neighbours of a level multi-index."""
    return [_lowered(level, k) for k, at in enumerate(level) if at > 0]


@dataclass(frozen=True)
class AdaptiveReport(RecordReport):
    """What a dimension-adaptive grid concluded (:class:`~pcmb.result.AdaptiveFit`), stored
    as ``/adaptive/index_set`` (K, n), ``indicators`` and ``active`` (K,), ``history`` (R, 2:
    runs, estimated error) and ``orders`` (n,)."""

    key: ClassVar[str] = "adaptive"
    GROUP: ClassVar[str] = "adaptive"
    RECORD: ClassVar[type] = AdaptiveFit
    LAYOUT: ClassVar[dict[str, Placement]] = {
        "index_set": (None, "input"),
        "indicators": (),
        "active": (),
        "history": (),
        "orders": ("input",),
    }

    adaptive: AdaptiveFit

    #: The estimate fell to 0.14 of the true error on smooth functions (docs/methods.md).
    UNDERSTATES: ClassVar[float] = 1.0 / 0.14

    def statistics_error(self, result: StudyResult, output: str) -> float | None:
        """The last round's estimated error, the same for every output (``None`` before any
        round)."""
        estimate = self.adaptive.estimate
        return estimate if math.isfinite(estimate) else None

    def summary(self, result: StudyResult) -> list[tuple[str, str]]:
        """Per round: runs and estimated error; per input: what it reached."""
        fit = self.adaptive
        rounds = ", ".join(f"{int(runs)}: {error:.2g}" for runs, error in fit.history)
        reached = zip(result.input_names, fit.levels, fit.orders, fit.importance, strict=True)
        return [
            (
                "adaptive",
                f"{fit.index_set.shape[0]} level indices, estimated error {fit.estimate:.3g}; "
                f"runs: estimate per round {rounds}",
            ),
            (
                "inputs",
                ", ".join(f"{n} level {lv} order {p} share {sh:.2g}" for n, lv, p, sh in reached),
            ),
        ]
