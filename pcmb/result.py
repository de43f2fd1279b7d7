"""What a study produced: the result, node status, the design record, failures and warnings.

Everything here is plain data (numpy and the chaos core); :mod:`pcmb.store` writes and reads it.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from collections.abc import MutableMapping
from dataclasses import asdict, dataclass, field, fields
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, Self

import numpy as np
from numpy.typing import NDArray

from pcmb.axes import OutputAxis
from pcmb.chaos.elements import Partition, PiecewiseExpansion
from pcmb.chaos.expansion import ChaosExpansion, sample_mean, sample_std
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.process import RandomProcess, germ_names
from pcmb.run.status import ModelTraceback, NodeFailure, Status

if TYPE_CHECKING:
    from pcmb.analysis.diagnostics import HeldOut, OutputDiagnostics
    from pcmb.analysis.statistics import Analysis

__all__ = [
    "ATTRIBUTE",
    "NOTE",
    "POINTS",
    "WARNING",
    "AdaptiveFit",
    "Design",
    "DesignReport",
    "ModelTraceback",
    "NodeFailure",
    "Placement",
    "RecordReport",
    "Refinement",
    "RegressionFit",
    "ReportFile",
    "ReportedByDesign",
    "Status",
    "StudyResult",
    "WarningRecord",
]


@dataclass(frozen=True)
class Design:
    """How a study's nodes were made, so nothing downstream has to guess.

    Attributes
    ----------
    kind:
        ``method.kind`` of the config: ``"collocation"``, ``"montecarlo"``, ``"lhs"``,
        ``"sobol"``, ...
    grid:
        The node rule: ``"tensor-gauss"`` for collocation, ``"random"`` for sampling.
    basis:
        The chaos terms recovered: ``"tensor"`` or ``"total"`` (``None``: no expansion).
    orders:
        Largest degree per input, germ order (``None`` without an expansion).
    level:
        Level of a sparse grid (``None`` otherwise).
    rule:
        The nested 1-D rule(s) of a sparse grid, resolved (``"gauss-patterson"``; one per
        input family, comma-separated, when they differ), ``None`` otherwise.
    elements:
        Number of elements the germ domain is split into (1: one global expansion).
    samples, seed:
        Size and seed of a sampled design (``None`` for a grid).
    fit:
        How coefficients come from the runs: ``"projection"``, ``"regression"`` (least
        squares), ``"lars"``, ``"omp"`` (sparse regression), ``"ols"`` (least squares on
        every candidate term) or ``"none"``.
    q:
        Hyperbolic exponent of sparse regression's candidate terms (``None`` otherwise).
    tolerance, max_samples:
        Sparse regression adding samples until its leave-one-out error meets ``tolerance``,
        within ``max_samples`` runs in all (``None``: one round); ``samples`` is then the
        number of runs made. An adaptive sparse grid refines to ``tolerance`` within
        ``max_runs`` runs (``samples``: the runs made); so does tensor collocation with
        ``order: auto`` (``orders``: the orders reached).
    label:
        A short label the design gives itself: ``chaos order 5``, ``chaos orders 3x5``,
        ``lhs + chaos fit, total order 3``, ``Smolyak level 3, rule gauss-patterson``, ...

    Records written before a field existed load with its default (the label: the kind).
    """

    kind: str
    grid: str
    basis: str | None = None
    orders: tuple[int, ...] | None = None
    level: int | None = None
    elements: int = 1
    samples: int | None = None
    seed: int | None = None
    fit: str = "none"
    rule: str | None = None
    q: float | None = None
    tolerance: float | None = None
    max_samples: int | None = None
    max_runs: int | None = None
    label: str = ""

    def describe(self) -> str:
        """JSON text of the record (stored in ``/design``)."""
        return json.dumps(asdict(self))

    @classmethod
    def from_description(cls, text: str) -> Design:
        """The record back from :meth:`describe`'s text."""
        data = json.loads(text)
        if data.get("orders") is not None:
            data["orders"] = tuple(data["orders"])
        data.setdefault("label", data["kind"])
        return cls(**data)


