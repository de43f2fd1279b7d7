"""Anisotropic tensor refinement (``method: {kind: adaptive, basis: tensor}``).

The driver of :mod:`pcmb.designs.adaptive`, kept to tensor grids: the index set is always a
box, levels 0..L_k in input k, on the same nested rules. It starts at level 1 in every input
(3^n runs on Gauss–Patterson or Genz–Keister rules). After each round the error left in each
input is ``order: auto``'s (:func:`pcmb.designs.refine.box_errors`: the change its last level
makes, scaled by the fall of the coefficients along it from the lower box's degree to the
box's, :func:`pcmb.designs.refine.error_ratio`), and the
estimated error is the largest over the inputs. While it exceeds the tolerance, the input with the
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
from pcmb.chaos.sparse import SparseGrid, box_index_set
from pcmb.designs.adaptive import LAST_LEVEL_REMEDY, AdaptiveCollocation, AdaptiveRound
from pcmb.designs.base import MethodSettings
from pcmb.designs.refine import box_errors
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
        self._errors = np.ones(len(self.distributions))

    def record(self) -> Design:
        return dataclasses.replace(super().record(), basis="tensor", grid="adaptive tensor")

    def _active(self) -> NDArray[np.bool_]:
        """The indices on a top face of the box (what the last level of an input added)."""
        index = np.array(self._index)
        return np.any(index == np.array(self._levels), axis=1)

    def _measure(self, values: NDArray[np.float64]) -> None:
        """The adaptive driver's indicators, and the error left in each input."""
        super()._measure(values)
        self._errors = box_errors(self._grid, values)

    def _round(self) -> AdaptiveRound:
        """The driver's record, with the estimate the largest error left in an input."""
        return dataclasses.replace(super()._round(), estimate=float(self._errors.max()))

    def more(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The nodes of the next input's level while the estimated error exceeds the
        tolerance and the budget allows, else ``None``."""
        if (
            not self._measure_round(nodes, values, ok)
            or self._rounds[-1].estimate <= self.tolerance
        ):
            return None
        # Only an input whose own error passes the tolerance is raised: raising another cannot
        # lower the largest.
        above = [
            k for k in np.argsort(-self._errors, kind="stable") if self._errors[k] > self.tolerance
        ]
        for k in above:
            rule = self.rules[k]
            if rule.max_level is not None and self._levels[k] >= rule.max_level:
                continue
            levels = tuple(top + (j == k) for j, top in enumerate(self._levels))
            box = box_index_set(levels)
            if SparseGrid(self.distributions, box, self.rules).size > self.max_runs:
                self._stop_at_budget(f"raising {self.names[k]}")
                return None
            present = set(self._index)
            added = [tuple(row) for row in box.tolist() if tuple(row) not in present]
            self._levels = levels
            self._refined.update(added)
            return self._grow(added)
        names = " and ".join(self.names[k] for k in above)
        verb = "is" if len(above) == 1 else "are"
        self._stopped = (
            f"{names} {verb} at its rule's last level with its error above the tolerance, "
            f"which raising the other inputs cannot lower: {LAST_LEVEL_REMEDY}"
        )
        return None
