"""The node-design protocol: make nodes, say how they were made, recover coefficients."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pcmb.chaos.expansion import ChaosExpansion, sample_mean, sample_std
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, TensorGrid
from pcmb.chaos.recovery import fit_largest_stable
from pcmb.config.types import NonNegativeInt, Section
from pcmb.errors import ConfigError, ConfigProblem
from pcmb.result import (
    RECORDED_ONLY,
    Design,
    DesignReport,
    ReportedByDesign,
    ReportFile,
    WarningRecord,
)

__all__ = [
    "RECORDED_ONLY",
    "AdaptiveDesign",
    "IntrusiveDesign",
    "MethodSection",
    "MethodSettings",
    "MomentReport",
    "NodeDesign",
    "Recovery",
    "RefittingDesign",
    "least_squares_recovery",
    "missing_keys",
    "order_words",
    "refuse",
    "statistics_warnings",
]

#: Magnitudes whose squares exceed the largest float.
_SQUARE_LIMIT = float(np.sqrt(np.finfo(float).max))


@dataclass(frozen=True)
class MethodSettings:
    """The ``method:`` settings a design is built from (config keys of the same names), made by
    :meth:`MethodSection.settings` from a validated section.

    ``orders`` is one order per input (germ order), ``"auto"`` for order refinement, ``None``
    when the method has none. :func:`pcmb.designs.design_key` picks the design from ``kind``
    (and, for collocation, ``grid``, ``elements`` and ``orders``); each design reads the fields
    it uses. ``diagnostics_tolerance`` is ``diagnostics.tolerance``, which ``order: auto``
    refines to.
    """

    kind: str
    orders: tuple[int, ...] | str | None = None
    basis: str | None = None
    samples: int | None = None
    seed: int = 0
    fit: str = "none"
    grid: str = "tensor"
    level: int | None = None
    rule: str = "auto"
    elements: Mapping[str, Sequence[float]] | str | None = None
    max_elements: int = 16
    selection: str = "lars"
    sampling: str = "sobol"
    q: float = 1.0
    tolerance: float | None = None
    max_samples: int | None = None
    max_runs: int | None = None
    diagnostics_tolerance: float | None = None


class MethodSection(Section):
    """Base of every ``method:`` section: the keys of one design family, tagged by ``kind``.

    A design class names its section as ``Settings``; the config's ``method:`` union is built
    from the sections of :data:`pcmb.designs.DESIGNS`, so a section holds only its own keys.
    A subclass declares ``kind: Literal[...]`` and says which key sets its number of runs
    (:attr:`size_key`), which one a sweep raises (:attr:`cost_key`) and which one bounds the
    runs of all its rounds (:attr:`budget_key`).
    """

    #: The key that bounds the runs of all rounds of a design that runs in rounds.
    budget_key: ClassVar[str] = "max_runs"

    kind: str  # each section narrows it to its Literal (kept first in listings)
    validation: NonNegativeInt | None = Field(
        default=None,
        description="held-out runs that check a chaos expansion (0: none; default: sized to "
        "the design, at most max(8, a quarter of its runs)): placed to extend a grid of one "
        "input, else drawn at random, in batches while the verdict is undecided",
    )
    seed: NonNegativeInt = Field(
        default=0, description="seed of the design's random nodes and of the held-out runs"
    )

    @property
    def size_key(self) -> str:
        """The key that sets the number of runs (where a design too large is reported)."""
        return "kind"

    @property
    def cost_key(self) -> str | None:
        """The key a default sweep raises (``None``: nothing to raise)."""
        return None

    def settings(
        self,
        orders: tuple[int, ...] | str | None = None,
        diagnostics_tolerance: float | None = None,
    ) -> MethodSettings:
        """The record a design is built from: these keys, with ``orders`` one per germ input
        (or ``"auto"``) and ``diagnostics.tolerance``."""
        data = self.model_dump(exclude={"order", "validation"})
        return MethodSettings(orders=orders, diagnostics_tolerance=diagnostics_tolerance, **data)


@dataclass(frozen=True)
class Recovery(ReportedByDesign):
    """What a design recovered from the runs: expansions per output, warnings and what else
    the design concluded (its :class:`~pcmb.result.DesignReport`: a sparse regression's fits,
    an adaptive grid's index set, the rounds of ``order: auto``, the elements of the nodes, the
    moments of statistical linearization), which the result keeps."""

    expansions: dict[str, ChaosExpansion] = field(default_factory=dict)
    warnings: tuple[WarningRecord, ...] = ()
    report: DesignReport | None = None


@dataclass(frozen=True)
class MomentReport(DesignReport):
    """The mean and std of each output, (2, T), computed without an expansion and without
    the runs at hand (statistical linearization; a streamed study's running moments): they are
    the ``mean`` and ``std`` every output stores, so nothing more is written; read back, for
    the outputs without coefficients, from a file without nodes or whose runs are not read
    (:attr:`~pcmb.result.ReportFile.runs`: more than the memory holds)."""

    key: ClassVar[str] = "moments"

    moments: dict[str, NDArray[np.float64]]

    def write(self, file: ReportFile) -> None:
        """Nothing: the result file stores every output's mean and std."""

    @classmethod
    def read(cls, file: ReportFile) -> MomentReport | None:
        germ = file.shape("nodes/germ")
        if germ is None or (germ[0] and file.runs):
            return None
        moments = {
            name: np.stack([file.read(f"outputs/{name}/mean"), file.read(f"outputs/{name}/std")])
            for name in file.outputs
            if file.shape(f"outputs/{name}/coefficients") is None
        }
        return cls(moments) if moments else None


class NodeDesign(Protocol):
    """How a method makes its nodes and turns runs into coefficients.

    A design is built as ``Design(distributions, settings)`` (``settings`` a
    :class:`MethodSettings`); it raises ``ValueError`` with the offending key for settings it
    cannot use, or a ConfigError naming every problem at once (:func:`refuse`). Register it in
    :data:`pcmb.designs.DESIGNS` under every ``method.kind`` it serves.
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
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        """Expansions of every output from (N, T) values; ``ok`` marks the nodes that ran.

        The warnings include :func:`statistics_warnings` (located in time with ``times``, the
        (T,) grid, when given).

        Raises
        ------
        IllPosedError
            No trustworthy expansion exists for the surviving nodes.
        """
        ...


class AdaptiveDesign(NodeDesign, Protocol):
    """A design that runs in rounds: after each, it may ask for more nodes (sparse regression
    to a tolerance, multi-element refinement, order refinement). ``Study.run`` runs each round
    through the same workers and journals it in its own folder of the journal, so a resumed run
    recomputes the same rounds from the journaled values."""

    def more(
        self,
        nodes: TensorGrid | NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
    ) -> NodeSet | None:
        """The next round's nodes, given every node run so far, or ``None`` when done."""
        ...


class RefittingDesign(NodeDesign, Protocol):
    """A design whose expansions are fitted again, after the held-out check's verdict, over
    its runs and the held-out runs that succeeded (a regression's final fit,
    ``docs/methods.md``). ``Study.run`` calls :meth:`refit` where a design has it; the others
    keep the expansions the check judged."""

    def refit(
        self,
        nodes: TensorGrid | NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        weights: NDArray[np.float64],
        times: NDArray[np.float64] | None = None,
    ) -> Recovery:
        """Expansions of every output from the (N, T) values of the design's runs followed by
        the held-out runs, as :meth:`~NodeDesign.recover` makes them, the rows weighted by
        ``weights`` (N,): 1 for the design's runs, the held-out draws' importance weights, 0
        for a row left out."""
        ...


class IntrusiveDesign(Protocol):
    """A method that solves equations derived from the model instead of running it at nodes
    (stochastic Galerkin, statistical linearization): it has no nodes (``runs`` is 0, ``nodes``
    is empty) and no ``recover``. ``Study.run`` calls :meth:`solve` as one task in a worker
    process, with the model built there, because the equations come from the model's own code
    (its polynomial form, :mod:`pcmb.designs.polynomial_form`); ``pcmb validate`` calls
    :meth:`check` the same way."""

    @property
    def runs(self) -> int: ...

    def nodes(self) -> NodeSet: ...

    def weights(self, nodes: NodeSet) -> None: ...

    def record(self) -> Design: ...

    def check(self, model: object, outputs: Sequence[str] | None) -> list[tuple[str, str]]:
        """``(key, message)`` of what keeps the method from this model and these outputs
        (``None``: all the model's); empty when it can be solved."""
        ...

    def solve(self, model: object, times: NDArray[np.float64], outputs: Sequence[str]) -> Recovery:
        """Expansions (or moments) of the outputs on the (T,) grid.

        Raises
        ------
        ConfigError
            What :meth:`check` finds.
        ModelError
            The integration failed.
        """
        ...


def missing_keys(needed_by: str, **values: object) -> list[tuple[str, str]]:
    """``(key, message)`` of each ``method.<key>`` among ``values`` that is not given (``None``),
    which ``needed_by`` (e.g. ``kind regression``) requires."""
    message = f"required key is missing (needed by {needed_by})"
    return [(f"method.{key}", message) for key, value in values.items() if value is None]


def refuse(problems: Sequence[tuple[str, str]]) -> None:
    """Raise every ``(key, message)`` problem of a design's settings as one ConfigError.

    Raises
    ------
    ConfigError
        When there is any problem.
    """
    if problems:
        raise ConfigError([ConfigProblem(key, message) for key, message in problems])


def order_words(orders: Sequence[int], basis: str | None) -> str:
    """The chaos order in words: ``order 5``, ``orders 3x5`` (tensor), ``total order 4``."""
    if basis != "tensor":
        return f"total order {max(orders)}"
    if len(set(orders)) == 1:
        return f"order {orders[0]}"
    return "orders " + "x".join(map(str, orders))


def fit_of(ok: NDArray[np.bool_]) -> str:
    """The record's ``fit`` of a grid's recovery: ``projection``, or ``regression`` (the least
    squares of :func:`least_squares_recovery`) when a node failed (``ok`` False)."""
    return "projection" if ok.all() else "regression"


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


def statistics_warnings(
    expansions: Mapping[str, ChaosExpansion],
    values: Mapping[str, NDArray[np.float64]],
    ok: NDArray[np.bool_],
    times: NDArray[np.float64] | None = None,
) -> tuple[WarningRecord, ...]:
    """Records of where the statistics of an output are undefined or not finite.

    - ``sobol-undefined`` (one per output with an expansion that does not vary somewhere):
      there its variance is 0 up to round-off, its std exactly 0 and its Sobol' indices NaN.
      It speaks of the expansion, not of the output: held-out runs may vary where the
      design's did not (the verdict's ``chaos-unreliable`` says so).
    - ``statistic-non-finite`` (one per output with a NaN or infinite mean or std): values
      that are not finite among the runs kept, or magnitudes whose statistics exceed the
      floating-point range even when computed with scaling.
    - ``square-overflow`` (one per output with values beyond ~1.3e154, whose squares exceed
      the largest float): its mean, std and Sobol' indices are computed with scaling, but
      quantities in squared units (the variance, power spectra) are inf.

    Parameters
    ----------
    expansions:
        Output name -> expansion (sample statistics for the outputs without one).
    values:
        Output name -> (N, T) runs.
    ok:
        (N,) the runs that count.
    times:
        (T,) the grid, for the records' time ranges; without it the message names the
        time indices instead.
    """
    records = []
    for name, runs in values.items():
        expansion = expansions.get(name)
        kept = np.asarray(runs)[ok]
        if expansion is not None:
            mean, std = expansion.mean(), expansion.std()
        else:
            mean, std = sample_mean(kept), sample_std(kept)
        mean, std = np.atleast_1d(mean), np.atleast_1d(std)
        broken = ~(np.isfinite(mean) & np.isfinite(std))
        if broken.any():
            if not np.isfinite(kept).all():
                cause = "the runs kept hold values that are not finite"
            else:
                top = float(np.max(np.abs(kept)))
                cause = f"values up to {top:.3g} put them beyond the floating-point range"
            where, span = _where(broken, times)
            sobol = "; its Sobol' indices there are NaN" if expansion is not None else ""
            records.append(
                WarningRecord(
                    "statistic-non-finite",
                    f"the mean or std is not finite (NaN or inf) at {where}: {cause}{sobol}",
                    name,
                    span,
                )
            )
        finite = kept[np.isfinite(kept)]
        top = float(np.max(np.abs(finite))) if finite.size else 0.0
        if top > _SQUARE_LIMIT:
            records.append(
                WarningRecord(
                    "square-overflow",
                    f"values up to {top:.3g}: quantities in squared units (the variance, power "
                    "spectra) exceed the floating-point range and are inf; the mean, std and any "
                    "Sobol' indices are computed with scaling",
                    name,
                )
            )
        constant = std == 0
        if expansion is not None and constant.any():
            where, span = _where(constant, times)
            records.append(
                WarningRecord(
                    "sobol-undefined",
                    f"the expansion does not vary (variance 0 up to round-off) at {where}, "
                    "as fitted to the design's runs: its std is 0 and its Sobol' indices are "
                    "undefined there (stored as NaN)",
                    name,
                    span,
                )
            )
    return tuple(records)


def _where(
    mask: NDArray[np.bool_], times: NDArray[np.float64] | None
) -> tuple[str, tuple[float, float] | None]:
    """Words for the points of ``mask`` and, given ``times``, their (first, last) times."""
    hits = np.flatnonzero(mask)
    first, last = int(hits[0]), int(hits[-1])
    count, size = hits.size, mask.size
    if count == size:
        words = f"all {size} times" if size > 1 else "its only time"
    elif count == last - first + 1:
        words = f"{count} consecutive times" if count > 1 else "1 time"
    else:
        words = f"{count} of the {last - first + 1} times in this range"
    if times is None:
        if size == 1:  # a scalar output (a figure of merit)
            return "its value", None
        return f"{words} (time indices {first}..{last})", None
    return words, (float(times[first]), float(times[last]))