@dataclass(frozen=True)
class RegressionFit:
    """What sparse regression found for one output (stored under ``/outputs/<name>``).

    Attributes
    ----------
    selected:
        (S_k, n) the terms selected for this output (a subset of the expansion's terms).
    loo:
        (T,) corrected relative leave-one-out error per time (NaN where the output does not
        vary).
    condition:
        Condition number of the information matrix of the selected terms.
    held_out_fitted:
        Held-out runs the fit used besides the design's (the final fit, ``docs/methods.md``);
        0: the design's runs alone (files without it: 0).
    effective_runs:
        The runs the fit counts as: its rows, weighted, as (Σ w)² / Σ w² (files without it:
        NaN, and no estimate is made from the fit).
    """

    selected: NDArray[np.int64]
    loo: NDArray[np.float64]
    condition: float
    held_out_fitted: int = 0
    effective_runs: float = np.nan


@dataclass(frozen=True)
class Refinement:
    """The rounds of order refinement, ``order: auto`` (stored under ``/refinement``).

    Attributes
    ----------
    orders:
        (R, n) the orders (projection degrees) of each round's grid.
    runs:
        (R,) runs made by the end of each round.
    indicator:
        (R,) the estimated error of each round's statistics, relative to the output's largest
        std (the largest over the inputs of :func:`pcmb.designs.refine.box_errors`).
    """

    orders: NDArray[np.int64]
    runs: NDArray[np.int64]
    indicator: NDArray[np.float64]


@dataclass(frozen=True)
class AdaptiveFit:
    """What a dimension-adaptive sparse grid concluded (stored under ``/adaptive``).

    Attributes
    ----------
    index_set:
        (K, n) the final downward-closed set of level multi-indices, in the order added.
    indicators:
        (K,) each index's error indicator: the largest norm over outputs and times of the
        coefficients its tensor difference adds, relative to the output's largest std (NaN
        where not computed, as after failed nodes).
    active:
        (K,) the indices not refined yet: the indicators mark which to refine.
    history:
        (R, 2) runs so far and estimated error of the mean and std after each round (see
        :mod:`pcmb.designs.adaptive`).
    orders:
        (n,) highest degree per input of the recovered terms.
    """

    index_set: NDArray[np.int64]
    indicators: NDArray[np.float64]
    active: NDArray[np.bool_]
    history: NDArray[np.float64]
    orders: NDArray[np.int64]

    @property
    def estimate(self) -> float:
        """The estimated error of the mean and std after the last round (NaN if none)."""
        return float(self.history[-1, 1]) if self.history.shape[0] else float("nan")

    @property
    def levels(self) -> NDArray[np.int64]:
        """(n,) highest 1-D level per input."""
        return self.index_set.max(axis=0)

    @property
    def importance(self) -> NDArray[np.float64]:
        """(n,) each input's share of the indicators of the indices that refine it (the
        indices with a level > 0 there; shares overlap through interactions, so they need not
        sum to 1): which inputs matter."""
        finite = np.nan_to_num(self.indicators)
        refine = self.index_set > 0
        total = finite[refine.any(axis=1)].sum()
        shares = refine.T.astype(float) @ finite
        return shares / total if total > 0 else np.zeros(self.index_set.shape[1])


class ReportFile(Protocol):
    """The open result file as a :class:`DesignReport` writes and reads it
    (:mod:`pcmb.store` gives one). Paths are relative to the file's root; a scale is named by
    its root dataset (``"node"``, ``"input"``), ``None`` leaving that axis without one."""

    @property
    def outputs(self) -> tuple[str, ...]:
        """The outputs, in the model's order."""
        ...

    def dataset(self, path: str, data: NDArray[Any], *scales: str | None) -> None:
        """Write ``data`` at ``path``, its leading axes on ``scales``."""
        ...

    def points(self, path: str, data: NDArray[Any], output: str, *scales: str) -> None:
        """Write ``data`` whose last axis is the points of ``output`` (dropped for a scalar)."""
        ...

    def attrs(self, path: str) -> MutableMapping[str, Any]:
        """The attributes of the group or dataset at ``path``."""
        ...

    def read(self, path: str) -> NDArray[Any] | None:
        """The dataset at ``path`` (``None``: the file has none)."""
        ...

    def read_points(self, path: str, output: str) -> NDArray[Any] | None:
        """A dataset written by :meth:`points`, with its last axis back for a scalar output."""
        ...

    def shape(self, path: str) -> tuple[int, ...] | None:
        """The shape of the dataset at ``path``, without reading it (``None``: none)."""
        ...

    @property
    def runs(self) -> bool:
        """Whether the runs' values are read with the result (not when they exceed the
        memory available: a streamed study's statistics are then the stored ones)."""
        ...


