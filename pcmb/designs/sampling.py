"""Sampling designs (Monte Carlo, Latin hypercube, Sobol'), optionally fitted by least squares."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, random_nodes
from pcmb.config.types import OrderSpec, PositiveInt
from pcmb.designs.base import (
    MethodSection,
    MethodSettings,
    Recovery,
    least_squares_recovery,
    missing_keys,
    order_words,
    refuse,
    statistics_warnings,
)
from pcmb.result import Design, WarningRecord

__all__ = ["Sampling", "SamplingSettings", "monte_carlo"]

FITS = ("none", "regression")


def monte_carlo(samples: int | list[int], seed: int) -> dict[str, Any]:
    """The ``method:`` keys of plain Monte Carlo of ``samples`` runs (a list: one setting of a
    sweep each), the comparison every other method can be held against."""
    return {"kind": "montecarlo", "samples": samples, "seed": seed}


class SamplingSettings(MethodSection):
    """``method: {kind: montecarlo | lhs | sobol, samples, seed, fit, order}``."""

    kind: Literal["montecarlo", "lhs", "sobol"] = Field(
        description="how nodes are made (a registered design)"
    )
    samples: PositiveInt | None = Field(default=None, description="runs of a sampling method")
    fit: Literal[FITS] = Field(
        default="none", description="regression: least-squares chaos fit on sampled nodes"
    )
    order: OrderSpec | None = Field(
        default=None, description="total order of fit: regression (int or input -> int)"
    )

    @property
    def size_key(self) -> str:
        return "samples"

    cost_key = size_key  # a sweep raises what sets the size


class Sampling:
    """``method: {kind: montecarlo | lhs | sobol, samples, seed, fit, order}``.

    Statistics are sample statistics; ``fit: regression`` adds a least-squares chaos fit of
    total order ``order`` (the largest stable one).
    """

    Settings = SamplingSettings

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        problems = missing_keys(f"kind {settings.kind}", samples=settings.samples)
        if settings.fit == "regression":
            problems += missing_keys("fit regression", order=settings.orders)
        refuse(problems)
        if settings.samples < 2:
            raise ValueError(
                f"method.samples: {settings.kind} needs at least 2 samples, got {settings.samples}"
            )
        self.names, self.distributions = tuple(inputs), tuple(inputs.values())
        self.kind, self.samples, self.seed = settings.kind, settings.samples, settings.seed
        self.fit = settings.fit
        self.orders = settings.orders if self.fit == "regression" else None

    @property
    def runs(self) -> int:
        return self.samples

    def nodes(self) -> NodeSet:
        return random_nodes(self.distributions, self.samples, self.kind, self.seed)

    def weights(self, nodes: NodeSet) -> None:
        return None

    def record(self) -> Design:
        return Design(
            kind=self.kind,
            grid="random",
            basis="total" if self.orders is not None else None,
            orders=self.orders,
            samples=self.samples,
            seed=self.seed,
            fit=self.fit,
            label=self.kind
            if self.orders is None
            else f"{self.kind} + chaos fit, {order_words(self.orders, 'total')}",
        )

    def recover(
        self,
        nodes: NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        warnings: tuple[WarningRecord, ...] = ()
        if self.kind == "sobol" and self.samples & (self.samples - 1):
            warnings = (
                WarningRecord(
                    "sobol-balance",
                    f"{self.samples} Sobol' points is not a power of two, so the points lose "
                    "their balance properties (use 2^m samples)",
                ),
            )
        if self.orders is None:
            return Recovery({}, warnings + statistics_warnings({}, values, ok, times))
        recovery = least_squares_recovery(
            self.distributions,
            self.names,
            nodes.nodes[ok],
            {name: y[ok] for name, y in values.items()},
            max(self.orders),
        )
        found = statistics_warnings(recovery.expansions, values, ok, times)
        return Recovery(recovery.expansions, warnings + recovery.warnings + found)
