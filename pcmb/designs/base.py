"""The node-design protocol: make nodes, say how they were made, recover coefficients."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, TensorGrid
from pcmb.chaos.recovery import fit_largest_stable
from pcmb.result import Design, WarningRecord

__all__ = ["MethodSettings", "NodeDesign", "Recovery", "least_squares_recovery"]


@dataclass(frozen=True)
class MethodSettings:
    """The ``method:`` settings a design is built from (config keys of the same names).

    ``orders`` is one order per input (germ order), ``None`` when the method has none.
    """

    kind: str
    orders: tuple[int, ...] | None = None
    basis: str = "tensor"
    samples: int | None = None
    seed: int = 0
    fit: str = "none"


@dataclass(frozen=True)
class Recovery:
    """What a design recovered from the runs: expansions per output and warnings."""

    expansions: dict[str, ChaosExpansion] = field(default_factory=dict)
    warnings: tuple[WarningRecord, ...] = ()


class NodeDesign(Protocol):
    """How a method makes its nodes and turns runs into coefficients.

    A design is built as ``Design(distributions, settings)`` (``settings`` a
    :class:`MethodSettings`); it raises ``ValueError`` with the offending key for settings it
    cannot use. Register it in :data:`pcmb.designs.DESIGNS` under every ``method.kind`` it
    serves.
    """

    def nodes(self) -> TensorGrid | NodeSet:
        """The nodes to run: ``.nodes`` (N, n) germ, ``.params`` (N, n) physical values."""
        ...

    @property
    def runs(self) -> int:
        """Number of model runs the design asks for (known before any node is made)."""
        ...

    def weights(self, nodes: TensorGrid | NodeSet) -> NDArray[np.float64] | None:
        """(N,) quadrature weights summing to 1, or ``None`` for random sampling."""
        ...

    def record(self) -> Design:
        """The :class:`~pcmb.result.Design` stored with the result."""
        ...

    def recover(
        self,
        nodes: TensorGrid | NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> Recovery:
        """Expansions of every output from (N, T) values; ``ok`` marks the nodes that ran.

        Raises
        ------
        IllPosedError
            No trustworthy expansion exists for the surviving nodes.
        """
        ...


def least_squares_recovery(
    distributions: Sequence[Distribution],
    names: Sequence[str],
    germ: NDArray[np.float64],
    values: Mapping[str, NDArray[np.float64]],
    max_order: int,
    *,
    weights: NDArray[np.float64] | None = None,
    caps: Sequence[int] | None = None,
) -> Recovery:
    """Least-squares expansions of every output at once (one basis, one factorisation).

    The basis is the largest total-degree set up to ``max_order`` (capped per input by
    ``caps``) that the nodes fit stably; the choice is reported as a warning.

    Raises
    ------
    IllPosedError
        Not even a constant fits.
    """
    dists, names = tuple(distributions), tuple(names)
    stacked = np.stack(list(values.values()), axis=1)
    index, fit = fit_largest_stable(dists, germ, stacked, max_order, weights, orders=caps)
    expansions = {
        name: ChaosExpansion(fit.coefficients[:, k], index, dists, names)
        for k, name in enumerate(values)
    }
    order = int(index.sum(axis=1).max())
    message = (
        f"least-squares chaos of total order {order} ({index.shape[0]} terms, asked "
        f"{max_order}) on {germ.shape[0]} nodes; worst relative leave-one-out error "
        f"{float(np.nanmax(fit.loo_error, initial=0.0)):.3g}"
    )
    return Recovery(expansions, (WarningRecord("least-squares-fit", message),))