class DesignReport(ABC):
    """What a design concluded beyond its expansions (a sparse regression's fits, an adaptive
    grid's index set, ...), written, read and summarised by the design's own code, so the
    result file, ``pcmb inspect`` and ``pcmb report`` need not know the design. A study holds
    one at most; :data:`pcmb.designs.REPORTS` lists them by :attr:`key`."""

    #: The report's name in :data:`pcmb.designs.REPORTS`.
    key: ClassVar[str]

    @abstractmethod
    def write(self, file: ReportFile) -> None:
        """Write the report into a result file (its outputs are written already)."""

    @classmethod
    @abstractmethod
    def read(cls, file: ReportFile) -> Self | None:
        """The report back from a result file (``None``: the file holds none of this kind)."""

    def summary(self, result: StudyResult) -> list[tuple[str, str]]:
        """``(label, text)`` lines for ``pcmb inspect`` and the report's table."""
        return []

    def merged(self, other: Self) -> Self:
        """This report with ``other``'s, of the same design on other outputs (the outputs of
        another axis); a report of the whole study keeps its own."""
        return self

    #: How many times below the true error the design's estimate (:meth:`statistics_error`)
    #: was measured to fall at worst, each design from its own calibration on smooth
    #: functions (``docs/methods.md``): the verdict vouches by the estimate alone only where
    #: this many times it meets the tolerance (``docs/diagnostics.md``).
    UNDERSTATES: ClassVar[float] = 1.0

    def statistics_error(self, result: StudyResult, output: str) -> float | None:
        """The design's own estimate of the error of ``output``'s mean and std, relative to
        its largest std (the largest over its times; a design with one estimate for all
        outputs gives the largest over them, which bounds each), where it makes one that is
        calibrated (``docs/methods.md``) from what ``result`` holds; ``None`` otherwise."""
        return None


#: A field of a :class:`RecordReport`'s record stored as a dataset whose last axis is the
#: points of the output (dropped for a scalar output).
POINTS = "points"
#: A field of a :class:`RecordReport`'s record stored as an attribute of its group.
ATTRIBUTE = "attribute"
#: Where a field of a :class:`RecordReport`'s record goes: the scales of its dataset's leading
#: axes (``None``: no scale), :data:`POINTS` or :data:`ATTRIBUTE`.
Placement = tuple[str | None, ...] | str


