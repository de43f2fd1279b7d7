"""Collocation on a tensor grid of Gauss nodes, recovered by Kronecker projection."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pcmb.chaos.basis import total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nested import RULES
from pcmb.chaos.nodes import TensorGrid
from pcmb.chaos.recovery import project_tensor
from pcmb.config.types import Name, NonNegativeInt, OrderSpec, PositiveInt, Real
from pcmb.designs.base import (
    MethodSection,
    MethodSettings,
    Recovery,
    fit_of,
    least_squares_recovery,
    missing_keys,
    order_words,
    refuse,
    statistics_warnings,
)
from pcmb.result import Design, WarningRecord

__all__ = ["CollocationSettings", "TensorCollocation"]

BASES = ("tensor", "total")
#: ``method.grid`` values: the tensor Gauss grid, or a Smolyak sparse grid.
GRIDS = ("tensor", "smolyak")


class CollocationSettings(MethodSection):
    """``method: {kind: collocation, ...}``: a tensor Gauss grid (``order``), a Smolyak grid
    (``grid: smolyak``, ``level``, ``rule``), multi-element collocation (``elements``) or
    order refinement (``order: auto``, within ``max_runs``)."""

    kind: Literal["collocation"] = Field(description="how nodes are made (a registered design)")
    order: OrderSpec | None = Field(
        default=None,
        description="int, a mapping input -> int, or auto: tensor grids of nested rules raised "
        "level by level until diagnostics.tolerance is met",
    )
    basis: Literal[BASES] | None = Field(
        default=None, description="chaos terms: tensor (default) or total degree"
    )
    grid: Literal[GRIDS] = Field(default="tensor", description="tensor Gauss grid or Smolyak")
    level: NonNegativeInt | None = Field(default=None, description="level of a Smolyak grid")
    rule: Literal[RULES] = Field(
        default="auto", description="nested 1-D rule of a Smolyak grid or of order auto"
    )
    elements: Literal["auto"] | dict[Name, list[Real]] | None = Field(
        default=None,
        description="multi-element collocation: input -> split points (physical units), or "
        "auto: elements halved until diagnostics.tolerance is met",
    )
    max_elements: PositiveInt = Field(default=16, description="most elements of elements: auto")
    max_runs: PositiveInt | None = Field(
        default=None, description="order auto: most runs in all (default 1000)"
    )

    @property
    def size_key(self) -> str:
        if self.order == "auto":
            return self.budget_key
        return "level" if self.level is not None else "order"

    cost_key = size_key  # a sweep raises what sets the size


class TensorCollocation:
    """``method: {kind: collocation, order, basis}``: (P_k + 1) Gauss nodes per input.

    ``basis: tensor`` recovers every term of the grid (interpolation); ``basis: total``
    projects onto the terms of total degree <= max P_k inside it. A grid with failed nodes
    is no quadrature rule: its survivors are refitted by least squares, and the record of the
    last recovery says so (``fit: regression``).
    """

    Settings = CollocationSettings

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        refuse(missing_keys("kind collocation", order=settings.orders))
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        self.orders = tuple(settings.orders)
        self.basis = settings.basis or "tensor"
        self._fit = "projection"

    @property
    def runs(self) -> int:
        return math.prod(order + 1 for order in self.orders)

    def nodes(self) -> TensorGrid:
        return TensorGrid(self.distributions, self.orders)

    def weights(self, nodes: TensorGrid) -> NDArray[np.float64]:
        return nodes.weights

    def record(self) -> Design:
        return Design(
            kind="collocation",
            grid="tensor-gauss",
            basis=self.basis,
            orders=self.orders,
            fit=self._fit,
            label=f"chaos {order_words(self.orders, self.basis)}",
        )

    def _index(self, grid: TensorGrid) -> NDArray[np.int64]:
        if self.basis == "tensor":
            return grid.multi_index
        index = total_index_set(len(self.orders), max(self.orders))
        return index[np.all(index <= np.array(self.orders), axis=1)]

    def recover(
        self,
        grid: TensorGrid,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        flat = [name for name, order in zip(self.names, self.orders, strict=True) if order == 0]
        warnings: tuple[WarningRecord, ...] = ()
        self._fit = fit_of(ok)
        if ok.all():
            index = self._index(grid)
            expansions = {
                name: ChaosExpansion(
                    project_tensor(grid, y, index), index, self.distributions, self.names
                )
                for name, y in values.items()
            }
            recovery = Recovery(expansions)
        else:
            recovery = least_squares_recovery(
                self.distributions,
                self.names,
                grid.nodes[ok],
                {name: y[ok] for name, y in values.items()},
                max(self.orders),
                weights=grid.weights[ok],
                caps=self.orders,
            )
            warnings = recovery.warnings
        if flat:
            warnings += (
                WarningRecord(
                    "order-zero",
                    f"input(s) {flat} have order 0: each is held at its single Gauss node and "
                    "contributes no variance",
                ),
            )
        warnings += statistics_warnings(recovery.expansions, values, ok, times)
        return Recovery(recovery.expansions, warnings)
