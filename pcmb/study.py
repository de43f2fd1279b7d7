"""The pipeline: nodes -> model runs -> coefficients -> statistics -> one result file.

The command line and the Python API share this one code path::

    import numpy as np, pcmb

    def model(params, times):                       # any per-point simulator
        return {"y": params["a"] * np.sin(params["w"] * times)}

    study = pcmb.Study(model, {"a": pcmb.Uniform(0.5, 1.5), "w": pcmb.Normal(2.0, 0.1)},
                       times=np.linspace(0, 10, 201), order=5, outputs=["y"])
    result = study.run("results/toy.h5")             # or study.run() to keep it in memory
    result.mean("y"), result.std("y"), result.sobol_total("y")

``Study.from_config(pcmb.config.schema.load_config("configs/quarter_car.yaml"))`` builds the same
object from a YAML file.

Besides the statistics, every run stores the deterministic run at the nominal parameters
(``result.nominal``; for a nonlinear model the mean differs from it) and, when asked for
(``analysis=``, the config's ``analysis:``), quantile bands, PDFs and spectra
(:mod:`pcmb.analysis.statistics`). ``study.replace(method="montecarlo", samples=2000)`` is the same
study by Monte Carlo, to check the chaos against.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import cloudpickle
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.adapters.python import Model, ObjectModelFactory
from pcmb.analysis.statistics import Analysis, AnalysisSettings, analyse
from pcmb.chaos.basis import total_index_set
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, TensorGrid, random_nodes
from pcmb.chaos.recovery import fit_largest_stable, project_tensor
from pcmb.errors import ConfigError, IllPosedError, ModelRunError
from pcmb.run.executor import NodeFailure, run_nodes
from pcmb.run.journal import Journal

if TYPE_CHECKING:
    from pcmb.config.schema import StudyConfig

__all__ = ["Study", "StudyResult"]

Method = Literal["collocation", "montecarlo", "lhs", "sobol"]
FailurePolicy = Literal["abort", "retry", "regress"]
_SAMPLING: tuple[str, ...] = ("montecarlo", "lhs", "sobol")


@dataclass(frozen=True)
class StudyResult:
    """Everything a study produced (and everything a result file holds).

    Attributes
    ----------
    name, method:
        The study's name and node method.
    times:
        (T,) output grid.
    input_names, distributions:
        The n inputs in germ order.
    nodes, params:
        (N, n) germ and physical coordinates of the nodes.
    weights:
        (N,) quadrature weights (collocation) or ``None`` (sampling).
    status:
        (N,) int8: 0 pending, 1 ok, 2 failed.
    values:
        Output name -> (N, T) model values (NaN rows for failed nodes).
    expansions:
        Output name -> :class:`ChaosExpansion` (empty for sampling without a fit).
    failures:
        The failed nodes.
    warnings:
        Everything the user must know about the trustworthiness of the numbers.
    seconds:
        Wall time of the model runs.
    nominal_params:
        Input name -> the value used in the deterministic nominal run.
    nominal:
        Output name -> (T,) the deterministic run at the nominal parameters (empty if it
        failed: see ``warnings``). For a nonlinear model it differs from the mean.
    analysis:
        Quantile bands, PDFs and spectra (:func:`pcmb.analysis.statistics.analyse`), when requested.
    """

    name: str
    method: str
    times: NDArray[np.float64]
    input_names: tuple[str, ...]
    distributions: tuple[Distribution, ...]
    nodes: NDArray[np.float64]
    params: NDArray[np.float64]
    weights: NDArray[np.float64] | None
    status: NDArray[np.int8]
    values: dict[str, NDArray[np.float64]]
    expansions: dict[str, ChaosExpansion] = field(default_factory=dict)
    failures: tuple[NodeFailure, ...] = ()
    warnings: tuple[str, ...] = ()
    seconds: float = 0.0
    nominal_params: dict[str, float] = field(default_factory=dict)
    nominal: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    analysis: Analysis | None = None

    @property
    def outputs(self) -> tuple[str, ...]:
        return tuple(self.values)

    @property
    def multi_index(self) -> NDArray[np.int64] | None:
        """(S, n) the chaos terms, or ``None`` without an expansion."""
        first = next(iter(self.expansions.values()), None)
        return None if first is None else first.multi_index

    def _ok_values(self, name: str) -> NDArray[np.float64]:
        return self.values[name][self.status == 1]

    def mean(self, name: str) -> NDArray[np.float64]:
        """(T,) mean of an output: from the expansion, else the sample mean."""
        if name in self.expansions:
            return self.expansions[name].mean()
        return self._ok_values(name).mean(axis=0)

    def std(self, name: str) -> NDArray[np.float64]:
        """(T,) standard deviation: from the expansion, else the sample std (ddof 1)."""
        if name in self.expansions:
            return self.expansions[name].std()
        return self._ok_values(name).std(axis=0, ddof=1)

    def sobol_first(self, name: str) -> NDArray[np.float64]:
        """(n, T) first-order Sobol' indices (needs an expansion)."""
        return self.expansions[name].sobol_first()

    def sobol_total(self, name: str) -> NDArray[np.float64]:
        """(n, T) total Sobol' indices (needs an expansion)."""
        return self.expansions[name].sobol_total()