class RecordReport(DesignReport):
    """A report holding records (dataclasses of arrays), each stored as one group of the result
    file, a field per entry of :attr:`LAYOUT`: the one definition of how a design's record is
    written and read. A subclass is a dataclass of one field: the record, or output name ->
    record when :attr:`GROUP` holds ``{output}``."""

    #: The record's group: ``"adaptive"``, or ``"outputs/{output}"`` for a record per output.
    GROUP: ClassVar[str]
    #: The record's dataclass.
    RECORD: ClassVar[type]
    #: Field -> its :data:`Placement`; the first is a dataset, whose presence marks the
    #: record's (attributes come last).
    LAYOUT: ClassVar[dict[str, Placement]]

    @classmethod
    def _per_output(cls) -> bool:
        return "{output}" in cls.GROUP

    def _records(self) -> dict[str, Any]:
        """Output name -> record (``""`` -> the record of the whole study)."""
        (held,) = (getattr(self, each.name) for each in fields(self))  # type: ignore[arg-type]
        return held if self._per_output() else {"": held}

    def write(self, file: ReportFile) -> None:
        for output, record in self._records().items():
            group = self.GROUP.format(output=output)
            for name, place in self.LAYOUT.items():
                value = getattr(record, name)
                if place == ATTRIBUTE:
                    file.attrs(group)[name] = value
                elif place == POINTS:
                    file.points(f"{group}/{name}", value, output)
                else:
                    file.dataset(f"{group}/{name}", value, *place)

    @classmethod
    def _read_field(cls, file: ReportFile, group: str, name: str, output: str) -> Any:
        place = cls.LAYOUT[name]
        if place == ATTRIBUTE:
            if name not in file.attrs(group):  # a field added later: the record's default
                return next(f.default for f in fields(cls.RECORD) if f.name == name)
            value = file.attrs(group)[name]
            return value.item() if isinstance(value, np.generic) else value
        if place == POINTS:
            return file.read_points(f"{group}/{name}", output)
        return file.read(f"{group}/{name}")

    @classmethod
    def read(cls, file: ReportFile) -> Self | None:
        records = {}
        first, *rest = cls.LAYOUT
        for output in file.outputs if cls._per_output() else ("",):
            group = cls.GROUP.format(output=output)
            if (marker := cls._read_field(file, group, first, output)) is not None:
                found = {name: cls._read_field(file, group, name, output) for name in rest}
                records[output] = cls.RECORD(**{first: marker}, **found)
        if not records:
            return None
        return cls(records if cls._per_output() else records[""])  # type: ignore[call-arg]


class ReportedByDesign:
    """The records of a design report under their names of old (``regression``, ...), read
    from ``self.report``: empty (or ``None``) when the design reports none of them."""

    report: DesignReport | None

    @property
    def regression(self) -> dict[str, RegressionFit]:
        """Output name -> :class:`RegressionFit` of a sparse regression (empty otherwise)."""
        return getattr(self.report, "regression", {})

    @property
    def node_elements(self) -> NDArray[np.intp] | None:
        """(N,) the element of every node of a multi-element study, -1 for the nodes of
        elements split by ``elements: auto`` (not used by the recovery); ``None`` otherwise."""
        return getattr(self.report, "node_elements", None)

    @property
    def adaptive(self) -> AdaptiveFit | None:
        """What an adaptive sparse grid concluded (``None`` otherwise)."""
        return getattr(self.report, "adaptive", None)

    @property
    def refinement(self) -> Refinement | None:
        """The rounds of ``order: auto`` (``None`` otherwise)."""
        return getattr(self.report, "refinement", None)

    @property
    def moments(self) -> dict[str, NDArray[np.float64]]:
        """Output name -> (2, T) mean and std of a method that computes them without runs or
        an expansion (statistical linearization); empty otherwise."""
        return getattr(self.report, "moments", {})


@dataclass(frozen=True)
class WarningRecord:
    """One thing the user must know about the trustworthiness of the numbers.

    Attributes
    ----------
    code:
        A stable identifier, e.g. ``"nodes-failed"``, ``"least-squares-refit"``,
        ``"order-zero"``, ``"nominal-failed"``.
    message:
        What happened and what it means, in a sentence or two.
    output:
        The output it concerns (``None``: the whole study).
    time_range:
        ``(start, stop)`` of the times it concerns (``None``: all times).
    severity:
        :data:`WARNING` or :data:`NOTE` as read from a result file, which stores the
        severity :meth:`StudyResult.severity` decided when it was written; ``None`` until then
        (and in files without it). Not part of what the record says: records equal but for it
        compare equal.
    """

    code: str
    message: str
    output: str | None = None
    time_range: tuple[float, float] | None = None
    severity: str | None = field(default=None, compare=False)

    def __str__(self) -> str:
        where = f"{self.output}: " if self.output else ""
        if self.time_range is not None:
            where += f"t in [{self.time_range[0]:g}, {self.time_range[1]:g}]: "
        return f"{where}{self.message} [{self.code}]"


