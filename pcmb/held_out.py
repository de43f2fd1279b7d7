"""A study's held-out runs: how many it makes, where they go (placed to extend the design's
nodes, or drawn), and what they found; the check itself is :mod:`pcmb.analysis.diagnostics`'s
(``docs/diagnostics.md``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from pcmb.analysis.diagnostics import (
    ELEMENT_POINTS,
    FIRST_BATCH,
    HELD_OUT_SEED,
    HeldOut,
    element_importance,
    held_out_budget,
    held_out_draws,
    held_out_line,
    held_out_placed,
    held_out_placed_elements,
    held_out_unit,
    tail_input,
    widened_inputs,
)
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet
from pcmb.designs import NodeDesign
from pcmb.result import NodeFailure, Status, WarningRecord

if TYPE_CHECKING:
    from pcmb.analysis.diagnostics.decay import Expansion
    from pcmb.run.executor import RunResult

__all__ = ["HELD_OUT_RUN", "TAIL_FAILURE_SHARE", "TAIL_SIGMAS", "HeldOutDraws", "HeldOutPlan"]

#: What messages call a held-out run (numbered among those runs, not the design's nodes).
HELD_OUT_RUN = "held-out run"

#: How far out (in standard deviations) a normal input's tail starts, where a model may rightly
#: refuse its input (0.27 % of its mass lies beyond): a held-out run is a tail draw only beyond
#: both this and the design's nodes (:attr:`HeldOutDraws.beyond`).
TAIL_SIGMAS = 3.0

#: The largest share of a check's runs that may fail in the tails without stopping a study: with
#: more, the check cannot stand on the rest.
TAIL_FAILURE_SHARE = 0.5

#: The grids of one input whose held-out runs are placed (:meth:`HeldOutPlan.placed`).
_PLACED_GRIDS = frozenset(
    {"tensor-gauss", "tensor-nested", "smolyak", "adaptive", "adaptive tensor", "element-gauss"}
)


@dataclasses.dataclass(frozen=True)
class HeldOutPlan:
    """The held-out runs that check the expansions of a study's ``design`` of the germ
    ``inputs``: ``validation`` of them (``method.validation``; ``None``: as many as the
    verdict needs, within the budget), drawn from ``seed`` (``method.seed``)."""

    design: NodeDesign
    inputs: Mapping[str, Distribution]
    seed: int
    validation: int | None

    def runs(self, design_runs: int) -> tuple[int, int]:
        """(first batch, most in all) of the held-out runs that check an expansion of
        ``design_runs`` runs: ``validation`` both when it is set, else a first batch of at
        most ``FIRST_BATCH`` and at most :func:`~pcmb.analysis.diagnostics.held_out_budget`
        in all, the rest drawn only where the verdict is undecided; placed runs
        (:meth:`placed`) all at once, as half of them can call a wrong result reliable (the
        double well at order 7 with 4)."""
        most = self._most(design_runs)
        if self.validation is not None or self.placed():
            return most, most
        return min(FIRST_BATCH, most), most

    def placed(self) -> bool:
        """Whether the held-out runs are placed to extend the design's nodes
        (:func:`~pcmb.analysis.diagnostics.held_out_placed`) rather than drawn: a grid of one
        input (tensor, ``order: auto``'s, sparse, adaptive or multi-element, unless its
        elements cannot hold the check's runs: ``ELEMENT_POINTS``), where a random sample
        wastes the few runs."""
        grid = self.design.record().grid
        if len(self.inputs) != 1 or grid not in _PLACED_GRIDS:
            return False
        if grid != "element-gauss":
            return True
        own = np.bincount(self.design.node_elements[self.design.node_elements >= 0])
        return self._most(self.design.node_elements.size) <= np.sum(ELEMENT_POINTS - own)

    def after_fit(self) -> bool:
        """Whether where the held-out runs go waits for the expansions (:meth:`line_input`): a
        tensor Gauss grid of several inputs, some of them normal."""
        normal = widened_inputs(tuple(self.inputs.values()))
        return self.design.record().grid == "tensor-gauss" and normal.size > 1 and normal.any()

    def line_input(self, expansions: Mapping[str, Expansion]) -> int | None:
        """The input along which the first batch of held-out runs is placed, and no second
        (:func:`~pcmb.analysis.diagnostics.held_out_line`), where the tails of the fitted
        ``expansions`` lie along one normal input
        (:func:`~pcmb.analysis.diagnostics.tail_input`); ``None``: drawn."""
        if not self.after_fit():
            return None
        return tail_input(expansions.values())

    def _first_batch(self, design_runs: int) -> NDArray[np.float64]:
        """The unit-cube points of the first batch of draws, whose empty slices the second
        fills (:func:`~pcmb.analysis.diagnostics.held_out_unit`)."""
        first, _ = self.runs(design_runs)
        return held_out_unit(first, len(self.inputs), self.seed + HELD_OUT_SEED)

    def _most(self, design_runs: int) -> int:
        """The most held-out runs of the check: ``validation``, else the budget."""
        if self.validation is not None:
            return self.validation
        return held_out_budget(design_runs)

    def draws(
        self,
        count: int,
        design: NDArray[np.float64],
        values: Mapping[str, NDArray[np.float64]] | None = None,
        batch: int = 0,
        axis: int | None = None,
    ) -> HeldOutDraws:
        """Where the ``count`` held-out runs of batch ``batch`` go (seed ``seed + 7919 +
        batch``), placed to extend the design's nodes ``design`` (germ points) where
        :meth:`placed` (per element of a multi-element design, where its node ``values`` say
        it may err most) or along input ``axis`` (:meth:`line_input`), else drawn; with the
        runs beyond the design's nodes and ``TAIL_SIGMAS`` in a normal input marked
        (:attr:`HeldOutDraws.beyond`)."""
        seed = self.seed + HELD_OUT_SEED + batch
        placed = self.placed() or axis is not None
        normal = widened_inputs(tuple(self.inputs.values()))
        # Without design runs (an intrusive solve) no range is known: no run is a tail draw.
        low, high = (design.min(axis=0), design.max(axis=0)) if design.size else (-np.inf, np.inf)
        partition = getattr(self.design, "partition", None)
        if placed and partition is not None:
            # Each element's own nodes (not those of the elements split on the way).
            where = self.design.node_elements
            own = where >= 0
            design, values = design[own], {name: y[own] for name, y in (values or {}).items()}
            importance = element_importance(partition, design, where[own], values)
            draws, weights = held_out_placed_elements(
                partition, design, where[own], importance, count
            )
        elif axis is not None:
            # Leja points extending the nodes along the input that carries the tails.
            draws, weights = held_out_line(tuple(self.inputs.values()), design, axis, count)
        elif placed:
            # Leja points extending the nodes: with them, a far richer interpolant.
            draws, weights = held_out_placed(next(iter(self.inputs.values())), design, count)
        else:
            # A Latin hypercube, normal inputs widened into their tails (weighted back): each
            # input's range is met evenly, which steadies the estimated errors of the
            # statistics against a few runs missing where the error sits.
            # A later batch completes the first's hypercube: its runs and the first's
            # stratify every input as one, their mean steadier (two apart left slices empty
            # and doubled others). Not with a widened input: the weights' products do not
            # stratify, and there it cost timely flags without saving a miss.
            before = None if batch == 0 or normal.any() else self._first_batch(design.shape[0])
            draws, weights = held_out_draws(tuple(self.inputs.values()), count, seed, before)
        low, high = np.minimum(low, -TAIL_SIGMAS), np.maximum(high, TAIL_SIGMAS)
        beyond = ((draws.nodes < low) | (draws.nodes > high)) & normal
        return HeldOutDraws(seed, draws, weights, placed, tuple(self.inputs), beyond)


@dataclasses.dataclass(frozen=True)
class HeldOutDraws:
    """Where a batch of held-out runs goes: its ``seed``, its ``nodes`` and their ``weights``,
    ``placed`` or drawn (:meth:`HeldOutPlan.draws`); ``beyond`` (K, n): where a run's germ
    lies outside the design's nodes and ±``TAIL_SIGMAS`` in a normal one of the germ
    ``inputs``, a tail the check explores (drawn widened, or placed) and the model need not
    stand (``docs/diagnostics.md``)."""

    seed: int
    nodes: NodeSet
    weights: NDArray[np.float64]
    placed: bool
    inputs: tuple[str, ...]
    beyond: NDArray[np.bool_]

    @property
    def tails(self) -> NDArray[np.bool_]:
        """(K,) the tail draws: the runs whose failure may not stop a study (``Study`` judges
        whether more than ``TAIL_FAILURE_SHARE`` of the check's runs fail there)."""
        return self.beyond.any(axis=1)

    def checked(self, found: RunResult) -> tuple[HeldOut, tuple[WarningRecord, ...]]:
        """The held-out runs made (``found``), and ``nodes-failed`` records naming those that
        failed (left out of the check): the tail draws' (:attr:`tails`), and the others'
        (``on_failure: regress``)."""
        ok = found.status == Status.OK
        held_out = HeldOut(
            self.seed,
            self.nodes.nodes,
            self.nodes.params,
            found.values,
            ok,
            self.weights,
            self.placed,
        )
        tail = self.tails
        tails = [f for f in found.failures if tail[f.index]]
        others = [f for f in found.failures if not tail[f.index]]
        records = []
        if tails:
            beyond = np.any([self.beyond[f.index] for f in tails], axis=0)
            names = " and ".join(np.asarray(self.inputs)[beyond])
            where = f" in the tails of {names} beyond the design's nodes and ±{TAIL_SIGMAS:g} σ"
            records.append(_failed(tails, self.nodes.size, where, ""))
        if others:
            records.append(_failed(others, self.nodes.size, "", " (on_failure: regress)"))
        return held_out, tuple(records)


def _failed(failures: list[NodeFailure], total: int, where: str, why: str) -> WarningRecord:
    """The ``nodes-failed`` record of the held-out runs ``failures`` (of ``total``), failed
    ``where`` and left out ``why``."""
    return WarningRecord(
        "nodes-failed",
        f"{len(failures)} of {total} {HELD_OUT_RUN}(s) failed{where} and were left out of the "
        f"check{why}: " + "; ".join(map(str, failures)),
    )
