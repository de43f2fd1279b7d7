"""Sampling designs (Monte Carlo, Latin hypercube, Sobol'), optionally fitted by least squares."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, random_nodes
from pcmb.designs.base import (
    MethodSettings,
    Recovery,
    least_squares_recovery,
    statistics_warnings,
)
from pcmb.result import Design, WarningRecord

__all__ = ["Sampling"]

FITS = ("none", "regression")


class Sampling:
    """``method: {kind: montecarlo | lhs | sobol, samples, seed, fit, order}``.

    Statistics are sample statistics; ``fit: regression`` adds a least-squares chaos fit of
    total order ``order`` (the largest stable one).
    """

    def __init__(self, inputs: Mapping[str, Distribution], settings: MethodSettings):
        if settings.samples is None:
            raise ValueError(
                f"method.samples: required key is missing (needed by kind {settings.kind})"
            )
        if settings.samples < 2:
            raise ValueError(
                f"method.samples: {settings.kind} needs at least 2 samples, got {settings.samples}"
            )
        if settings.fit not in FITS:
            raise ValueError(f"method.fit: expected one of {', '.join(FITS)}")
        if settings.fit == "regression" and settings.orders is None:
            raise ValueError("method.order: required key is missing (needed by fit regression)")
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