#: The two severities of a warning record (stored with it in the result file): a warning is
#: issued (``Study.run``, ``pcmb run``); a note only informs (``pcmb inspect``, the report).
WARNING = "warning"
NOTE = "note"
#: Codes of the cautions on what is drawn from the surrogate (PDFs, quantiles, Sobol'
#: indices) while its mean and std hold: recorded only, shown beside those figures.
SURROGATE_CAUTIONS = frozenset({"surrogate-inaccurate", "pdf-outside-runs"})
#: Codes of warning records that explain a result without questioning it (a Sobol' index that
#: cannot exist where an output does not vary, e.g. at a fixed initial state; surrogate values
#: beyond the runs' range, which the verdict of the diagnostics already weighs; a surrogate
#: less accurate pointwise than its statistics, or a PDF drawn from it with mass where no run
#: went, which caution what is drawn from the surrogate, not the mean and std; an output whose
#: runs and nominal run are all equal): kept in the result and its file, listed as
#: notes by ``pcmb inspect``, never a warning.
RECORDED_ONLY = (
    frozenset({"sobol-undefined", "surrogate-out-of-range", "output-constant"}) | SURROGATE_CAUTIONS
)
#: Codes of a method's own convergence indicators (an element's decay, a regression's
#: leave-one-out error, the adaptive grid's surpluses falling algebraically) and of the
#: budgets that ended a refinement judged by the same tolerance as the verdict or by an
#: internal threshold (``order: auto``, ``elements: auto``; not ``method.tolerance``, which
#: the user asked of ``adaptive`` and regression): the diagnostics' verdict judges the
#: result, so where it calls their output (for a record of the whole study: every output it
#: judged) reliable they are notes like :data:`RECORDED_ONLY`; where it does not, or there
#: is none, they are warnings that support it.
INDICATORS = frozenset(
    {"element-decay", "regression-loo", "adaptive-nonsmooth", "element-budget", "order-budget"}
)


