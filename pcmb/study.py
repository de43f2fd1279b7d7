"""The pipeline: nodes -> model runs -> coefficients -> statistics -> one result file.

The command line and the Python API share this one code path; see ``docs/architecture.md``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TextIO, TypeVar

import cloudpickle
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pcmb.adapters.protocol import ModelFactory
from pcmb.adapters.python import is_function_model, model_factory
from pcmb.analysis.derived import DerivedOutput, derive, derived_problems, parse_derived
from pcmb.analysis.diagnostics import (
    RANGE_DRAWS,
    HeldOut,
    diagnose_all,
    more_runs,
    pdf_outside_runs,
)
from pcmb.analysis.statistics import AnalysisSettings, analyse
from pcmb.analysis.streaming import stream_statistics
from pcmb.axes import OutputAxis
from pcmb.chaos.inputs import Distribution
from pcmb.chaos.nodes import NodeSet, TensorGrid, join_nodes, overflowing_inputs
from pcmb.chaos.process import RandomProcess, germ_inputs, model_params, per_germ
from pcmb.config.schema import DiagnosticsSpec, ExecutionSpec
from pcmb.designs import MethodSection, MethodSpec, NodeDesign, make_design
from pcmb.designs.base import MomentReport, Recovery
from pcmb.errors import (
    ConfigError,
    ConfigProblem,
    IllPosedError,
    ModelError,
    ModelRunError,
    PcmbError,
    PcmbWarning,
    UsageError,
)
from pcmb.held_out import HELD_OUT_RUN, TAIL_FAILURE_SHARE, HeldOutPlan
from pcmb.result import Design, DesignReport, NodeFailure, Status, StudyResult, WarningRecord
from pcmb.run.backends import InProcessPool, Pool, checking_pool, open_pool
from pcmb.run.executor import (
    JoinedJournal,
    PendingRun,
    RunResult,
    chunk_bounds,
    describe_model,
    join_runs,
    run_in_worker,
    run_nodes,
    split_runs,
    start_run,
)
from pcmb.run.fingerprint import Fingerprint, digest_files, model_files
from pcmb.run.journal import Journal
from pcmb.run.journaling import Journaling, removed_if_rejected
from pcmb.run.memory import MemoryEstimate, StreamPlan, check_memory, parse_memory
from pcmb.run.output import SizeEstimate, check_output, estimate_size
from pcmb.run.progress import phase
from pcmb.run.worker import Layout, ModelFacts
from pcmb.study_arguments import (
    DEPRECATED,
    from_keywords,
    keys_of,
    usage_error,
    validated_section,
)
from pcmb.wording import plural

_Runs = TypeVar("_Runs", RunResult, HeldOut, None)
_T = TypeVar("_T")

if TYPE_CHECKING:
    from pcmb.chaos.expansion import ChaosExpansion
    from pcmb.config.schema import StudyConfig

__all__ = ["DEPRECATED", "Study"]


def _derived(entries: Mapping[str, Any]) -> dict[str, DerivedOutput]:
    """``derived`` entries as DerivedOutput s (a config-like mapping is parsed)."""
    given = {k: v for k, v in entries.items() if not isinstance(v, DerivedOutput)}
    try:
        parsed = parse_derived(given)
    except ConfigError as error:
        raise UsageError(error.problems, source="Study") from None
    return {name: parsed.get(name, entry) for name, entry in entries.items()}


def _check_inputs(
    inputs: Mapping[str, Distribution | RandomProcess],
) -> dict[str, Distribution | RandomProcess]:
    if not inputs:
        raise usage_error("inputs", "a study needs at least one input")
    for name, dist in inputs.items():
        if not isinstance(dist, Distribution | RandomProcess):
            raise usage_error(
                f"inputs.{name}", f"must be a pcmb distribution or random process, got {dist!r}"
            )
    return dict(inputs)


#: The method of a study given none: tensor collocation of order 3.
DEFAULT_METHOD: Mapping[str, Any] = {"kind": "collocation", "order": 3}


@dataclasses.dataclass(frozen=True)
class StudySource:
    """Where a study's settings came from, for what it fingerprints and how it names them.

    Attributes
    ----------
    settings:
        The run-relevant part of its validated config as JSON (:meth:`Study.from_config`),
        fingerprinted with the nodes; empty for a study built in Python.
    address_key:
        Where the dask address was given (``address``, ``execution.address``,
        ``--address``), named when it cannot be reached.
    """

    settings: str = ""
    address_key: str = "address"


class Study:
    """A study of a model: its nodes, runs, chaos expansions and statistics.

    Parameters
    ----------
    model:
        A :class:`~pcmb.adapters.protocol.ModelFactory` (as built from a config), a model
        class (constructed with ``params``), a model object, or a function marked with
        :func:`pcmb.pointwise` or :func:`pcmb.batched`.
    inputs:
        Ordered mapping input name -> distribution, or random process
        (:class:`pcmb.chaos.process.RandomProcess`: its germs ``name[0]``, ``name[1]``, ...
        become standard normal inputs and the model receives its field, (B, m)); the order
        is the germ order.
    times:
        (T,) output grid.
    method:
        The ``method:`` section (a design's ``Settings``, e.g.
        ``CollocationSettings(kind="collocation", order=3)``) or its keys as a mapping
        (``{"kind": "lhs", "samples": 256}``); default: tensor collocation of order 3. The keys
        are those of the config (``docs/config.md``).
    execution:
        The ``execution:`` section (:class:`pcmb.config.schema.ExecutionSpec`) or its keys:
        jobs, backend, address, on_failure, retries, chunk_size, nominal_run, timeout.
    analysis:
        Quantile bands, PDFs and spectra to compute after recovery (``None``: none; they
        can still be computed later with :func:`pcmb.analysis.statistics.analyse`).
    diagnostics:
        The ``diagnostics:`` section (:class:`pcmb.config.schema.DiagnosticsSpec`) or its
        keys: the accepted error (``tolerance``) and the outputs judged (``outputs``).
    address:
        With backend dask: a ``distributed.Client`` or ``Cluster`` of your own, which pcmb
        uses and leaves open (or an address; overrides ``execution.address``).
    outputs:
        Outputs to keep (default: all the model declares).
    params:
        Nominal parameters for a model class or function (ignored for a factory).
    name:
        Free text stored in the result.
    nominal:
        Values of the uncertain inputs for the deterministic nominal run. An input not
        given here takes its value in ``params`` when there is one (for a config: the
        ``model.params`` value), else its distribution's mean.
    derived:
        Figures of merit computed from the time outputs after the runs, each a scalar
        output: name -> :class:`~pcmb.analysis.derived.DerivedOutput`, or a mapping as in
        the config's ``derived:`` (``{"x1_peak": {"max_abs": "x1"}}``).
    source:
        Where the settings came from (:class:`StudySource`): set by :meth:`from_config` and
        the command line; a study built in Python keeps the default.
    **deprecated:
        The keyword arguments of pcmb 0.x (``order=``, ``samples=``, ``jobs=``,
        ``backend=``, ``diagnostics_tolerance=``, ``method="lhs"``, ...; :data:`DEPRECATED`
        says where each goes), accepted for one release with a ``DeprecationWarning``.

    Raises
    ------
    UsageError
        Bad arguments (no inputs, a non-increasing grid, a setting the method's section
        refuses or its design cannot use, a nominal value for an unknown input), named by
        their key.
    """

    def __init__(
        self,
        model: Any,
        inputs: Mapping[str, Distribution | RandomProcess],
        times: ArrayLike,
        *,
        method: MethodSection | Mapping[str, Any] | None = None,
        execution: ExecutionSpec | Mapping[str, Any] | None = None,
        analysis: AnalysisSettings | None = None,
        diagnostics: DiagnosticsSpec | Mapping[str, Any] | None = None,
        address: Any = None,
        outputs: Sequence[str] | None = None,
        params: Mapping[str, Any] | None = None,
        name: str = "study",
        nominal: Mapping[str, float] | None = None,
        derived: Mapping[str, DerivedOutput | Mapping[str, Any]] | None = None,
        source: StudySource = StudySource(),
        **deprecated: Any,
    ):
        if isinstance(method, str) or deprecated:
            kind = method if isinstance(method, str) else None
            current = None if isinstance(method, str) else method
            method, execution, diagnostics = from_keywords(
                kind, execution, diagnostics, deprecated, current
            )
        #: What the model receives, by name: distributions and random processes.
        self.model_inputs = _check_inputs(inputs)
        self.processes = {
            name: value
            for name, value in self.model_inputs.items()
            if isinstance(value, RandomProcess)
        }
        #: The germ inputs (a process's germs in its place), in germ order.
        self.inputs = germ_inputs(self.model_inputs)
        self.times = np.asarray(times, dtype=float)
        if self.times.ndim != 1 or self.times.size < 1 or np.any(np.diff(self.times) <= 0):
            raise usage_error("times", "must be a non-empty increasing 1-D grid")
        self.method: MethodSection = validated_section(
            "method", MethodSpec, method or DEFAULT_METHOD
        )
        if isinstance(address, str):  # an address is an execution setting, checked there
            execution, address = {**keys_of(execution), "address": address}, None
        self.execution: ExecutionSpec = validated_section(
            "execution", ExecutionSpec, execution or {}
        )
        #: ``execution.memory`` (:class:`~pcmb.run.memory.MemoryBudget`).
        self.memory = parse_memory(self.execution.memory)
        self.diagnostics: DiagnosticsSpec = validated_section(
            "diagnostics", DiagnosticsSpec, diagnostics or {}
        )
        self.analysis = analysis
        self.address = self.execution.address if address is None else address
        self.name = name
        self.params = dict(params or {})
        if is_function_model(model):
            # A per-point function receives every parameter by name: uncertain inputs it was
            # not given a nominal value for start at their mean (used by the nominal run).
            self.params = {
                **{
                    name: np.zeros(value.grid.size)  # a process's mean field
                    if isinstance(value, RandomProcess)
                    else value.expectation()
                    for name, value in self.model_inputs.items()
                },
                **self.params,
            }
        self.model_factory: ModelFactory = model_factory(model, self.params, _tuple(outputs))
        self.outputs = _tuple(outputs)
        self.nominal = dict(nominal or {})
        self.derived = _derived(derived or {})
        self.source = source
        unknown = sorted(set(self.nominal) - set(self.inputs))
        if unknown:
            raise usage_error("nominal", f"values given for unknown input(s) {unknown}")
        self.design = self._design()
        self._held_out = HeldOutPlan(
            self.design, self.inputs, self.method.seed, self.method.validation
        )

    def _design(self) -> NodeDesign:
        settings = self.method.settings(self.orders, self.diagnostics.tolerance)
        try:
            return make_design(self.inputs, settings)
        except ConfigError as error:  # the design names every problem of its keys
            raise UsageError(error.problems, source="Study") from None
        except ValueError as error:
            key, _, message = str(error).partition(": ")
            raise usage_error(key, message) from None

    # -- construction from a config -----------------------------------------------------------

    @classmethod
    def from_config(
        cls,
        config: StudyConfig,
        execution: Mapping[str, Any] | None = None,
        address_key: str = "execution.address",
    ) -> Study:
        """The study a validated config describes (same code path as ``pcmb run``).

        ``execution``: keys set over the config's ``execution:`` (the command line's
        ``--jobs``, ``--backend``, ``--address``), checked with it; ``address_key``: where
        the dask address was given (:class:`StudySource`).
        """
        settings = keys_of(config.execution) | dict(execution) if execution else config.execution
        return cls(
            config.model_factory(),
            config.study_inputs,
            config.times,
            method=config.method,
            execution=settings,
            analysis=config.analysis_settings,
            diagnostics=config.diagnostics,
            outputs=config.output_names,
            name=config.name,
            nominal={
                name: float(config.model.params[name])
                for name in config.input_names
                if name in config.model.params
            },
            derived=config.derived_outputs,
            source=StudySource(_run_settings(config), address_key),
        )

    def replace(self, **changes: Any) -> Study:
        """A copy of this study with some constructor arguments changed, checked again.

        For example the Monte Carlo twin of a collocation study,
        ``study.replace(method={"kind": "montecarlo", "samples": 2000, "seed": 1})``, runs the
        same model, inputs, grid, executor and analysis. The keywords of pcmb 0.x are
        accepted too (deprecated): ``study.replace(jobs=2)`` changes one key of a section;
        ``method="lhs"`` keeps the keys of the current method the new kind takes.

        Raises
        ------
        UsageError
            If an argument is unknown or the changed study is invalid.
        """
        arguments = {
            "inputs": self.model_inputs,
            "times": self.times,
            "method": self.method,
            "execution": self.execution,
            "analysis": self.analysis,
            "diagnostics": self.diagnostics,
            "outputs": self.outputs,
            "name": self.name,
            "params": self.params,
            "nominal": self.nominal,
            "derived": self.derived,
            "source": self.source,
        }
        if self.address is not self.execution.address:
            arguments["address"] = self.address
        old = {key: changes.pop(key) for key in list(changes) if key in DEPRECATED}
        if isinstance(changes.get("method"), str):
            old["method"] = changes.pop("method")
        unknown = sorted(set(changes) - set(arguments) - {"address"})
        if unknown:
            raise UsageError(f"unknown argument(s) {unknown}", source="Study.replace")
        arguments.update(changes)
        if old:
            arguments["method"], arguments["execution"], arguments["diagnostics"] = from_keywords(
                old.pop("method", None),
                arguments["execution"],
                arguments["diagnostics"],
                old,
                arguments["method"],
            )
        if "inputs" in changes and "nominal" not in changes:
            arguments["nominal"] = {k: v for k, v in self.nominal.items() if k in changes["inputs"]}
        if "address" in changes or "address" in old:  # given here, under this name
            arguments["source"] = dataclasses.replace(arguments["source"], address_key="address")
        return Study(self.model_factory, **arguments)

    # -- nodes --------------------------------------------------------------------------------

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.inputs)

    @property
    def orders(self) -> tuple[int, ...] | Literal["auto"] | None:
        """Chaos order per input, germ order (``"auto"``: chosen in rounds; ``None``: the
        method takes no order)."""
        order = getattr(self.method, "order", None)
        if order is None or order == "auto":
            return order
        if isinstance(order, Mapping):
            order = per_germ(order, self.model_inputs)
            missing = set(self.inputs) - set(order)
            if missing:
                raise usage_error("method.order", f"no order given for input(s) {sorted(missing)}")
            return tuple(int(order[name]) for name in self.inputs)
        return (int(order),) * len(self.inputs)

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
        """The nodes this study runs (made by its design).

        Raises
        ------
        UsageError
            At ``inputs.<name>``: an input's map from the germ overflows at a node.
        """
        nodes = self.design.nodes()
        self._check_finite(nodes)
        return nodes

    def _check_finite(self, nodes: TensorGrid | NodeSet) -> None:
        """Every input's value at every node is a finite number (see
        :func:`~pcmb.chaos.nodes.overflowing_inputs`)."""
        problems = [
            ConfigProblem(f"inputs.{name}", message)
            for name, message in overflowing_inputs(nodes, self.input_names)
        ]
        if problems:
            raise UsageError(problems, source="Study")

    def fingerprint(
        self, nodes: TensorGrid | NodeSet, outputs: Sequence[str], loaded: Sequence[str] = ()
    ) -> Fingerprint:
        """What the resume journal belongs to: everything that changes the node values.

        Its ``digest`` hashes the nodes' parameters, the time grid, the settings of every
        random process (what its germs become), the input names (the
        order of the columns), the outputs, an explicit chunk size, ``source.settings``
        (for a study built from a config: the run-relevant part of the validated config,
        see :meth:`from_config`) and the pickled model factory (entry, params, or the object
        itself). Its ``files`` table holds the SHA-256 of the content of every file the model
        is known to depend on, so that editing one between a kill and a resume is refused,
        naming it: those its factory declares (:func:`pcmb.run.fingerprint.model_files`: the
        python entry file and ``model.files``, a command's program, templates and files, an
        MJCF scene and what it references, an FMU) and ``loaded``, the files the model
        loaded while built in a worker (:attr:`~pcmb.run.worker.ModelFacts.loaded_files`:
        a python model's own modules).
        Execution settings that cannot change a node's values (jobs, backend, failure
        policy) and the analysis are left out: changing them keeps the finished work.
        """
        return Fingerprint(self._digest(nodes, outputs), self._file_digests(loaded))

    def _digest(self, nodes: TensorGrid | NodeSet, outputs: Sequence[str]) -> str:
        """The ``digest`` of :meth:`fingerprint`."""
        digest = hashlib.sha256()
        for array in (nodes.params, self.times):
            digest.update(np.ascontiguousarray(array))  # its buffer, not a copy of it
        settings = [
            list(outputs),
            self.execution.chunk_size,
            list(self.input_names),
            self.source.settings,
        ]
        if self.processes:  # by their settings: they make the modes, whose bits vary by BLAS
            settings.append({name: p.describe() for name, p in self.processes.items()})
        digest.update(json.dumps(settings).encode())
        digest.update(cloudpickle.dumps(self.model_factory))
        return digest.hexdigest()

    def _file_digests(self, loaded: Sequence[str]) -> dict[str, str]:
        """The SHA-256 of every file the model depends on, ``loaded`` too (see
        :meth:`fingerprint`)."""
        return digest_files([*model_files(self.model_factory), *loaded])

    # -- running ------------------------------------------------------------------------------

    def size_estimate(
        self,
        n_nodes: int,
        outputs: Sequence[str],
        axes: Mapping[str, OutputAxis | None] | None = None,
    ) -> SizeEstimate:
        """Upper estimate of the space a run from ``n_nodes`` nodes writes
        (:func:`pcmb.run.output.estimate_size`): the most design and held-out runs it may make
        (:meth:`planned_runs`), every output (the derived ones too) counted as wide as the
        widest (``axes``: the model's ``output_axes``)."""
        widths = Layout.of(outputs, self.times, axes or {}).widths
        count = len(outputs) + len(self.derived)
        design, _, held_out = self.planned_runs(n_nodes)
        return estimate_size(design + held_out, max(widths, default=1), count, len(self.inputs))

    def memory_estimate(
        self,
        n_nodes: int,
        outputs: Sequence[str],
        axes: Mapping[str, OutputAxis | None] | None = None,
    ) -> MemoryEstimate:
        """Upper estimate of the memory a run from ``n_nodes`` nodes needs
        (:mod:`pcmb.run.memory`): the most design and held-out runs it may make
        (:meth:`planned_runs`), the range check's draws of a method with an expansion, every
        output (the derived ones too) as wide as the widest."""
        widths = Layout.of(outputs, self.times, axes or {}).widths
        design, _, held_out = self.planned_runs(n_nodes)
        return MemoryEstimate(
            nodes=design,
            held_out=held_out,
            width=max(widths, default=1),
            outputs=len(outputs) + len(self.derived),
            draws=RANGE_DRAWS if self.design.record().basis is not None else 0,
        )

    def planned_runs(self, n_nodes: int) -> tuple[int, int, int]:
        """(most design runs, first batch and most in all of the held-out runs) of a run from
        ``n_nodes`` nodes: a refining design may make up to its budget, and its check is sized
        to those (:meth:`held_out_runs`); no held-out run without an expansion."""
        design = max(n_nodes, getattr(self.design, "budget", n_nodes))
        if self.design.record().basis is None:
            return design, 0, 0
        return design, self.held_out_runs(n_nodes)[0], self.held_out_runs(design)[1]

    def check_model(self, pool: Pool | None = None) -> tuple[str, ...]:
        """Build the model in a worker, check it against the study, and return the outputs
        to keep.

        Parameters
        ----------
        pool:
            Workers to build it in (default: the workers that check a config, see
            :func:`pcmb.run.backends.checking_pool`).

        Raises
        ------
        UsageError
            A requested output the model lacks, or an uncertain input that names none of the
            model's parameters (when the model lists them) — before anything runs.
        ModelError
            The model's code failed or killed its worker while building.
        """
        if pool is None:
            # The workers that checked the config build it (or have it built already).
            with checking_pool(self.execution.backend, self.execution.jobs) as own:
                return self.check_model(own)
        return self._outputs(describe_model(self.model_factory, pool))

    def _outputs(self, facts: ModelFacts) -> tuple[str, ...]:
        """The outputs to keep, checked against what the model says of itself."""
        declared = facts.outputs
        unknown = [name for name in self.outputs or () if name not in declared]
        if unknown:
            raise usage_error(
                "outputs", f"the model has no output(s) {unknown}; it has {list(declared)}"
            )
        parameters = facts.parameters
        if parameters is not None:
            strangers = [name for name in self.model_inputs if name not in parameters]
            if strangers:
                raise usage_error(
                    "inputs",
                    f"input(s) {strangers} name no parameter of the model; "
                    f"it has {sorted(parameters)}",
                )
        kept = declared if self.outputs is None else self.outputs
        on_time = tuple(name for name in kept if name not in facts.axes)
        problems = derived_problems(self.derived, kept, on_time, self.times)
        if problems:
            raise UsageError(
                [ConfigProblem(key, message) for key, message in problems], source="Study"
            )
        return kept

    def run(
        self,
        output: str | Path | None = None,
        *,
        resume: bool = False,
        fresh: bool = False,
        force: bool = False,
        progress: bool | None = None,
        provenance: Mapping[str, str] | None = None,
        pool: Pool | None = None,
    ) -> StudyResult:
        """Run the model at every node and recover the statistics.

        Parameters
        ----------
        output:
            Result file (HDF5, written atomically); ``None`` keeps the result in memory
            and journals nothing.
        resume:
            Continue from the journal ``<output>.journal`` of an interrupted run.
        fresh:
            Start over: discard the journal ``<output>.journal`` first, whatever its state
            (unreadable, of another config); never one a live run holds, nor a folder
            holding anything a journal does not (``--fresh``).
        force:
            Overwrite a file at ``output`` that is not a pcmb result (``--force``); without
            it such a file is refused. A pcmb result is always replaced.
        progress:
            Progress bar on stderr (default: when stderr is a terminal).
        provenance:
            Extra attributes for the file (config text, command line).
        pool:
            Workers of the study's backend to run on; default: those of
            :func:`pcmb.run.backends.open_pool`.

        Warns
        -----
        PcmbWarning
            One per :class:`~pcmb.result.WarningRecord` of the result (also in
            ``result.warnings`` and in the file), except the notes
            (:meth:`~pcmb.result.StudyResult.is_note`: Sobol' indices undefined where an
            output does not vary; a method's own indicator about an output the diagnostics
            call reliable), which are kept in ``result.warnings`` and the file only.

        Raises
        ------
        UsageError
            Bad settings, ``resume`` and ``fresh`` together, an unfinished journal exists and
            neither ``resume`` nor ``fresh`` is given, or another process writes the journal.
        ResultFileError
            The output cannot be written (a folder, read-only, not enough space, a file that
            is not a pcmb result without ``force``), before any node runs; or a write failed
            during the run (the journal keeps finished nodes).
        ModelRunError
            Nodes failed and the policy does not allow going on; the journal is kept.
        """
        if resume and fresh:
            raise usage_error("fresh", "resume continues the journal, fresh discards it: give one")
        nodes = self.node_set()
        with contextlib.ExitStack() as stack:
            if pool is None:
                tasks = (
                    len(chunk_bounds(nodes.size, self.execution.chunk_size)) if nodes.size else 1
                )
                pool = stack.enter_context(
                    open_pool(
                        self.execution.backend,
                        self.execution.jobs,
                        self.address,
                        tasks=tasks,
                        key=self.source.address_key,
                    )
                )
            return self._run_on(nodes, pool, output, resume, fresh, force, progress, provenance)

    def _run_on(
        self,
        nodes: TensorGrid | NodeSet,
        pool: Pool,
        output: str | Path | None,
        resume: bool,
        fresh: bool,
        force: bool,
        progress: bool | None,
        provenance: Mapping[str, str] | None,
    ) -> StudyResult:
        """:meth:`run` on ``pool``, from the design's ``nodes`` (made and checked)."""
        # What the design is; taken again after its rounds, and after the recovery (_recover).
        record = self.design.record()
        # What the model finds wrong with the inputs or the time grid (an FMU's aliased
        # variables, a grid it cannot step): refused before any node, as `pcmb validate` does.
        facts = describe_model(self.model_factory, pool, self.times, tuple(self.inputs))
        if facts.input_problems or facts.time_problems:
            problems = [*facts.input_problems, *facts.time_problems]
            raise UsageError([ConfigProblem(*problem) for problem in problems], source="Study")
        outputs = self._outputs(facts)
        if self.analysis is not None:
            on_time = [name for name in outputs if name not in facts.axes]
            self.analysis.check(self.times, [*outputs, *self.derived], on_time)
        # Before any node runs and before a journal exists: a run that cannot fit in memory and
        # an output that cannot be written (a folder, a read-only or full file system) are
        # found now.
        _, streaming = check_memory(
            self.memory_estimate(nodes.size, outputs, facts.axes),
            self.memory,
            inputs=len(self.inputs),
            streams=self.why_not_streamed(output),
        )
        journaling = None
        if output is not None:
            estimate = self.size_estimate(nodes.size, outputs, facts.axes)
            check_output(output, estimate, create=True)
            if not force and Path(output).exists():
                from pcmb.store import check_replaceable

                check_replaceable(output)
            files = self._file_digests(facts.loaded_files)
            journaling = Journaling.start(output, files, resume=resume, fresh=fresh)
        run = _RunContext(pool, facts, outputs, journaling, progress)
        joined = self._joins_runs(streaming is not None)
        early = None if joined else self._start_nominal(run)
        intrusive = hasattr(self.design, "solve")
        stream = sys.stderr if (sys.stderr.isatty() if progress is None else progress) else None
        nominal = None
        try:
            # Where the held-out runs go may wait for the fit (along the input that carries the
            # tails): then they are not in the nodes' campaign.
            after_fit = self._held_out.after_fit()
            if joined:
                first = 0 if after_fit else self.held_out_runs(nodes.size)[0]
                runs, journal, checked, nominal = self._run_joined(run, nodes, record, first)
            elif intrusive:
                # An intrusive method: one solve in a worker, nothing to journal but the
                # held-out runs, which are few and run again on a resume.
                journal, run = None, dataclasses.replace(run, journaling=None)
                found = self._solve(run, nodes, record)
            else:
                runs, journal = self._run_nodes(run, nodes, keep=streaming is None)
                if hasattr(self.design, "more"):
                    nodes, runs = self._run_rounds(run, nodes, runs)
                    record = self.design.record()  # with the runs the rounds made
            first, most = self.held_out_runs(nodes.size)
            # Runs joined: made already. Else the workers make the held-out runs while this
            # process fits the expansions and draws the statistics, which do not need them
            # (after the fit: beside the statistics only); not in this process's own thread
            # (in-process runs), nor beside a nominal run sent after them (a timeout).
            background = bool(first) and not (
                isinstance(pool, InProcessPool) or self.execution.timeout is not None
            )
            beside = background and not joined
            make = functools.partial(
                self._run_held_out,
                # No bar beside the phases' lines.
                dataclasses.replace(run, progress=False) if background else run,
                record,
                design=nodes.nodes,
                values=None if intrusive else runs.values,
            )
            check = (lambda: checked) if joined else functools.partial(make, first)
            checking = None if after_fit else _beside(check, beside)
        except PcmbError:
            if early is not None:
                early.result()  # the nominal run sent ahead ends too: no run is left half done
            raise
        try:
            if early is not None:
                nominal = early.result()
            if self.execution.nominal_run and nominal is None:
                nominal = self._run_nominal(run)
            if streaming is not None:
                return self._finish_streamed(
                    run,
                    nodes,
                    runs,
                    journal,
                    nominal,
                    streaming,
                    output,
                    provenance,
                    stream,
                )
            if not intrusive:
                runs, nominal = self._with_derived(runs), self._with_derived(nominal)
                axes = {
                    **{name: axis for name, axis in facts.axes.items() if name in outputs},
                    **dict.fromkeys(self.derived),
                }
                fitting = f"fitting {plural(len(runs.values), 'output')}"
                with phase(f"{fitting} ({record.label})", stream):
                    found = dataclasses.replace(self._recover(nodes, runs, axes), axes=axes)
            found = self._with_nominal(found, nominal)
            if checking is None:
                axis = self._held_out.line_input(self._judged(found.expansions))
                checking = _beside(functools.partial(make, first, axis=axis), background)
            analysis = None
            # A design that refits after the check (_final_fit) has its statistics drawn then.
            if self.analysis is not None and not (first and hasattr(self.design, "refit")):
                with phase("statistics (quantile bands, PDFs, spectra)", stream):
                    analysis = analyse(found, self.analysis)
        except BaseException:
            # No run left going behind the error: the held-out runs beside it end first.
            with contextlib.suppress(BaseException):
                if checking is not None:
                    checking.exception()
            raise
        with phase(plural(first, "held-out run"), stream if beside or (joined and first) else None):
            held_out, held_out_failed = checking.result()
        if not intrusive:
            held_out = self._with_derived(held_out)
        with phase("diagnostics", stream):
            result = self._diagnosed(found, held_out, held_out_failed)
            wanted = max(map(more_runs, result.diagnostics.values()), default=0)
            # A placed check makes its runs at once.
            if held_out is not None and not held_out.placed and min(wanted, most - first) > 0:
                more, more_failed = self._run_held_out(
                    run,
                    record,
                    min(wanted, most - first),
                    nodes.nodes,
                    batch=1,  # drawn: a placed check makes its runs at once
                    earlier=held_out,
                )
                held_out = held_out.joined(self._with_derived(more))
                held_out_failed = (*held_out_failed, *more_failed)
                result = self._diagnosed(found, held_out, held_out_failed)
        if not intrusive:
            result = self._final_fit(nodes, runs, found, result, stream)
        if self.analysis is not None and analysis is None:
            with phase("statistics (quantile bands, PDFs, spectra)", stream):
                analysis = analyse(result, self.analysis)
        if analysis is not None:
            result = dataclasses.replace(result, analysis=analysis)
            result = dataclasses.replace(
                result, warnings=(*result.warnings, *pdf_outside_runs(result))
            )
        if output is not None:
            from pcmb.store import write_result  # h5py only when a file is written

            with phase(f"writing {output}", stream):
                write_result(output, result, provenance=provenance or {})
            if journal is not None:
                journal.remove()
        for alert in result.alerts:  # not the notes, e.g. Sobol' undefined at a fixed state
            warnings.warn(str(alert), PcmbWarning, stacklevel=3)
        return result

    def why_not_streamed(self, output: str | Path | None) -> str | None:
        """Why this study cannot stream its runs (``None``: it can): only a sampling design
        without a fit, writing a file, without derived outputs, has statistics that
        accumulate run by run."""
        design = self.design.record()
        if design.grid != "random" or design.basis is not None:
            fit = "" if design.grid != "random" else " with fit: regression"
            return f"method.kind {design.kind}{fit} needs every run at once"
        if self.derived:
            return "derived outputs are computed from every run at once"
        if output is None:
            return "without an output file its runs are kept in memory"
        return None

    def _finish_streamed(
        self,
        run: _RunContext,
        nodes: NodeSet,
        runs: RunResult,
        journal: Journal,
        nominal: RunResult | None,
        plan: StreamPlan,
        output: str | Path,
        provenance: Mapping[str, str] | None,
        stream: Any,
    ) -> StudyResult:
        """The end of a streamed study (:meth:`why_not_streamed`): one pass over the journal
        in node order accumulates every output's mean and std block by block
        (:class:`~pcmb.analysis.running_moments.RunningMoments`) and a reservoir of runs
        (:class:`~pcmb.analysis.reservoir.Reservoir`) for the warnings, quantiles, PDFs and
        spectra; a second pass writes the runs to the file (:func:`pcmb.store.write_streamed`).
        The result holds the statistics and no runs (``values`` without rows)."""
        from pcmb.store import write_streamed  # h5py only when a file is written

        outputs, axes = run.outputs, run.facts.axes
        layout = Layout.of(outputs, self.times, axes)
        widths = dict(zip(outputs, layout.widths, strict=True))
        with phase(f"statistics of {nodes.size} streamed runs", stream):
            moments, reservoir = stream_statistics(
                journal.chunks(), widths, plan.block_rows, plan.reservoir_rows, self.method.seed
            )
        axes = {name: axis for name, axis in axes.items() if name in outputs}
        kept = reservoir.index
        sample_runs = RunResult(
            values=layout.split(reservoir.rows),
            status=np.full(kept.size, Status.OK, dtype=np.int8),
            failures=(),
            seconds=runs.seconds,
            resumed=runs.resumed,
        )
        sample_nodes = NodeSet(nodes.distributions, nodes.nodes[kept], nodes.params[kept])
        sample = self._with_nominal(
            dataclasses.replace(self._recover(sample_nodes, sample_runs, axes), axes=axes),
            nominal,
        )
        result = dataclasses.replace(
            sample,
            germ=nodes.nodes,
            params=nodes.params,
            status=runs.status,
            failures=runs.failures,
            warnings=(*_nodes_failed(runs.failures, nodes.size), *sample.warnings),
            values={name: np.empty((0, width)) for name, width in widths.items()},
            report=MomentReport({name: np.stack([m.mean, m.std()]) for name, m in moments.items()}),
        )
        if self.analysis is not None:
            with phase("statistics (quantile bands, PDFs, spectra)", stream):
                found = analyse(sample, self.analysis)
            result = dataclasses.replace(result, analysis=found)
        with phase(f"writing {output}", stream):
            write_streamed(output, result, journal.chunks(), provenance=provenance or {})
        journal.remove()
        for record in result.alerts:
            warnings.warn(str(record), PcmbWarning, stacklevel=4)
        return result

    def _recover_by_axis(
        self,
        nodes: TensorGrid | NodeSet,
        values: Mapping[str, NDArray[np.float64]],
        ok: NDArray[np.bool_],
        axes: Mapping[str, OutputAxis | None],
        weights: NDArray[np.float64] | None = None,
    ) -> Recovery:
        """The design's recovery of each axis's outputs (:func:`_by_axis`), merged in output
        order, with their reports merged (:meth:`~pcmb.result.DesignReport.merged`); with (N,)
        row ``weights``, its final fit
        (:meth:`~pcmb.designs.base.RefittingDesign.refit`)."""
        parts = []
        for _, on_time, group in _by_axis(values, axes):
            # Warning records locate times only (time_range): off time they name indices.
            grid = self.times if on_time else None
            if weights is None:
                parts.append(self.design.recover(nodes, group, ok, times=grid))
            else:
                parts.append(self.design.refit(nodes, group, ok, weights, times=grid))
        first = parts[0]
        if len(parts) == 1:
            return first
        return dataclasses.replace(
            first,
            expansions={
                name: part.expansions[name]
                for name in values
                for part in parts
                if name in part.expansions
            },
            warnings=tuple(record for part in parts for record in part.warnings),
            report=_merged_reports(parts),
        )

    def _with_derived(self, runs: _Runs) -> _Runs:
        """Runs (or held-out runs, or ``None``) with the derived figures of their time
        outputs added as (N, 1) outputs."""
        if runs is None or not self.derived:
            return runs
        found = derive(self.derived, self.times, runs.values)
        return dataclasses.replace(runs, values={**runs.values, **found})

    def _solve(self, run: _RunContext, nodes: NodeSet, record: Design) -> StudyResult:
        """The result of an intrusive design (:class:`~pcmb.designs.base.IntrusiveDesign`),
        ``record`` its record, checked and solved in a worker with the model built there."""
        design, outputs = self.design, run.outputs
        kind = record.kind
        problems = run_in_worker(self.model_factory, run.pool, design.check, outputs)
        if self.derived:
            problems = [
                *problems,
                ("derived", f"figures of merit are computed from runs, and kind {kind} has none"),
            ]
        if problems:
            raise UsageError([ConfigProblem(key, message) for key, message in problems], "Study")
        start = time.perf_counter()
        try:
            recovery = run_in_worker(
                self.model_factory, run.pool, design.solve, self.times, outputs
            )
        except ModelError as error:
            raise ModelRunError((), f"the {kind} solve failed: {error}") from error
        return StudyResult(
            name=self.name,
            design=record,
            times=self.times,
            input_names=self.input_names,
            distributions=tuple(self.inputs.values()),
            germ=nodes.nodes,
            params=nodes.params,
            weights=None,
            status=np.zeros(0, dtype=np.int8),
            values={name: np.zeros((0, self.times.size)) for name in outputs},
            expansions=recovery.expansions,
            warnings=recovery.warnings,
            seconds=time.perf_counter() - start,
            report=recovery.report,
        )

    def _run_rounds(
        self, run: _RunContext, nodes: TensorGrid | NodeSet, runs: RunResult
    ) -> tuple[TensorGrid | NodeSet, RunResult]:
        """Run the further rounds an adaptive design asks for (its ``more`` method, see
        :class:`~pcmb.designs.base.AdaptiveDesign`), each journaled in its own folder of the
        journal; all nodes and runs so far."""
        more = getattr(self.design, "more", None)
        round_number = 0
        while more is not None:
            # Rounds are steered by the outputs of one axis (time first): see _by_axis.
            steering = _by_axis(runs.values, run.facts.axes)[0][2]
            batch = more(nodes, steering, runs.status == Status.OK)
            if batch is None:
                break
            self._check_finite(batch)
            round_number += 1
            found, journal = self._run_nodes(run, batch, f"round-{round_number}", proven=True)
            if journal is not None:
                journal.close()  # the folder goes with the whole journal at the end
            nodes, runs = join_nodes(nodes, batch), join_runs(runs, found)
        return nodes, runs

    def _joins_runs(self, streams: bool) -> bool:
        """Whether the design's runs, its first held-out runs and the nominal run go to the
        workers as one campaign (:meth:`_run_joined`): all of them known before any node runs
        (no rounds, no intrusive solve, held-out runs not placed by the element nodes' values),
        and the runs kept in memory (``streams`` False)."""
        return not (
            streams
            or hasattr(self.design, "more")
            or hasattr(self.design, "solve")
            or (self.places_held_out() and hasattr(self.design, "partition"))
        )

    def _run_joined(
        self, run: _RunContext, nodes: TensorGrid | NodeSet, record: Design, count: int
    ) -> tuple[
        RunResult,
        Journal | None,
        tuple[HeldOut | None, tuple[WarningRecord, ...]],
        RunResult | None,
    ]:
        """The design's ``nodes``, its first ``count`` held-out runs and the nominal run (if
        wanted) as one campaign, so that a chunk may hold runs of all three and the workers
        make as few model calls as the runs need (a stacked ODE pays its steps per call). Each
        set is journaled where it would be alone (the nominal run not at all) and judged by
        the failure policy as it would be, the design's runs first: (design runs, their
        journal, the held-out check as :meth:`_run_held_out` makes it, the nominal run)."""
        journal, fresh_journal = self._journal(run, nodes)
        # (model parameters, journal) of each set of runs, in order.
        sets = [(model_params(self.model_inputs, nodes.params), journal)]
        draws, held_journal = None, None
        if count and record.basis is not None:
            draws = self._held_out.draws(count, nodes.nodes)
            self._check_finite(draws.nodes)
            held_journal, _ = self._journal(run, draws.nodes, "validation")
            sets.append((model_params(self.model_inputs, draws.nodes.params), held_journal))
        if self.execution.nominal_run:
            sets.append((self._nominal_node(), None))
        sizes = [len(next(iter(params.values()))) for params, _ in sets]
        # Only the held-out runs' tail draws fail without stopping the campaign.
        tolerated = np.zeros(sum(sizes), dtype=bool)
        if draws is not None:
            tolerated[sizes[0] : sizes[0] + sizes[1]] = draws.tails
        joined = None
        if journal is not None:
            joined = JoinedJournal(
                [(part, size) for (_, part), size in zip(sets, sizes, strict=True)]
            )
        params = {name: np.concatenate([p[name] for p, _ in sets]) for name in sets[0][0]}
        with removed_if_rejected(journal, fresh_journal):  # its held-out runs' folder too
            runs = self._campaign(run, params, joined, counted=nodes.size, tolerated=tolerated)
        design_runs, *others = split_runs(runs, sizes)
        self._judge_failures(run, design_runs, journal)
        checked: tuple[HeldOut | None, tuple[WarningRecord, ...]] = (None, ())
        if draws is not None:
            found = others.pop(0).of(HELD_OUT_RUN)
            if held_journal is not None:
                held_journal.close()  # the folder goes with the whole journal at the end
            self._judge_failures(run, found, held_journal, HELD_OUT_RUN, draws.tails)
            checked = draws.checked(found)
        return design_runs, journal, checked, others[0] if others else None

    def _run_nodes(
        self,
        run: _RunContext,
        nodes: TensorGrid | NodeSet,
        folder: str | None = None,
        chunk_size: int | None = None,
        *,
        proven: bool = False,
        keep: bool = True,
        runs_of: str = "node",
        tolerated: NDArray[np.bool_] | None = None,
        earlier: tuple[int, int] = (0, 0),
    ) -> tuple[RunResult, Journal | None]:
        """Run every node (checked by the caller, :meth:`_check_finite`), journaled in the
        run's journal (its ``folder``, if given) when it has one (the journal is returned, to
        be removed once the result is written); raise by the failure policy. ``chunk_size``
        overrides the study's; ``proven``: the model ran at the study's nodes already (see
        :func:`~pcmb.run.executor.run_nodes`); ``keep`` False: the values stay in the journal
        only (a streamed study); ``runs_of``: what the runs are, for the error, and
        ``tolerated`` and ``earlier``: the runs whose failure the policy lets by, and the
        check's earlier batches (:meth:`_judge_failures`)."""
        journal, fresh_journal = self._journal(run, nodes, folder)
        with removed_if_rejected(journal, fresh_journal):
            runs = self._campaign(
                run,
                model_params(self.model_inputs, nodes.params),
                journal,
                chunk_size,
                proven=proven,
                keep=keep,
                tolerated=tolerated,
            ).of(runs_of)
        self._judge_failures(run, runs, journal, runs_of, tolerated, earlier)
        return runs, journal

    def _journal(
        self, run: _RunContext, nodes: TensorGrid | NodeSet, folder: str | None = None
    ) -> tuple[Journal | None, bool]:
        """The journal of ``nodes`` in the run's journal (its ``folder``, if given; ``None``:
        the run journals nothing), and whether it is new."""
        if run.journaling is None:
            return None, False
        journaling = run.journaling if folder is None else run.journaling.folder(folder)
        widths = Layout.of(run.outputs, self.times, run.facts.axes).widths
        digest = self._digest(nodes, run.outputs)
        return journaling.open(digest, nodes.size, run.outputs, widths)

    def _campaign(
        self,
        run: _RunContext,
        params: dict[str, NDArray[np.float64]],
        journal: Journal | JoinedJournal | None,
        chunk_size: int | None = None,
        *,
        proven: bool = False,
        keep: bool = True,
        counted: int | None = None,
        tolerated: NDArray[np.bool_] | None = None,
    ) -> RunResult:
        """:func:`~pcmb.run.executor.run_nodes` of the model at ``params`` under the study's
        execution settings and failure policy (see :meth:`_run_nodes`), which the failures of
        the ``tolerated`` runs do not stop; the progress line counts the first ``counted``
        runs (default: all)."""
        return run_nodes(
            self.model_factory,
            params,
            self.times,
            run.outputs,
            execution=self.execution,
            address=self.address,
            chunk_size=chunk_size,
            retries=self.execution.retries if self.execution.on_failure == "retry" else 0,
            journal=journal,
            progress=run.progress,
            stop_on_failure=self.execution.on_failure == "abort",
            pool=run.pool,
            facts=run.facts,
            proven=proven,
            keep_values=keep,
            counted=counted,
            tolerated=tolerated,
        )

    def _judge_failures(
        self,
        run: _RunContext,
        runs: RunResult,
        journal: Journal | None,
        runs_of: str = "node",
        tolerated: NDArray[np.bool_] | None = None,
        earlier: tuple[int, int] = (0, 0),
    ) -> None:
        """Raise a ModelRunError for failed runs unless the policy (``regress``) goes on, or
        all of them are ``tolerated`` (:attr:`~pcmb.held_out.HeldOutDraws.tails`) and, with
        the ``earlier`` (runs, tail failures) of the check's batches before, at most
        ``TAIL_FAILURE_SHARE`` of the check's runs fail in the tails; ``runs_of``: what the
        runs are (``"held-out run"``: numbered among those, and kept beside the design's
        nodes, which the error names too: ``--resume`` keeps both)."""
        failures = [f for f in runs.failures if tolerated is None or not tolerated[f.index]]
        in_tails = len(runs.failures) - len(failures)
        checked, failed_before = earlier
        too_many = in_tails + failed_before > TAIL_FAILURE_SHARE * (runs.status.size + checked)
        if too_many:
            failures = list(runs.failures)
        if not failures or self.execution.on_failure == "regress":
            return
        finished = int(np.sum(runs.status == Status.OK))
        finished_in = journal.directory if journal is not None and finished else None
        kept = ""
        if runs_of == HELD_OUT_RUN and run.journaling is not None:
            design = f"; the design's nodes are kept in {run.journaling.directory}"
            if finished_in is None:
                kept = f"{design} (--resume keeps them)"
            else:
                kept = (
                    f"{design} and the {finished} finished {runs_of}(s) in {finished_in}"
                    " (--resume keeps both)"
                )
        elif finished_in is not None:
            kept = f"; the {finished} finished {runs_of}(s) are kept in {finished_in}"
        pending = int(np.sum(runs.status == Status.PENDING))
        stopped = (
            f"; stopped at the first failure, {pending} {runs_of}(s) not run"
            + (" (--resume runs them)" if journal is not None else "")
            if pending
            else ""
        )
        tails = (
            f", {in_tails} of them in the tails"
            + (f" and {failed_before} of the check's {checked} earlier runs" if checked else "")
            + f", more than {TAIL_FAILURE_SHARE:.0%} of the "
            "check's runs: too many for it to stand on the rest"
            if too_many
            else ""
        )
        raise ModelRunError(
            failures,
            f"the model failed at {len(failures)} of {runs.status.size} {runs_of}(s) "
            f"(on_failure: {self.execution.on_failure}){tails}{kept}{stopped}:",
        )

    def held_out_runs(self, design_runs: int) -> tuple[int, int]:
        """(first batch, most in all) of the held-out runs that check an expansion of
        ``design_runs`` runs (:meth:`pcmb.held_out.HeldOutPlan.runs`)."""
        return self._held_out.runs(design_runs)

    def places_held_out(self) -> bool:
        """Whether the held-out runs are placed to extend the design's nodes rather than
        drawn (:meth:`pcmb.held_out.HeldOutPlan.placed`)."""
        return self._held_out.placed()

    def _judged(self, expansions: Mapping[str, ChaosExpansion]) -> dict[str, ChaosExpansion]:
        """The ``expansions`` of the outputs the diagnostics judge (``diagnostics.outputs``;
        all where it names none)."""
        judged = self.diagnostics.outputs or tuple(expansions)
        return {name: e for name, e in expansions.items() if name in judged}

    def _run_held_out(
        self,
        run: _RunContext,
        record: Design,
        count: int,
        design: NDArray[np.float64],
        values: Mapping[str, NDArray[np.float64]] | None = None,
        batch: int = 0,
        earlier: HeldOut | None = None,
        axis: int | None = None,
    ) -> tuple[HeldOut | None, tuple[WarningRecord, ...]]:
        """``count`` held-out runs that check a chaos expansion (none for plain sampling,
        by the design's ``record``), batch ``batch`` of the check, placed to extend the
        design's nodes ``design`` (germ points; along input ``axis`` where given) or drawn
        (:meth:`~pcmb.held_out.HeldOutPlan.draws`); journaled in the journal's ``validation``
        folder (``validation-<batch>`` after the first), under the failure policy, which the
        tail draws' failures trigger only where, with the ``earlier`` batches' runs, too many
        of the check's fail (:meth:`_judge_failures`); and ``nodes-failed`` records naming
        those that failed (:meth:`~pcmb.held_out.HeldOutDraws.checked`)."""
        if not count or record.basis is None:
            return None, ()
        draws = self._held_out.draws(count, design, values, batch, axis)
        self._check_finite(draws.nodes)
        name = "validation" if batch == 0 else f"validation-{batch}"
        # Two chunks, whatever the workers: a few runs do not pay one model call each.
        halves = self.execution.chunk_size or -(-count // 2)
        # After the nodes (not after an intrusive solve) the model is known to work.
        proven = not hasattr(self.design, "solve")
        # An earlier batch's failures are all tail draws': any other stopped the study, but
        # under `regress`, which judges none.
        before = (0, 0) if earlier is None else (earlier.ok.size, int(np.sum(~earlier.ok)))
        found, journal = self._run_nodes(
            run,
            draws.nodes,
            name,
            halves,
            proven=proven,
            runs_of=HELD_OUT_RUN,
            tolerated=draws.tails,
            earlier=before,
        )
        if journal is not None:
            journal.close()  # the folder goes with the whole journal at the end
        return draws.checked(found)

    def _diagnosed(
        self,
        result: StudyResult,
        held_out: HeldOut | None,
        held_out_failed: tuple[WarningRecord, ...],
    ) -> StudyResult:
        """The result with its diagnostics (per output) and their warning records, after
        ``held_out_failed``. A method without runs (Galerkin) has its range checked against
        the held-out runs, and no diagnostics without them."""
        germ, values, ok = result.germ, result.values, result.status == Status.OK
        warnings = (*result.warnings, *held_out_failed)
        if result.n_nodes == 0:
            if held_out is None or not held_out.ok.any():
                return dataclasses.replace(result, held_out=held_out, warnings=warnings)
            germ, values, ok = held_out.germ, held_out.values, held_out.ok
        judged = self._judged(result.expansions)
        found = diagnose_all(
            judged,
            germ,
            values,
            ok,
            result.times,
            held_out,
            self.diagnostics.tolerance,
            axes=result.axes,
            nominal=result.nominal,
            budgets={w.code for w in result.warnings if w.code.endswith("-budget")},
            design_error=None
            if result.report is None
            else {name: result.report.statistics_error(result, name) for name in judged},
            design_understates=1.0 if result.report is None else result.report.UNDERSTATES,
        )
        records = tuple(record for diagnosis in found.values() for record in diagnosis.warnings)
        return dataclasses.replace(
            result,
            diagnostics=found,
            held_out=held_out,
            warnings=(*warnings, *records),
        )

    def _final_fit(
        self,
        nodes: TensorGrid | NodeSet,
        runs: RunResult,
        found: StudyResult,
        judged: StudyResult,
        stream: TextIO | None,
    ) -> StudyResult:
        """The ``judged`` result (``found``, the design's own fit, diagnosed) with the final
        fit of a design that refits (:class:`~pcmb.designs.base.RefittingDesign`): every
        output the check does not vouch for fitted over the ``runs`` at its ``nodes`` and the
        held-out runs that succeeded, weighted back by their importance weights, its
        expansion, report entry and records (``regression-budget`` among them: judged on the
        final fit) replacing ``found``'s; the others keep the fit the check vouched for. The
        diagnostics, verdict and corrected mean and std stay those of the checked fit
        (``docs/methods.md``, "The final fit"). ``judged`` itself for any other design,
        without a held-out run that succeeded, or where the check vouches for all."""
        held_out = judged.held_out
        if not hasattr(self.design, "refit") or held_out is None or not held_out.ok.any():
            return judged
        vouched = {name for name, checked in judged.diagnostics.items() if checked.vouched}
        if vouched >= set(found.expansions):
            return judged
        every = join_nodes(nodes, NodeSet(nodes.distributions, held_out.germ, held_out.params))
        values = {
            name: np.concatenate([y, held_out.values[name]])
            for name, y in runs.values.items()
            if name not in vouched
        }
        ok = np.concatenate([runs.status == Status.OK, held_out.ok])
        weights = np.concatenate([np.ones(nodes.size), held_out.weights])
        fitting = f"final fit with {plural(int(held_out.ok.sum()), 'held-out run')}"
        with phase(fitting, stream):
            recovery = self._recover_by_axis(every, values, ok, found.axes, weights)
        kept = tuple(record for record in found.warnings if record.output not in values)
        expansions = {
            name: recovery.expansions.get(name, expansion)
            for name, expansion in found.expansions.items()
        }
        report = recovery.report if found.report is None else found.report.merged(recovery.report)
        return dataclasses.replace(
            judged,
            expansions=expansions,
            report=report,
            # The check's records come after the design's (_diagnosed).
            warnings=(*kept, *recovery.warnings, *judged.warnings[len(found.warnings) :]),
        )

    def _start_nominal(self, run: _RunContext) -> PendingRun | None:
        """The nominal run sent to the pool ahead of the nodes, to run beside them
        (:func:`~pcmb.run.executor.start_run`); ``None`` if not wanted, or with a timeout,
        when chunks must not wait behind it (it runs after them, :meth:`_run_nominal`)."""
        if not self.execution.nominal_run or self.execution.timeout is not None:
            return None
        node = self._nominal_node()
        return start_run(self.model_factory, node, self.times, run.outputs, run.pool, run.facts)

    def _nominal_node(self) -> dict[str, NDArray[np.float64]]:
        """The nominal parameters as a one-node batch of the model's inputs."""
        return model_params(self.model_inputs, [list(self.nominal_params().values())])

    def _run_nominal(self, run: _RunContext) -> RunResult:
        """The deterministic run at the nominal parameters (not part of any statistic)."""
        return run_nodes(
            self.model_factory,
            self._nominal_node(),
            self.times,
            run.outputs,
            execution=self.execution,
            address=self.address,
            progress=False,
            pool=run.pool,
            facts=run.facts,
            proven=True,  # its failure is a warning (_with_nominal)
        )

    def _with_nominal(self, result: StudyResult, run: RunResult | None) -> StudyResult:
        """The result with the nominal run added (``None``: none was made); its failure is a
        warning, not an error."""
        params = self.nominal_params()
        if run is None:
            return dataclasses.replace(result, nominal_params=params)
        if run.failures:
            warning = WarningRecord(
                "nominal-failed",
                f"the nominal run failed, so none is stored: {run.failures[0].message}",
            )
            return dataclasses.replace(
                result, nominal_params=params, warnings=(*result.warnings, warning)
            )
        nominal = {name: values[0] for name, values in run.values.items()}
        return dataclasses.replace(result, nominal_params=params, nominal=nominal)

    # -- recovery -----------------------------------------------------------------------------

    def _recover(
        self,
        nodes: TensorGrid | NodeSet,
        runs: RunResult,
        axes: Mapping[str, OutputAxis | None],
    ) -> StudyResult:
        """Expansions of every output: the design recovers the outputs of each axis together
        (time first, then each own axis, then the scalars)."""
        ok = runs.status == Status.OK
        warnings = _nodes_failed(runs.failures, nodes.size)
        try:
            recovery = self._recover_by_axis(nodes, runs.values, ok, axes)
        except IllPosedError as error:
            message = f"on_failure regress could not refit: {error}:"
            raise ModelRunError(runs.failures, message) from error
        return StudyResult(
            name=self.name,
            design=self.design.record(),  # after the recovery, which a design may record
            times=self.times,
            input_names=self.input_names,
            distributions=tuple(self.inputs.values()),
            germ=nodes.nodes,
            params=nodes.params,
            weights=self.design.weights(nodes),
            status=runs.status,
            values=runs.values,
            expansions=recovery.expansions,
            failures=runs.failures,
            warnings=(*warnings, *recovery.warnings),
            seconds=runs.seconds,
            report=recovery.report,
            processes=self.processes,
        )


@dataclasses.dataclass(frozen=True)
class _RunContext:
    """What the steps of one :meth:`Study.run` share: the workers (``pool``), what the model
    says of itself (``facts``), the ``outputs`` kept, where the runs are journaled
    (``journaling``; ``None``: nowhere) and whether a progress bar is shown (``progress``, as
    :meth:`Study.run` takes it)."""

    pool: Pool
    facts: ModelFacts
    outputs: tuple[str, ...]
    journaling: Journaling | None
    progress: bool | None


def _merged_reports(parts: list[Recovery]) -> DesignReport | None:
    """The parts' design reports merged into one, in order (``None``: the design has none)."""
    reports = [part.report for part in parts if part.report is not None]
    return functools.reduce(lambda first, other: first.merged(other), reports) if reports else None


def _nodes_failed(failures: Sequence[NodeFailure], total: int) -> list[WarningRecord]:
    """The ``nodes-failed`` record of the nodes left out (none if none failed)."""
    if not failures:
        return []
    return [
        WarningRecord(
            "nodes-failed",
            f"{len(failures)} of {total} node(s) failed and were left out "
            f"(on_failure: regress): " + "; ".join(str(f) for f in failures),
        )
    ]


def _by_axis(
    values: Mapping[str, Any], axes: Mapping[str, OutputAxis | None]
) -> list[tuple[OutputAxis | None, bool, dict[str, Any]]]:
    """The outputs grouped by axis: ``(axis, on_time, {name: values})``, time first."""
    groups: dict[str | None, tuple[OutputAxis | None, bool, dict[str, Any]]] = {}
    for name, array in values.items():
        axis = axes.get(name)
        key = "" if name not in axes else None if axis is None else axis.name
        groups.setdefault(key, (axis, name not in axes, {}))[2][name] = array
    return sorted(groups.values(), key=lambda group: not group[1])


#: ``execution:`` keys that cannot change a node's values (left out of the fingerprint).
_EXECUTION_ONLY = frozenset(
    {"jobs", "backend", "address", "on_failure", "retries", "timeout", "nominal_run", "memory"}
)
#: Top-level config keys that cannot change a node's values.
_NOT_RUN = frozenset({"name", "analysis", "diagnostics", "output", "execution", "derived"})


def _run_settings(config: StudyConfig) -> str:
    """The run-relevant part of a validated config, as JSON: the ``model`` section, ``time``,
    ``inputs``, ``method`` and ``execution.chunk_size`` (and any key added later that is not
    known to be irrelevant). Its text is not used, so comments, layout and the settings that
    cannot change node values (name, analysis, diagnostics, method.validation, output, jobs,
    backend, address, on_failure, retries, timeout) do not invalidate a journal."""
    data = config.model_dump(mode="json", exclude=set(_NOT_RUN))
    data["execution"] = config.execution.model_dump(mode="json", exclude=set(_EXECUTION_ONLY))
    # The held-out runs have their own journal folder, fingerprinted by their own nodes.
    data["method"] = config.method.model_dump(mode="json", exclude={"validation"})
    return json.dumps(data)


def _tuple(values: Sequence[str] | None) -> tuple[str, ...] | None:
    return None if values is None else tuple(values)


def _beside(call: Callable[[], _T], background: bool) -> Future[_T]:
    """``call()`` in a thread of its own when ``background``, its result or exception kept in
    the future returned; else now (raising here)."""
    future: Future[_T] = Future()
    if not background:
        future.set_result(call())
        return future

    def run() -> None:
        try:
            future.set_result(call())
        except BaseException as error:  # the caller's to raise, from future.result()
            future.set_exception(error)

    # A daemon: an interrupted run does not wait for it at exit (its workers are killed).
    threading.Thread(target=run, name="pcmb-held-out", daemon=True).start()
    return future