def _check_inputs(inputs: Mapping[str, Distribution]) -> dict[str, Distribution]:
    if not inputs:
        raise ConfigError("a study needs at least one input")
    for name, dist in inputs.items():
        if not isinstance(dist, Distribution):
            raise ConfigError(f"input {name!r} must be a pcmb distribution, got {dist!r}")
    return dict(inputs)


class Study:
    """A collocation (or sampling) study of a model.

    Parameters
    ----------
    model:
        A model factory (a picklable callable returning a model, as built from a config),
        a model class (constructed with ``params``), a model object, or a per-point
        function ``f(params: dict, times) -> dict``.
    inputs:
        Ordered mapping input name -> distribution; the order is the germ order.
    times:
        (T,) output grid.
    order:
        Chaos order, one for all inputs or a mapping input -> order.
    basis:
        ``"tensor"`` (interpolation on the grid) or ``"total"`` (projection onto |α| <= P).
    method:
        ``"collocation"`` (tensor Gauss nodes) or a sampling method ``"montecarlo"``,
        ``"lhs"``, ``"sobol"`` (with ``samples`` and ``seed``; ``fit="regression"`` adds a
        least-squares chaos fit of total order ``order``).
    outputs:
        Outputs to keep (default: all the model declares).
    params:
        Nominal parameters for a model class or function (ignored for a factory).
    name:
        Free text stored in the result.
    jobs, backend, address, chunk_size:
        Execution settings (see :func:`pcmb.run.executor.run_nodes`).
    on_failure, retries:
        Failure policy: ``"abort"`` (raise :class:`ModelRunError` naming every failed
        node), ``"retry"`` (re-run failed nodes ``retries`` times, then abort) or
        ``"regress"`` (least-squares refit on the surviving nodes, recorded as a warning).
    nominal:
        Values of the uncertain inputs for the deterministic nominal run. An input not
        given here takes its value in ``params`` when there is one (for a config: the
        ``model.params`` value), else its distribution's mean.
    analysis:
        Quantile bands, PDFs and spectra to compute after recovery (``None``: none; they
        can still be computed later from the result with :func:`pcmb.analysis.statistics.analyse`).

    Raises
    ------
    ConfigError
        Bad settings (no inputs, a non-increasing grid, a sampling method without samples,
        an unknown method, a nominal value for an unknown input).
    """

    def __init__(
        self,
        model: Any,
        inputs: Mapping[str, Distribution],
        times: ArrayLike,
        *,
        order: int | Mapping[str, int] = 3,
        basis: Literal["tensor", "total"] = "tensor",
        method: Method = "collocation",
        samples: int | None = None,
        seed: int = 0,
        fit: Literal["none", "regression"] = "none",
        outputs: Sequence[str] | None = None,
        params: Mapping[str, Any] | None = None,
        name: str = "study",
        jobs: int | None = None,
        backend: str = "loky",
        address: str | None = None,
        chunk_size: int | None = None,
        on_failure: FailurePolicy = "abort",
        retries: int = 1,
        nominal: Mapping[str, float] | None = None,
        analysis: AnalysisSettings | None = None,
    ):
        self.inputs = _check_inputs(inputs)
        self.times = np.asarray(times, dtype=float)
        if self.times.ndim != 1 or self.times.size < 1 or np.any(np.diff(self.times) <= 0):
            raise ConfigError("times must be a non-empty increasing 1-D grid")
        self.order = order
        self.basis = basis
        self.method = method
        self.samples = samples
        self.seed = seed
        self.fit = fit
        self.name = name
        self.jobs, self.backend, self.address = jobs, backend, address
        self.chunk_size = chunk_size
        self.on_failure, self.retries = on_failure, retries
        self.params = dict(params or {})
        if _is_function(model):
            # A per-point function receives every parameter by name: uncertain inputs it was
            # not given a nominal value for start at their mean (used by the nominal run).
            self.params = {
                **{name: dist.expectation() for name, dist in self.inputs.items()},
                **self.params,
            }
        self.model_factory: Callable[[], Model] = (
            model if _is_factory(model) else ObjectModelFactory(model, self.params, _tuple(outputs))
        )
        self.outputs = _tuple(outputs)
        self.nominal = dict(nominal or {})
        self.analysis = analysis
        self.fingerprint_extra = ""
        unknown = sorted(set(self.nominal) - set(self.inputs))
        if unknown:
            raise ConfigError(f"nominal values given for unknown input(s) {unknown}")
        choices = {
            "method": (method, ("collocation", *_SAMPLING)),
            "basis": (basis, ("tensor", "total")),
            "fit": (fit, ("none", "regression")),
            "on_failure": (on_failure, ("abort", "retry", "regress")),
        }
        for key, (value, allowed) in choices.items():
            if value not in allowed:
                raise ConfigError(f"{key} must be one of {', '.join(allowed)}, got {value!r}")
        if method in _SAMPLING and (samples is None or samples < 2):
            raise ConfigError(f"method {method!r} needs at least 2 samples, got {samples}")

    # -- construction from a config -----------------------------------------------------------

    @classmethod
    def from_config(cls, config: StudyConfig) -> Study:
        """The study a validated config describes (same code path as ``pcmb run``)."""
        method = config.method
        execution = config.execution
        study = cls(
            config.model_factory(),
            dict(zip(config.input_names, config.distributions, strict=True)),
            config.times,
            order=dict(zip(config.input_names, config.orders, strict=True))
            if config.orders is not None
            else 0,
            basis=method.basis,
            method=method.kind,
            samples=method.samples,
            seed=method.seed,
            fit=method.fit,
            outputs=config.output_names,
            name=config.name,
            jobs=execution.jobs,
            backend=execution.backend,
            address=execution.address,
            chunk_size=execution.chunk_size,
            on_failure=execution.on_failure,
            retries=execution.retries,
            nominal={
                name: float(config.model.params[name])
                for name in config.input_names
                if name in config.model.params
            },
            analysis=config.analysis_settings,
        )
        study.fingerprint_extra = config.sha256
        return study

    def replace(self, **changes: Any) -> Study:
        """A copy of this study with some constructor arguments changed, checked again.

        For example the Monte Carlo twin of a collocation study,
        ``study.replace(method="montecarlo", samples=2000, seed=1)``, runs the same model,
        inputs, grid, executor and analysis.

        Raises
        ------
        ConfigError
            If an argument is unknown or the changed study is invalid.
        """
        arguments = {
            "inputs": self.inputs,
            "times": self.times,
            "order": self.order,
            "basis": self.basis,
            "method": self.method,
            "samples": self.samples,
            "seed": self.seed,
            "fit": self.fit,
            "outputs": self.outputs,
            "name": self.name,
            "jobs": self.jobs,
            "backend": self.backend,
            "address": self.address,
            "chunk_size": self.chunk_size,
            "on_failure": self.on_failure,
            "retries": self.retries,
            "params": self.params,
            "nominal": self.nominal,
            "analysis": self.analysis,
        }
        unknown = sorted(set(changes) - set(arguments))
        if unknown:
            raise ConfigError(f"Study.replace: unknown argument(s) {unknown}")
        if "inputs" in changes and "nominal" not in changes:
            arguments["nominal"] = {k: v for k, v in self.nominal.items() if k in changes["inputs"]}
        study = Study(self.model_factory, **{**arguments, **changes})
        study.fingerprint_extra = self.fingerprint_extra
        return study

    # -- nodes --------------------------------------------------------------------------------

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.inputs)

    @property
    def orders(self) -> tuple[int, ...]:
        """Chaos order per input, germ order."""
        if isinstance(self.order, Mapping):
            missing = set(self.inputs) - set(self.order)
            if missing:
                raise ConfigError(f"no order given for input(s) {sorted(missing)}")
            return tuple(int(self.order[name]) for name in self.inputs)
        return (int(self.order),) * len(self.inputs)

    def nominal_params(self) -> dict[str, float]:
        """Values of the uncertain inputs in the nominal run: given, else ``params``, else mean."""
        values = {}
        for name, dist in self.inputs.items():
            if name in self.nominal:
                values[name] = float(self.nominal[name])
            elif name in self.params:
                values[name] = float(self.params[name])
            else:
                values[name] = dist.expectation()
        return values

    def node_set(self) -> TensorGrid | NodeSet:
        """The nodes this study runs: a tensor Gauss grid or random samples."""
        dists = tuple(self.inputs.values())
        if self.method == "collocation":
            return TensorGrid(dists, self.orders)
        return random_nodes(dists, int(self.samples or 0), self.method, self.seed)

    def fingerprint(self, nodes: TensorGrid | NodeSet, outputs: Sequence[str]) -> str:
        """Hash of everything that changes the results (for the resume journal)."""
        digest = hashlib.sha256()
        for array in (nodes.params, self.times):
            digest.update(np.ascontiguousarray(array).tobytes())
        digest.update(json.dumps([list(outputs), self.chunk_size, self.fingerprint_extra]).encode())
        # The model and its fixed parameters (entry, params, or the pickled object itself).
        digest.update(cloudpickle.dumps(self.model_factory))
        return digest.hexdigest()

    # -- running ------------------------------------------------------------------------------

    def check_model(self) -> tuple[str, ...]:
        """Build the model once, check it against the study, and return the outputs to keep.

        Raises
        ------
        ConfigError
            A requested output the model lacks, or an uncertain input that names none of the
            model's parameters (when the model lists them) — before anything runs.
        """
        model = self.model_factory()
        declared = tuple(model.outputs)
        unknown = [name for name in self.outputs or () if name not in declared]
        if unknown:
            raise ConfigError(f"the model has no output(s) {unknown}; it has {list(declared)}")
        parameters = getattr(model, "parameters", None)
        if parameters is not None:
            strangers = [name for name in self.inputs if name not in parameters]
            if strangers:
                raise ConfigError(
                    f"input(s) {strangers} name no parameter of the model; "
                    f"it has {sorted(parameters)}"
                )
        return declared if self.outputs is None else self.outputs

    def run(
        self,
        output: str | Path | None = None,
        *,
        resume: bool = False,
        progress: bool | None = None,
        provenance: Mapping[str, str] | None = None,
    ) -> StudyResult:
        """Run the model at every node and recover the statistics.

        Parameters
        ----------
        output:
            Result file (HDF5, written atomically); ``None`` keeps the result in memory
            and journals nothing.
        resume:
            Continue from the journal ``<output>.journal`` of an interrupted run.
        progress:
            Progress bar on stderr (default: when stderr is a terminal).
        provenance:
            Extra attributes for the file (config text, command line).

        Raises
        ------
        ConfigError
            Bad settings, or an unfinished journal exists and ``resume`` is False.
        ModelRunError
            Nodes failed and the policy does not allow going on; the journal is kept.
        """
        nodes = self.node_set()
        outputs = self.check_model()
        if self.analysis is not None:
            self.analysis.check(self.times, outputs)
        journal = None
        fresh_journal = False
        if output is not None:
            journal_dir = Path(f"{output}.journal")
            fresh_journal = not Journal.exists(journal_dir)
            if not fresh_journal and not resume:
                raise ConfigError(
                    f"{journal_dir} holds the finished nodes of an interrupted run: "
                    "continue with --resume, or delete it to start over"
                )
            journal = Journal(
                journal_dir, self.fingerprint(nodes, outputs), nodes.size, outputs, self.times.size
            )
        try:
            runs = run_nodes(
                self.model_factory,
                dict(zip(self.input_names, nodes.params.T, strict=True)),
                self.times,
                outputs,
                jobs=self.jobs,
                backend=self.backend,
                address=self.address,
                chunk_size=self.chunk_size,
                retries=self.retries if self.on_failure == "retry" else 0,
                journal=journal,
                progress=progress,
            )
        except ConfigError:
            # Rejected before any node ran: leave nothing behind (a journal would block a rerun).
            if journal is not None and fresh_journal:
                journal.remove()
            raise
        if runs.failures and self.on_failure != "regress":
            kept = f"; finished nodes are kept in {journal.directory}" if journal else ""
            raise ModelRunError(
                runs.failures,
                f"the model failed at {len(runs.failures)} of {nodes.size} node(s) "
                f"(on_failure: {self.on_failure}){kept}:",
            )
        result = self._recover(nodes, runs.values, runs.status, runs.failures, runs.seconds)
        result = self._with_nominal(result, outputs)
        if self.analysis is not None:
            result = dataclasses.replace(result, analysis=analyse(result, self.analysis))
        if output is not None:
            from pcmb.store import write_result  # h5py only when a file is written

            write_result(output, result, provenance=provenance or {})
            if journal is not None:
                journal.remove()
        return result

    def _with_nominal(self, result: StudyResult, outputs: Sequence[str]) -> StudyResult:
        """The result with the deterministic run at the nominal parameters added.

        It is not part of any statistic, so a failure is recorded as a warning, not raised.
        """
        params = self.nominal_params()
        run = run_nodes(
            self.model_factory,
            {name: np.array([value]) for name, value in params.items()},
            self.times,
            outputs,
            jobs=1,
            progress=False,
        )
        if run.failures:
            message = f"the nominal run failed, so none is stored: {run.failures[0].message}"
            return dataclasses.replace(
                result, nominal_params=params, warnings=(*result.warnings, message)
            )
        nominal = {name: values[0] for name, values in run.values.items()}
        return dataclasses.replace(result, nominal_params=params, nominal=nominal)

    # -- recovery -----------------------------------------------------------------------------

    def _projection_index(self, grid: TensorGrid) -> NDArray[np.int64]:
        """The terms recovered from a complete grid: the tensor set, or |α| <= P inside it."""
        if self.basis == "tensor":
            return grid.multi_index
        index = total_index_set(len(self.inputs), max(self.orders))
        return index[np.all(index <= np.array(self.orders), axis=1)]

    def _recover(
        self,
        nodes: TensorGrid | NodeSet,
        values: dict[str, NDArray[np.float64]],
        status: NDArray[np.int8],
        failures: tuple[NodeFailure, ...],
        seconds: float,
    ) -> StudyResult:
        dists = tuple(self.inputs.values())
        names = self.input_names
        ok = status == 1
        warnings: list[str] = []
        expansions: dict[str, ChaosExpansion] = {}
        if failures:
            warnings.append(
                f"{len(failures)} of {nodes.size} node(s) failed and were left out "
                f"(on_failure: regress): " + "; ".join(str(f) for f in failures)
            )
        if isinstance(nodes, TensorGrid) and not failures:
            index = self._projection_index(nodes)
            for name, y in values.items():
                coefficients = project_tensor(nodes, y, index)
                expansions[name] = ChaosExpansion(coefficients, index, dists, names)
        elif isinstance(nodes, TensorGrid) or self.fit == "regression":
            # An incomplete grid is no quadrature rule: refit by least squares instead, all
            # outputs at once (one basis, one factorisation).
            max_order = max(self.orders)
            weights = nodes.weights[ok] if isinstance(nodes, TensorGrid) else None
            caps = self.orders if isinstance(nodes, TensorGrid) else None
            stacked = np.stack([y[ok] for y in values.values()], axis=1)
            try:
                index, fit = fit_largest_stable(
                    dists, nodes.nodes[ok], stacked, max_order, weights, orders=caps
                )
            except IllPosedError as error:
                message = f"on_failure regress could not refit: {error}:"
                raise ModelRunError(failures, message) from error
            for k, name in enumerate(values):
                expansions[name] = ChaosExpansion(fit.coefficients[:, k], index, dists, names)
            order = int(index.sum(axis=1).max())
            warnings.append(
                f"least-squares chaos of total order {order} ({index.shape[0]} terms, asked "
                f"{max_order}) on {int(ok.sum())} nodes; worst relative leave-one-out error "
                f"{float(np.nanmax(fit.loo_error, initial=0.0)):.3g}"
            )
        if self.method == "collocation":
            flat = [name for name, order in zip(names, self.orders, strict=True) if order == 0]
            if flat:
                warnings.append(
                    f"input(s) {flat} have order 0: each is held at its single Gauss node and "
                    "contributes no variance"
                )
        return StudyResult(
            name=self.name,
            method=self.method,
            times=self.times,
            input_names=names,
            distributions=dists,
            nodes=nodes.nodes,
            params=nodes.params,
            weights=nodes.weights if isinstance(nodes, TensorGrid) else None,
            status=status,
            values=values,
            expansions=expansions,
            failures=failures,
            warnings=tuple(warnings),
            seconds=seconds,
        )


def _is_factory(model: Any) -> bool:
    """Whether ``model`` is one of pcmb's model factories (as built from a config)."""
    from pcmb.adapters.python import CommandModelFactory, PythonModelFactory

    factories: tuple[type, ...] = (PythonModelFactory, CommandModelFactory, ObjectModelFactory)
    mujoco = sys.modules.get(
        "pcmb.adapters.mujoco.model"
    )  # a MuJoCo factory exists only once imported
    if mujoco is not None:
        factories += (mujoco.MujocoModelFactory,)
    return isinstance(model, factories)


def _is_function(model: Any) -> bool:
    """A plain per-point function (not a class, a model object or a factory)."""
    return (
        callable(model)
        and not inspect.isclass(model)
        and not hasattr(model, "simulate")
        and not _is_factory(model)
    )


def _tuple(values: Sequence[str] | None) -> tuple[str, ...] | None:
    return None if values is None else tuple(values)