@dataclass(frozen=True, repr=False)
class StudyResult(ReportedByDesign):
    """Everything a study produced (and everything a result file holds).

    Attributes
    ----------
    name:
        The study's name.
    design:
        How the nodes were made (:class:`Design`).
    times:
        (T,) output grid.
    input_names, distributions:
        The n inputs in germ order.
    germ, params:
        (N, n) germ (standard-variable) and physical coordinates of the nodes;
        :attr:`node_params` names the physical columns.
    weights:
        (N,) quadrature weights, or ``None`` for random sampling.
    status:
        (N,) int8 :class:`Status` codes.
    values:
        Output name -> (N, T) model values (NaN rows for failed nodes); (N, K) for an output
        on its own axis, (N, 1) for a scalar (see ``axes``).
    expansions:
        Output name -> :class:`ChaosExpansion` (empty for sampling without a fit), or
        :class:`~pcmb.chaos.elements.PiecewiseExpansion` for multi-element collocation.
    failures:
        The failed nodes.
    warnings:
        Structured :class:`WarningRecord` s.
    seconds:
        Wall time of the model runs.
    nominal_params:
        Input name -> the value used in the deterministic nominal run.
    nominal:
        Output name -> (T,) the deterministic run at the nominal parameters (empty if it
        failed: see ``warnings``).
    analysis:
        Quantile bands, PDFs and spectra (:func:`pcmb.analysis.statistics.analyse`).
    report:
        What the design concluded beyond its expansions (:class:`DesignReport`), ``None`` if
        nothing; read under its old names too (:class:`ReportedByDesign`: ``regression``,
        ``node_elements``, ``adaptive``, ``refinement``, ``moments``).
    diagnostics:
        Output name -> how far its chaos expansion can be trusted, time by time
        (:class:`pcmb.analysis.diagnostics.OutputDiagnostics`: ``failing_from``, ``decay``,
        ``holdout``...); empty without an expansion.
    held_out:
        The held-out runs that checked the expansions (``None``: none were made).
    processes:
        Random process inputs by name (:class:`pcmb.chaos.process.RandomProcess`); their
        germs ``name[k]`` are among the inputs.
    axes:
        Output name -> its own axis (:class:`~pcmb.axes.OutputAxis`), or ``None`` for a
        scalar (a derived figure of merit, a model's scalar output); the outputs not listed
        are on ``times``. Every statistic of an output is per point of its axis.
    """

    name: str
    design: Design
    times: NDArray[np.float64]
    input_names: tuple[str, ...]
    distributions: tuple[Distribution, ...]
    germ: NDArray[np.float64]
    params: NDArray[np.float64]
    weights: NDArray[np.float64] | None
    status: NDArray[np.int8]
    values: dict[str, NDArray[np.float64]]
    expansions: dict[str, ChaosExpansion] = field(default_factory=dict)
    failures: tuple[NodeFailure, ...] = ()
    warnings: tuple[WarningRecord, ...] = ()
    seconds: float = 0.0
    nominal_params: dict[str, float] = field(default_factory=dict)
    nominal: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    analysis: Analysis | None = None
    report: DesignReport | None = None
    diagnostics: dict[str, OutputDiagnostics] = field(default_factory=dict)
    held_out: HeldOut | None = None
    processes: dict[str, RandomProcess] = field(default_factory=dict)
    axes: dict[str, OutputAxis | None] = field(default_factory=dict)

    def __repr__(self) -> str:
        """A summary: method, runs, inputs, outputs and warnings (not the arrays)."""
        held_out = 0 if self.held_out is None else len(self.held_out.ok)
        grid = f"{len(self.times)} times in [{self.times[0]:g}, {self.times[-1]:g}]"
        codes = sorted({w.code for w in self.warnings})
        lines = [
            f"StudyResult {self.name!r}: {self.design.label}",
            f"  runs: {self.n_nodes} design ({int(self.ok.sum())} ok), {held_out} held-out, "
            f"{1 if self.nominal else 0} nominal; {self.seconds:.2f} s",
            *(
                f"  input {name} ~ {law.law}"
                for name, law in zip(self.input_names, self.distributions, strict=True)
            ),
            f"  outputs: {', '.join(self.outputs)} ({grid})",
            f"  warnings: {len(self.warnings)}" + (f" ({', '.join(codes)})" if codes else ""),
        ]
        return "\n".join(lines)

    @property
    def method(self) -> str:
        """The node method (``design.kind``)."""
        return self.design.kind

    @property
    def outputs(self) -> tuple[str, ...]:
        return tuple(self.values)

    def on_time(self, name: str) -> bool:
        """Whether output ``name`` is a time series on ``times``."""
        return name not in self.axes

    def axis(self, name: str) -> OutputAxis | None:
        """The axis of output ``name``: its own, a time axis (``unit`` empty), or ``None``
        for a scalar."""
        if name in self.axes:
            return self.axes[name]
        return OutputAxis("t", self.times)

    def grid(self, name: str) -> NDArray[np.float64]:
        """(W,) the points of output ``name``: ``times``, its axis's values, or ``[0.]`` for a
        scalar."""
        if self.on_time(name):
            return self.times
        axis = self.axes[name]
        return np.zeros(1) if axis is None else axis.values

    @property
    def n_nodes(self) -> int:
        return self.germ.shape[0]

    @property
    def fitted_runs(self) -> str:
        """The runs the expansions were fitted to, in words, where held-out runs were among
        them (a regression's final fit, :attr:`RegressionFit.held_out_fitted`): ``the fit of
        y used 32 design + 10 held-out runs``; empty otherwise."""
        refitted = {n: f.held_out_fitted for n, f in self.regression.items() if f.held_out_fitted}
        if not refitted:
            return ""
        design = int(np.sum(self.status == Status.OK))
        held_out = max(refitted.values())  # the same runs for every output refitted
        return f"the fit of {', '.join(refitted)} used {design} design + {held_out} held-out runs"

    def checked_fit(self, output: str) -> str:
        """``; of the fit before the final fit`` where ``output``'s verdict is of a fit its
        stored expansion replaced (:attr:`RegressionFit.held_out_fitted`), else empty."""
        fit = self.regression.get(output)
        return "; of the fit before the final fit" if fit and fit.held_out_fitted else ""

    @property
    def node_params(self) -> dict[str, NDArray[np.float64]]:
        """Input name -> (N,) physical value at every node."""
        return {name: self.params[:, k] for k, name in enumerate(self.input_names)}

    @property
    def partition(self) -> Partition | None:
        """The elements of a multi-element study (``None`` otherwise)."""
        first = next(iter(self.expansions.values()), None)
        return first.partition if isinstance(first, PiecewiseExpansion) else None

    @property
    def multi_index(self) -> NDArray[np.int64] | None:
        """(S, n) the chaos terms, or ``None`` without an expansion."""
        first = next(iter(self.expansions.values()), None)
        return None if first is None else first.multi_index

    @property
    def ok(self) -> NDArray[np.bool_]:
        """(N,) whether each node ran successfully."""
        return self.status == Status.OK

    def _expansion(self, name: str, statistic: str) -> ChaosExpansion:
        if name not in self.values:
            raise KeyError(f"no output {name!r}; the result has {list(self.values)}")
        if name not in self.expansions:
            raise ValueError(
                f"{statistic} of {name!r} needs a chaos expansion, and this {self.method} "
                "result has none (sample with fit: regression, or use collocation)"
            )
        return self.expansions[name]

    def mean(self, name: str) -> NDArray[np.float64]:
        """(T,) mean of an output: from the expansion, else the sample mean (which does not
        overflow where the exact one is a float, :func:`pcmb.chaos.expansion.sample_mean`)."""
        if name in self.expansions:
            return self.expansions[name].mean()
        if name in self.moments:
            return self.moments[name][0]
        return sample_mean(self.values[name][self.ok])

    def std(self, name: str) -> NDArray[np.float64]:
        """(T,) standard deviation: from the expansion, else the sample std (ddof 1); exactly 0
        where the output does not vary, finite where the exact one is a float
        (:func:`pcmb.chaos.expansion.sample_std`)."""
        if name in self.expansions:
            return self.expansions[name].std()
        if name in self.moments:
            return self.moments[name][1]
        return sample_std(self.values[name][self.ok], ddof=1)

    def sobol_first(self, name: str) -> NDArray[np.float64]:
        """(n, T) first-order Sobol' indices (needs an expansion)."""
        return self._expansion(name, "sobol_first").sobol_first()

    def sobol_total(self, name: str) -> NDArray[np.float64]:
        """(n, T) total Sobol' indices (needs an expansion)."""
        return self._expansion(name, "sobol_total").sobol_total()

    def sobol_process(self, name: str, process: str) -> NDArray[np.float64]:
        """(T,) total Sobol' index of a random process input: of its germs as one group."""
        expansion = self._expansion(name, "sobol_process")
        if process not in self.processes:
            raise KeyError(f"no random process {process!r}; the result has {list(self.processes)}")
        germs = germ_names(process, self.processes[process].terms)
        group = [self.input_names.index(germ) for germ in germs]
        if not isinstance(expansion, ChaosExpansion):
            raise ValueError("sobol_process needs one global chaos expansion (not multi-element)")
        return expansion.sobol_total_group(group)

    def severity(self, record: WarningRecord) -> str:
        """:data:`NOTE` when a record only informs (:data:`RECORDED_ONLY`, or an
        :data:`INDICATORS` record about an output the diagnostics vouch for — reliable and
        nowhere undecided — or about the whole study when they vouch for every output): kept in
        the result and its file, not issued as a warning; else :data:`WARNING`. A record read
        from a file keeps the severity stored there."""
        if record.severity is not None:
            return record.severity
        return NOTE if self._informs(record) else WARNING

    def is_note(self, record: WarningRecord) -> bool:
        """Whether a record's :meth:`severity` is :data:`NOTE`."""
        return self.severity(record) == NOTE

    def _informs(self, record: WarningRecord) -> bool:
        if record.code in RECORDED_ONLY:
            return True
        if record.code not in INDICATORS:
            return False
        if record.output is None:
            found = self.diagnostics.values()
            return bool(found) and all(judged.vouched for judged in found)
        judged = self.diagnostics.get(record.output)
        return judged is not None and judged.vouched

    @property
    def alerts(self) -> tuple[WarningRecord, ...]:
        """The records worth a warning: :attr:`warnings` without the notes (:meth:`is_note`)."""
        return tuple(w for w in self.warnings if not self.is_note(w))

    def warnings_for(self, output: str | None) -> tuple[WarningRecord, ...]:
        """The warnings about one output (``None``: those about the whole study)."""
        return tuple(w for w in self.warnings if w.output == output)
