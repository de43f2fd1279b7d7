"""Anisotropic tensor refinement (``method: {kind: adaptive, basis: tensor}``).

The driver of :mod:`pcmb.designs.adaptive`, kept to tensor grids: the index set is always a
box, levels 0..L_k in input k, on the same nested rules. It starts at level 1 in every input
(3^n runs on Gauss–Patterson or Genz–Keister rules). After each round, d_k is the change of
the mean and std (relative to the output's largest std) between the box and the box one level
lower in input k alone: the error of that lower box in input k. The std's error is quadratic
in the coefficients left out, so the error left in input k is d_k ρ_k^(2 Δp_k), with Δp_k the
degrees the last level of k added and ρ_k the decay per degree of the coefficients along k at
the box's top degrees (:func:`_decay`; 1, careful, where it cannot be told); the estimated
error is the largest over the inputs. While it exceeds the tolerance, the input with the
largest estimated error is raised by one level — one input direction at a time — within the
budget of runs. The nested rules reuse every run; the result is the tensor projection on the
box reached.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet
from pcmb.chaos.sparse import SparseGrid, box_index_set, find_rows
from pcmb.designs.adaptive import BLIND, AdaptiveCollocation
from pcmb.designs.base import MethodSettings
from pcmb.result import Design

__all__ = ["AnisotropicTensor"]


class AnisotropicTensor(AdaptiveCollocation):
    """``method: {kind: adaptive, basis: tensor, tolerance, max_runs, rule}``: a tensor grid
    of nested rules raised one input at a time where the estimated error is largest (see the
    module)."""

    _FIRST = "the tensor grid of level 1 in every input"

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        super().__init__(inputs, dataclasses.replace(settings, basis=None))

    def _first_indices(self) -> NDArray[np.int64]:
        return box_index_set((1,) * len(self.distributions))

    def _reset(self) -> None:
        super()._reset()
        self._levels = (1,) * len(self.distributions)
        self._refined = set(self._index)
        #: Per input k, d_k and the decay per degree of the coefficients along it.
        self._input_changes = np.ones(len(self.distributions))
        self._rates = np.ones(len(self.distributions))

    def record(self) -> Design:
        return dataclasses.replace(super().record(), basis="tensor", grid="adaptive tensor")

    def _active(self) -> NDArray[np.bool_]:
        """The indices on a top face of the box (what the last level of an input added)."""
        index = np.array(self._index)
        return np.any(index == np.array(self._levels), axis=1)

    def _measure(self, values: NDArray[np.float64]) -> None:
        """The adaptive driver's indicators, and per input the change d_k its top level
        makes."""
        super()._measure(values)
        mean, std = self._statistics(self._grid, values)
        spread = std.max(axis=-1)
        for k in range(len(self._levels)):
            lower = tuple(level - (j == k) for j, level in enumerate(self._levels))
            box = SparseGrid(self.distributions, box_index_set(lower), self.rules)
            low_mean, low_std = self._statistics(
                box, values[find_rows(self._grid.node_ids, box.node_ids)]
            )
            change = np.maximum(np.abs(mean - low_mean), np.abs(std - low_std)).max(axis=-1)
            relative = np.divide(change, spread, out=np.zeros_like(change), where=spread > 0)
            self._input_changes[k] = relative.max()
        coefficients = self._grid.project(values)
        degree = self._grid.multi_index
        self._rates = np.array(
            [
                _decay(
                    [
                        float(np.sqrt(np.sum(coefficients[degree[:, k] == p] ** 2, axis=0)).max())
                        for p in range(int(degree[:, k].max()) + 1)
                    ]
                )
                for k in range(len(self._levels))
            ]
        )

    def _errors(self) -> NDArray[np.float64]:
        """(n,) the estimated error left in each input (see the module)."""
        steps = [
            rule.projection_degree(top) - rule.projection_degree(top - 1)
            for rule, top in zip(self.rules, self._levels, strict=True)
        ]
        return self._input_changes * self._rates ** (2 * np.array(steps))

    def _estimate(self) -> float:
        return float(self._errors().max())

    def more(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The nodes of the next input's level while the estimated error exceeds the
        tolerance and the budget allows, else ``None``."""
        if not self._measure_round(nodes, values, ok) or self._estimate() <= self.tolerance:
            return None
        for k in np.argsort(-self._errors(), kind="stable"):
            rule = self.rules[k]
            if rule.max_level is not None and self._levels[k] >= rule.max_level:
                continue
            levels = tuple(top + (j == k) for j, top in enumerate(self._levels))
            box = box_index_set(levels)
            if SparseGrid(self.distributions, box, self.rules).size > self.max_runs:
                self._stopped = (
                    f"raising {self.names[k]} would pass method.max_runs: raise "
                    "method.max_runs, or the tolerance"
                )
                return None
            present = set(self._index)
            added = [tuple(row) for row in box.tolist() if tuple(row) not in present]
            self._levels = levels
            self._refined.update(added)
            return self._grow(added)
        self._stopped = "every input is at its rule's last level: use rule leja"
        return None


def _decay(norms: list[float]) -> float:
    """The decay per degree of the coefficients along an input, from the norms of those of
    degree 0, 1, ..., p in it: the largest of n_p / n_(p-1), √(n_p / n_(p-2)) and
    √(n_(p-1) / n_(p-3)) (two degrees apart where a symmetry zeroes every other degree) over
    degrees >= 1 whose norms are both above round-off (:data:`BLIND` of the larger), at most
    1; 1 when none are (the decay cannot be told)."""
    top = len(norms) - 1
    rates = []
    for high, low in ((top, top - 1), (top, top - 2), (top - 1, top - 3)):
        if low >= 1 and min(norms[high], norms[low]) > BLIND * max(norms[high], norms[low]):
            rates.append((norms[high] / norms[low]) ** (1 / (high - low)))
    return min(1.0, max(rates, default=1.0))
